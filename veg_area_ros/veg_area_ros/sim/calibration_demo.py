"""The built-in default job: calibrate a synthetic 640x480 underwater endoscope, in air and under water
at 0.7 m, and compare with the camera that rendered the images. No hardware, no ROS needed.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..board import BoardSpec
from ..calib_io import fit_metadata, write_calibration
from ..calibration import PARAM_NAMES, CalibrationResult, View, calibrate
from ..camera_model import BrownCamera
from .synthetic import BOARD, DISTANCE_M, ENDOSCOPE, VIEWS, FlatPort, board_views, render_board_views

if TYPE_CHECKING:
    from collections.abc import Callable


def _calibrate_synthetic(board: BoardSpec, port: FlatPort | None, seed: int, say: Callable[[str], None]
                         ) -> tuple[CalibrationResult, list]:
    rng = np.random.default_rng(seed)
    poses = board_views(ENDOSCOPE, board, VIEWS + 1, DISTANCE_M, rng, port=port)
    images = render_board_views(ENDOSCOPE, board, poses, port=port, rng=rng)
    views = []
    for i, image in enumerate(images[:-1]):
        detection = board.detect(image)
        if detection is not None:
            views.append(View(f"view{i:02d}", detection))
    say(f"  {len(views)} of {VIEWS} rendered views detected")
    return calibrate(views, ENDOSCOPE.image_size), [images[-1]]


def _holdout_rms(camera: BrownCamera, board: BoardSpec, images: list[np.ndarray]) -> float:
    """Reprojection RMS on a view not used in the fit, its pose solved with the given camera."""
    detection = board.detect(images[0])
    _, rvec, tvec = cv2.solvePnP(detection.object_points, detection.image_points, *camera.to_opencv())
    error = detection.image_points - camera.project(detection.object_points, rvec, tvec)
    return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))


def run_demo(output: Path, quiet: bool = False) -> int:
    def say(message: str) -> None:
        if not quiet:
            print(message, file=sys.stderr, flush=True)

    board = BoardSpec.parse(BOARD)
    print(f"veg_area_ros demo: synthetic {ENDOSCOPE.width}x{ENDOSCOPE.height} endoscope, board {BOARD}, "
          f"{VIEWS} views at {DISTANCE_M} m")
    say("calibrating in air ...")
    air, _ = _calibrate_synthetic(board, None, seed=1, say=say)
    say("calibrating under water (flat port, refraction traced with Snell's law) ...")
    water, water_holdout = _calibrate_synthetic(board, FlatPort(), seed=2, say=say)

    truth = ENDOSCOPE.parameters()
    print("\nIn air, the fit against the camera that rendered the images:")
    print(f"{'param':>6} {'true':>12} {'fitted':>12} {'std':>10} {'error/std':>10}")
    fitted_air = air.camera.parameters()
    for name in PARAM_NAMES:
        z = (fitted_air[name] - truth[name]) / air.std[name]
        print(f"{name:>6} {truth[name]:12.5g} {fitted_air[name]:12.5g} {air.std[name]:10.2g} {z:10.2f}")
    print(f"RMS {air.rms_px:.4f} px, max {air.max_residual_px:.4f} px over {air.views_used} views")

    print("\nUnder water the Brown terms absorb refraction (principal distance grows by about n = 1.333):")
    print(f"  c water / c air = {water.camera.c / air.camera.c:.4f};  "
          f"k1 {air.camera.k1:+.4f} -> {water.camera.k1:+.4f}")
    print(f"  RMS {water.rms_px:.4f} px, max {water.max_residual_px:.4f} px over {water.views_used} views")
    print("  reprojection RMS on a held-out underwater view: "
          f"{_holdout_rms(water.camera, board, water_holdout):.3f} px with the water calibration, "
          f"{_holdout_rms(air.camera, board, water_holdout):.3f} px with the air calibration")
    for warning in water.warnings:
        print(f"  warning: {warning}")

    output.mkdir(parents=True, exist_ok=True)
    path = output / "endoscope_water.yaml"
    metadata = {**fit_metadata(water.summary(), "water", DISTANCE_M, BOARD, "calibration-demo"), "synthetic": True}
    write_calibration(path, water.camera, "synthetic_endoscope", metadata)
    from ..report import write_calibration_report

    written = write_calibration_report(water, output / "report_water")
    print(f"\ncalibration written to {path}; report in {written[0].parent}")
    return 0
