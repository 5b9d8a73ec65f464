"""Install fourws_sim: Python modules, console scripts under lib/fourws_sim, config under share/fourws_sim."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "fourws_sim"

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
    description="Vehicle plant for fourws: nonlinear two-track model, Magic Formula tyres, in-wheel motors, steering actuators, roads, reference paths, scenarios; plant node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "plant_node = fourws_sim.plant_node:main",
        ],
    },
)
