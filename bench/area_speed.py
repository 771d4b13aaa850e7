"""Per-frame cost of the area node's core on a 640x480 underwater frame (idealize, find targets, classify,
Af with its uncertainty), beside a plain memory copy and a naive undistort-then-threshold of the same frame,
measured in one run. Prints ms per frame and ratios, and the share of a 30 fps frame interval.

    .venv/bin/python bench/area_speed.py [--repeats N]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from timing import median_seconds  # bench/ is the script's folder, first on sys.path

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.classify import Classifier
from veg_area_ros.scale import TargetsSpec
from veg_area_ros.synthetic import ENDOSCOPE, SCENE_DICTIONARY, SCENE_MARKERS, FlatPort, cube_scene, render_scene


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7, FlatPort())
    targets = TargetsSpec.from_dict({"dictionary": SCENE_DICTIONARY,
                                     "markers": {k: list(v) for k, v in SCENE_MARKERS.items()}})
    measurer = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120))
    measurer.measure(frame)  # maps and masks built once, as in the node

    def naive() -> None:
        ideal = cv2.undistort(frame, ENDOSCOPE.camera_matrix, ENDOSCOPE.dist)
        cv2.threshold(cv2.cvtColor(ideal, cv2.COLOR_BGR2GRAY), 120, 255, cv2.THRESH_BINARY_INV)

    copy_ms = 1000 * median_seconds(lambda: frame.copy(), args.repeats)
    naive_ms = 1000 * median_seconds(naive, args.repeats)
    core_ms = 1000 * median_seconds(lambda: measurer.measure(frame), args.repeats)
    print(f"640x480 bgr8, median of {args.repeats}")
    print(f"  memory copy                      {copy_ms:8.3f} ms")
    print(f"  naive undistort + threshold      {naive_ms:8.3f} ms  ({naive_ms / copy_ms:6.1f}x copy)")
    print(f"  area core (Af + uncertainty)     {core_ms:8.3f} ms  ({core_ms / copy_ms:6.1f}x copy, "
          f"{core_ms / naive_ms:.1f}x naive, {core_ms / (1000 / 30):.0%} of a 30 fps frame interval)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
