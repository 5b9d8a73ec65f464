"""Install fourws_torque_alloc: Python modules, console scripts under lib/fourws_torque_alloc, config under share/fourws_torque_alloc."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "fourws_torque_alloc"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        *[
            ("share/" + PACKAGE + "/" + d, glob(d + "/*.yaml"))
            for d in sorted({p.rsplit("/", 1)[0] for p in glob("config/**/*.yaml", recursive=True)})
        ],
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="fourws developers",
    maintainer_email="fourws@example.org",
    description="Lower layer of fourws: PID speed control and torque allocation over four in-wheel motors; two nodes.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "speed_pid_node = fourws_torque_alloc.speed_pid_node:main",
            "allocator_node = fourws_torque_alloc.allocator_node:main",
        ],
    },
)
