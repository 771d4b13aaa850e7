"""The calibration node's ~/feedback image on the built-in synthetic endoscope, for the docs: midway through
the views (a line says what is still needed) and after the fit (RMS, std, projection uncertainty, residuals).

    .venv/bin/python -m veg_area_ros.sim.feedback_demo docs/images

No ROS here.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

from ..board import BoardSpec
from ..calibration import View, calibrate
from ..feedback import FitView, render_feedback
from ..guidance import CalibrationGuide
from .synthetic import BOARD, DISTANCE_M, ENDOSCOPE, VIEWS, FlatPort, board_views, render_board_views


def main(argv: list[str] | None = None) -> int:
    folder = Path((argv or sys.argv[1:] or ["."])[0])
    folder.mkdir(parents=True, exist_ok=True)
    board = BoardSpec.parse(BOARD)
    poses = board_views(ENDOSCOPE, board, VIEWS, DISTANCE_M, np.random.default_rng(3), port=FlatPort())
    images = render_board_views(ENDOSCOPE, board, poses, port=FlatPort(), noise_sigma=1.0)
    guide = CalibrationGuide(board, ENDOSCOPE.image_size)
    views = []
    for k, image in enumerate(images):
        detection = board.detect(image)
        if detection is None:
            continue
        verdict = guide.offer(detection, image)
        if verdict.kept:
            views.append(View(f"view{k}", detection))
        if len(views) == 6 and verdict.kept:
            cv2.imwrite(str(folder / "feedback_midway.png"), render_feedback(image, guide, detection.image_points,
                                                                             verdict))
    result = calibrate(views, ENDOSCOPE.image_size)
    fit = FitView(result.rms_px, dict(result.std), result.projection_std_px, result.image_points[-1],
                  result.residuals[-1])
    image = images[0]
    detection = board.detect(image)
    cv2.imwrite(str(folder / "feedback_fitted.png"),
                render_feedback(image, guide, None if detection is None else detection.image_points, None, fit))
    print(f"{folder / 'feedback_midway.png'}, {folder / 'feedback_fitted.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
