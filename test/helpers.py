"""Helpers shared by the tests: data paths, running the CLI, rendering board views."""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from veg_area_ros.board import BoardSpec
from veg_area_ros.sim.synthetic import ENDOSCOPE, FlatPort, board_views, render_board_views

REPO = Path(__file__).resolve().parents[1]
SOURCE = REPO / "veg_area_ros"  # the ament_python package: the folder holding the veg_area_ros module
TEST_DATA = REPO / "test" / "data"
SHARED_DATA = REPO.parent / "shared" / "data"
OPENCV_LEFT = TEST_DATA / "opencv-left"
OPENCV_RIGHT = TEST_DATA / "opencv-right"  # the same stereo pair's other camera
UDACITY_CAMERA = TEST_DATA / "udacity-camera"  # a third camera, added as a check nobody tuned on
OPENCV_REFERENCE_RMS = 0.4087  # OpenCV 5.0 on the same 13 images (test/data/README.md)
CHESSBOARD = "chessboard:9x6:0.03"

INSTALL_PREFIX = Path(os.environ.get("VEG_AREA_PREFIX", REPO / ".venv"))


def installed(relative: str, what: str) -> Path:
    """The install prefix (.venv) when it holds `relative`; else fail under `make test` (its install step did
    not run) or skip (a plain pytest before any install)."""
    if not (INSTALL_PREFIX / relative).exists():
        if os.environ.get("VEG_AREA_REQUIRE_INSTALL"):
            pytest.fail(f"{INSTALL_PREFIX} has no {what}: the install step did not run")
        pytest.skip(f"{INSTALL_PREFIX} has no {what}; `make test` installs it")
    return INSTALL_PREFIX


def shared(relative: str) -> Path:
    """A file under ../shared/data, or skip with the reason (a user's fresh clone has no ../shared)."""
    path = SHARED_DATA / relative
    if not path.exists():
        pytest.skip(f"{path} not present: ../shared/data holds this real data on the development machines")
    return path


def children_cpu_seconds() -> float:
    """CPU seconds (user + system) of every child process this one has waited for: what a command cost, which a
    busy machine does not stretch as it stretches wall time."""
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_cli(*args: str, cwd: Path | None = None):
    """Run `veg-area` from the working tree as a user would run it; returns the CompletedProcess."""
    import subprocess

    env = dict(os.environ, PYTHONPATH=str(SOURCE))
    return subprocess.run([sys.executable, "-m", "veg_area_ros.cli", *args], capture_output=True, text=True,
                          env=env, cwd=cwd, timeout=600)


def render_views(seed: int, count: int = 15, port: FlatPort | None = None, spec: str = CHESSBOARD,
                 distance: float = 0.6):
    board = BoardSpec.parse(spec)
    rng = np.random.default_rng(seed)
    poses = board_views(ENDOSCOPE, board, count, distance, rng, port=port)
    images = render_board_views(ENDOSCOPE, board, poses, port=port, rng=rng)
    return board, poses, images


def recorded_conditions(camera, medium: str = "water") -> dict:
    """What a calibration of ours records beside a camera a test knows exactly (the renders' own): its medium,
    and a covariance of zero (the truth has no uncertainty), so nothing is said of either."""
    from veg_area_ros.camera_uncertainty import CameraCovariance

    names = camera.param_names
    return {"medium": medium,
            "camera_covariance": CameraCovariance(tuple(names), np.zeros((len(names), len(names)))).as_dict()}


def calibrated_endoscope(medium: str):
    """The synthetic endoscope calibrated in `medium` ('air' or 'water') at 0.7 m, the measuring distance,
    from 15 rendered 9x6 chessboard views (seed 3); computed once per test session."""
    return calibrated_camera("endoscope", medium)


def calibrated_camera(setup: str, medium: str):
    """A synthetic camera ('endoscope' or 'dslr') calibrated in `medium` ('air' or 'water') at 0.7 m from the
    rendered chessboard views of reproduction.SETUPS (seed 3); computed once per test session."""
    return calibration_result(setup, medium).camera


@functools.cache
def calibration_result(setup: str, medium: str):
    """The whole CalibrationResult behind `calibrated_camera` (std, correlation, ...)."""
    from veg_area_ros.sim.reproduction import CONDITIONS, SETUPS, calibrate_synthetic

    condition = next(c for c in CONDITIONS if c.name == {"air": "air", "water": "water tank"}[medium])
    return calibrate_synthetic(SETUPS[setup], condition, np.random.default_rng(3))


@functools.cache
def _fitted_conditions(setup: str, medium: str) -> str:
    import json

    from veg_area_ros.calib_io import fit_metadata

    return json.dumps(fit_metadata(calibration_result(setup, medium).summary(), medium, None, CHESSBOARD, "test"))


def fitted_conditions(setup: str, medium: str) -> dict:
    """What `veg-area calibrate` records beside `calibrated_camera(setup, medium)` (its medium, uncertainty...;
    no distance, so a test at any distance hears nothing of it)."""
    import json

    return json.loads(_fitted_conditions(setup, medium))


# a camera_info YAML as ROS camera_calibration writes it (ost.yaml), from a real 640x480 camera
OST_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [536.07, 0.0, 342.37, 0.0, 536.02, 235.54, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.2651, -0.0467, 0.0018, -0.0003, 0.2523]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [536.07, 0, 342.37, 0, 0, 536.02, 235.54, 0, 0, 0, 1, 0]
"""
