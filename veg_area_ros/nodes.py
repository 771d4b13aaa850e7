"""ROS 2 node entry points. The nodes themselves arrive with the ROS 2 graph issue (#4); until then each
entry point says so and exits non-zero instead of pretending to run."""

from __future__ import annotations

import sys


def _not_yet(node: str) -> int:
    print(f"{node}: not available yet; the ROS 2 nodes arrive with issue #4. "
          "Use `veg-area calibrate` meanwhile.", file=sys.stderr)
    return 1


def camera_main() -> int:
    return _not_yet("camera_node")


def calibration_main() -> int:
    return _not_yet("calibration_node")


def area_main() -> int:
    return _not_yet("area_node")
