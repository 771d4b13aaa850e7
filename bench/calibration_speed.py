"""Time to calibrate 15 and 50 views of 640x480 with veg_area_ros's bundle adjustment, beside
cv2.calibrateCamera on the very same detections, measured in one run. Prints ratios, not claims.

    .venv/bin/python bench/calibration_speed.py [--repeats N]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from timing import median_seconds  # bench/ is the script's folder, first on sys.path

from veg_area_ros.board import BoardSpec
from veg_area_ros.calibration import View, calibrate
from veg_area_ros.synthetic import ENDOSCOPE, board_views, render_board_views


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    board = BoardSpec.parse("chessboard:9x6:0.03")
    rng = np.random.default_rng(0)
    print("rendering 50 synthetic 640x480 board views ...", file=sys.stderr)
    poses = board_views(ENDOSCOPE, board, 50, 0.6, rng)
    images = render_board_views(ENDOSCOPE, board, poses, rng=rng)
    views = [View(f"v{i}", d) for i, image in enumerate(images) if (d := board.detect(image)) is not None]
    print(f"{'views':>5} {'opencv [s]':>11} {'veg_area [s]':>13} {'ratio':>7} {'rms opencv':>11} {'rms ours':>9}")
    for count in (15, 50):
        subset = views[:count]
        obj = [v.detection.object_points.astype(np.float32) for v in subset]
        img = [v.detection.image_points.astype(np.float32) for v in subset]
        opencv = median_seconds(lambda o=obj, i=img: cv2.calibrateCamera(o, i, ENDOSCOPE.image_size, None, None),
                                args.repeats)
        ours = median_seconds(lambda s=subset: calibrate(s, ENDOSCOPE.image_size), args.repeats)
        result = calibrate(subset, ENDOSCOPE.image_size)
        print(f"{len(subset):5d} {opencv:11.3f} {ours:13.3f} {ours / opencv:6.2f}x {result.opencv_rms_px:11.4f} "
              f"{result.rms_px:9.4f}")
    print("(ours includes OpenCV's initial estimate, the joint refinement, covariance and outlier checks)")


if __name__ == "__main__":
    main()
