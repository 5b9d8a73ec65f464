"""Install fourws_mpc: Python modules, console scripts under lib/fourws_mpc, config under share/fourws_mpc."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "fourws_mpc"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    # the default fuzzy response surfaces (fourws_mpc.core.fuzzy_weights.SHIPPED_SURFACES)
    package_data={PACKAGE: ["data/*.npz"]},
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
    description="Online parameter-reconfigured MPC for four-wheel steering with direct yaw moment: 3-DOF model, QP, fuzzy weights, APCHA horizons; MPC node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "mpc_node = fourws_mpc.mpc_node:main",
        ],
    },
)
