from glob import glob
from setuptools import find_packages, setup

PACKAGE = "veg_area_ros"
NODES = ["camera_node", "calibration_node", "area_node"]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    entry_points={
        "console_scripts": [f"{n}={PACKAGE}.cli:main" for n in NODES] + ["veg-area=veg_area_ros.cli:main"],
    },
)
