"""ROS 2 node entry points (`ros2 run veg_area_ros <node>`); rclpy is imported only when a node starts, so
the core and the `veg-area` command work without ROS."""

from __future__ import annotations

import sys


def _run(module: str) -> int:
    from importlib import import_module

    return import_module(f"{__package__}.ros.{module}").main(sys.argv)


def camera_main() -> int:
    return _run("camera_node")


def calibration_main() -> int:
    return _run("calibration_node")


def area_main() -> int:
    return _run("area_node")


def graph_main() -> int:
    return _run("graph")


def record_main() -> int:
    return _run("record_node")


def drag_main() -> int:
    return _run("drag_node")


def play_main() -> int:
    return _run("play_node")
