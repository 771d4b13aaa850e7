"""The calibration's own uncertainty carried to Af (camera_uncertainty): recorded by the calibration, read with
it, and checked against how Af really moves between the calibrations that a camera's views allow."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.board import BoardSpec
from veg_area_ros.calib_io import fit_metadata
from veg_area_ros.calibration import View, calibrate
from veg_area_ros.camera_uncertainty import CameraCovariance
from veg_area_ros.classify import Classifier, ClassifyError
from veg_area_ros.sim.synthetic import ENDOSCOPE, board_views, look_at_pose, render_board_views
from veg_area_ros.targets import TargetsSpec

BOARD = BoardSpec.parse("chessboard:9x6:0.02")


def test_the_covariance_is_recorded_read_back_and_refused_where_it_is_not_one():
    std = {"fx": 2.0, "fy": 2.0, "cx": 1.0, "cy": 1.0, "k1": 0.01, "k2": 0.02, "p1": 1e-4, "p2": 1e-4, "k3": 0.03}
    covariance = CameraCovariance.from_std(std, {"fx-fy": 0.9, "k1-k2": -0.8})
    assert covariance.matrix[0, 1] == pytest.approx(0.9 * 2 * 2) and covariance.matrix[4, 5] == pytest.approx(
        -0.8 * 0.01 * 0.02)
    conditions = {"camera_covariance": covariance.as_dict()}
    assert CameraCovariance.from_conditions(conditions, ENDOSCOPE) == covariance
    assert CameraCovariance.from_conditions({}, ENDOSCOPE) is None
    assert CameraCovariance.from_conditions(conditions, None) is None  # an uncalibrated frame has no camera to move
    wrong_names = {"camera_covariance": {**covariance.as_dict(), "parameters": ["fx", "fy", "cx", "cy"]}}
    asymmetric = covariance.as_dict()
    asymmetric["matrix"][0][1] += 1.0
    negative = covariance.as_dict()
    negative["matrix"][0][0] = -1.0
    for bad, said in ((wrong_names, "the camera's plumb_bob model has"), ({"camera_covariance": asymmetric},
                      "no covariance"), ({"camera_covariance": negative}, "no covariance"),
                      ({"camera_covariance": {"matrix": [[1.0]]}}, "not readable")):
        with pytest.raises(ValueError, match=said):
            CameraCovariance.from_conditions(bad, ENDOSCOPE)
        with pytest.raises(ClassifyError, match="the calibration's camera_covariance"):
            AreaMeasurer(ENDOSCOPE, TargetsSpec.from_dict({"points": [
                {"pixel": [100, 100], "plane": [0, 0]}, {"pixel": [300, 100], "plane": [0.1, 0]},
                {"pixel": [300, 300], "plane": [0.1, 0.1]}]}), Classifier(), calibration_conditions=bad)


def test_the_calibrations_covariance_says_how_far_af_moves_between_calibrations_its_views_allow():
    """Eight calibrations, each fitted on 10 of 30 rendered views (2 DN of noise), measure one frame of the board;
    the ROI is the same raw pixels under each (its outline in the white margin, so no pixel of the object
    changes sides) and the targets four inner corners three squares apart, so the scale is carried across the
    board and the calibration's error shows. Af moves between them by 0.0075 %; each calibration's covariance
    carried to Af over the board's black squares says 0.009 % (its std is the larger of the covariance's and
    the views' resampling, and the subsets share views, so the spread reads a little under it). Where the
    targets frame the board, both are ten times smaller: the targets' fit takes most of a calibration's error
    out."""
    rng = np.random.default_rng(4)
    poses = board_views(ENDOSCOPE, BOARD, 30, 0.4, rng, max_tilt_deg=30)
    images = render_board_views(ENDOSCOPE, BOARD, poses, noise_sigma=2.0, rng=np.random.default_rng(1),
                                blur_sigma_px=0.7)
    views = [View(f"view{k}", found) for k, image in enumerate(images) if (found := BOARD.detect(image)) is not None]
    assert len(views) == 30
    pose = look_at_pose(0.45, 10, -15, 5, centre=(0.06, 0.04), plane_point=(0.08, 0.05))
    frame = render_board_views(ENDOSCOPE, BOARD, [pose], noise_sigma=2.0, rng=np.random.default_rng(9),
                               blur_sigma_px=0.7)[0]
    detection = BOARD.detect(frame)
    ids = np.asarray(detection.ids).ravel()
    raw = np.asarray(detection.image_points, float).reshape(-1, 2)
    plane = np.asarray(detection.object_points, float)[:, :2]
    patch = [int(np.flatnonzero(ids == corner)[0]) for corner in (0, 3, 3 * BOARD.cols, 3 * BOARD.cols + 3)]
    targets = TargetsSpec.from_dict({"points": [{"pixel": raw[k].tolist(), "plane": plane[k].tolist()}
                                                for k in patch], "pixel_std": 0.1})
    square = BOARD.square
    low, right, bottom = -1.25 * square, (BOARD.cols + 0.25) * square, (BOARD.rows + 0.25) * square
    corners = np.array([[low, low], [right, low], [right, bottom], [low, bottom]])
    t = np.linspace(0, 1, 64, endpoint=False)[:, None]
    outline = np.concatenate([a + t * (b - a) for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True)])
    raw_outline = cv2.projectPoints(np.column_stack([outline, np.zeros(len(outline))]), *pose,
                                    *ENDOSCOPE.to_opencv())[0].reshape(-1, 2)
    areas, stds, counts = [], [], set()
    for _ in range(8):
        chosen = sorted(rng.choice(len(views), 10, replace=False))
        result = calibrate([views[k] for k in chosen], (ENDOSCOPE.width, ENDOSCOPE.height))
        metadata = fit_metadata(result.summary(), "air", None, str(BOARD), "test")
        camera = result.camera
        roi = camera.ideal().normalized_to_pixels(camera.pixels_to_normalized(raw_outline))
        measured = AreaMeasurer(camera, targets, Classifier(threshold="otsu"), roi=roi,
                                calibration_conditions=metadata).measure(frame)
        areas.append(measured.area_m2)
        stds.append(measured.calibration_std_m2)
        counts.add(measured.pixel_count)
        assert measured.area_std_m2 > measured.calibration_std_m2 > 0
    assert len(counts) == 1  # the same raw pixels under every calibration
    spread, said = np.std(areas, ddof=1), float(np.median(stds))
    assert 0.4 < spread / said < 2.0, (spread, said)
    assert abs(np.mean(areas) / (35 * square**2) - 1) < 0.01  # the board's 35 black squares
    uncalibrated_std = AreaMeasurer(camera, targets, Classifier(threshold="otsu"), roi=roi).measure(frame)
    assert uncalibrated_std.calibration_std_m2 == 0.0  # a calibration that records no covariance adds nothing
