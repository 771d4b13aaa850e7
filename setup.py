from glob import glob

from setuptools import find_packages, setup

PACKAGE = "veg_area_ros"
# graph_node: camera, calibration and area composed in one process
NODES = ["camera_node", "calibration_node", "area_node", "graph_node", "record_node", "drag_node", "play_node"]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    entry_points={
        "console_scripts": [f"{node}={PACKAGE}.nodes:{node.split('_')[0]}_main" for node in NODES]
        + [f"veg-area={PACKAGE}.cli:main"],
    },
)
