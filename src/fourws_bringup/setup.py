"""Install fourws_bringup: Python modules, console scripts under lib/fourws_bringup, config under share/fourws_bringup."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "fourws_bringup"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/launch", glob("launch/*.launch.py")),
        *[
            ("share/" + PACKAGE + "/" + d, glob(d + "/*.yaml") + glob(d + "/*.xml"))
            for d in sorted({p.rsplit("/", 1)[0] for p in glob("config/**/*.yaml", recursive=True)})
        ],
        ("share/" + PACKAGE + "/config/foxglove", glob("config/foxglove/*.json")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="fourws developers",
    maintainer_email="fourws@example.org",
    description="Bring-up of fourws: graph supervisor, MCAP recorder and replay nodes, metrics, plots and the fourws command line; controller presets.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "fourws = fourws_bringup.cli:entry",
            "recorder_node = fourws_bringup.recorder_node:main",
            "replay_node = fourws_bringup.replay_node:main",
            "container = fourws_bringup.container:main",
            "adapter_node = fourws_bringup.adapter_node:main",
        ],
    },
)
