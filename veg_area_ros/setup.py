from glob import glob

from setuptools import find_packages, setup

PACKAGE = "veg_area_ros"
# executable -> module under veg_area_ros.ros with its main(); graph_node: camera, calibration and area composed
# in one process. rclpy is imported only when a node starts, so `veg-area` and the core run without ROS.
NODES = {"camera_node": "camera_node", "calibration_node": "calibration_node", "area_node": "area_node",
         "graph_node": "graph", "record_node": "record_node", "drag_node": "drag_node", "play_node": "play_node",
         "console_node": "console_node"}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={PACKAGE: ["console_page/*.html", "console_page/*.js", "console_page/*.css"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    entry_points={
        "console_scripts": [f"{node}={PACKAGE}.ros.{module}:main" for node, module in NODES.items()]
        + [f"veg-area={PACKAGE}.launcher:main"],
    },
)
