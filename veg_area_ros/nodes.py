"""ROS 2 node entry points (`ros2 run veg_area_ros <node>`); rclpy is imported only when a node starts, so
the core and the `veg-area` command work without ROS."""

from __future__ import annotations

import sys


def camera_main() -> int:
    from .ros.camera_node import main

    return main(sys.argv)


def calibration_main() -> int:
    from .ros.calibration_node import main

    return main(sys.argv)


def area_main() -> int:
    from .ros.area_node import main

    return main(sys.argv)


def graph_main() -> int:
    from .ros.graph import main

    return main(sys.argv)


def record_main() -> int:
    from .ros.record_node import main

    return main(sys.argv)


def drag_main() -> int:
    from .ros.drag_node import main

    return main(sys.argv)
