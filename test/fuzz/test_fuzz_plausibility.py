"""Plausibility instead of silence: camera models no lens could have and targets files that cannot describe the
board are refused, from a file, from a camera_info message and in measurement, while every real calibration
and layout passes."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest
import yaml
from helpers import calibrated_camera

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.calib_io import CalibrationFileError, read_calibration, to_camera_info_dict, write_calibration
from veg_area_ros.camera_info import info_to_camera
from veg_area_ros.camera_model import implausibility
from veg_area_ros.cdr import CameraInfoFields, Header
from veg_area_ros.classify import Classifier
from veg_area_ros.sim.synthetic import (
    DSLR,
    ENDOSCOPE,
    SCENE_MARKERS,
    FlatPort,
    cube_scene,
    render_scene,
    scene_targets_content,
)
from veg_area_ros.targets import TargetsError, TargetsSpec

ABSURD = [dict(k1=1e6), dict(k1=-1e3), dict(k1=-2.0), dict(p1=0.5), dict(c=1.0), dict(aspect=10.0),
          dict(xp=1e5)]


@pytest.mark.parametrize("setup", ["endoscope", "dslr"])
@pytest.mark.parametrize("medium", ["air", "water"])
def test_every_real_calibration_is_plausible(setup, medium):
    assert implausibility(calibrated_camera(setup, medium)) is None


@pytest.mark.parametrize("change", ABSURD, ids=lambda c: ",".join(f"{k}={v:g}" for k, v in c.items()))
@pytest.mark.parametrize("camera", [ENDOSCOPE, DSLR], ids=["endoscope", "dslr"])
def test_absurd_models_are_refused_from_a_file_and_from_camera_info(tmp_path, camera, change):
    absurd = dataclasses.replace(camera, **change)
    assert implausibility(absurd)
    path = tmp_path / "camera.yaml"
    write_calibration(path, absurd, "absurd")
    with pytest.raises(CalibrationFileError, match="implausible camera model"):
        read_calibration(path)
    info = to_camera_info_dict(absurd)
    fields = CameraInfoFields(Header(0, 0, "camera"), absurd.height, absurd.width, "plumb_bob",
                              info["distortion_coefficients"]["data"], info["camera_matrix"]["data"],
                              info["rectification_matrix"]["data"], info["projection_matrix"]["data"])
    with pytest.raises(ValueError, match="implausible camera model"):
        info_to_camera(fields)


def _targets(markers: dict, side: float | None = None) -> TargetsSpec:
    content = scene_targets_content(markers)
    if side is not None:
        content["marker_side_m"] = side
    return TargetsSpec.from_dict(yaml.safe_load(yaml.safe_dump(content)))


@pytest.fixture(scope="module")
def noisy_water_frame():
    return render_scene(ENDOSCOPE, cube_scene(), 0.7, FlatPort(), noise_sigma=4.0)


def _measure(frame, targets: TargetsSpec):
    return AreaMeasurer(calibrated_camera("endoscope", "water"), targets, Classifier(threshold=120)).measure(frame)


def _layouts():
    ids = sorted(SCENE_MARKERS)
    rotated = dict(zip(ids, [SCENE_MARKERS[i] for i in ids[1:] + ids[:1]], strict=True))
    swapped = dict(SCENE_MARKERS)
    swapped[ids[0]], swapped[ids[1]] = SCENE_MARKERS[ids[1]], SCENE_MARKERS[ids[0]]
    mistyped = dict(SCENE_MARKERS)
    x, y = SCENE_MARKERS[ids[2]]
    mistyped[ids[2]] = (x * 10, y)  # a decimal point slipped
    return {"ids rotated": rotated, "two ids swapped": swapped, "one coordinate x10": mistyped}


@pytest.mark.parametrize("name", list(_layouts()))
def test_a_targets_file_that_does_not_match_the_board_is_refused(noisy_water_frame, name):
    with pytest.raises(TargetsError, match="do not match the board"):
        _measure(noisy_water_frame, _targets(_layouts()[name]))


def test_marker_side_catches_a_smaller_mistyped_coordinate(noisy_water_frame):
    """A 3 cm slip on a 44 cm layout keeps every marker square (Af +3 %); each marker's side says it is wrong."""
    ids = sorted(SCENE_MARKERS)
    slipped = dict(SCENE_MARKERS)
    slipped[ids[2]] = (SCENE_MARKERS[ids[2]][0] + 0.03, SCENE_MARKERS[ids[2]][1])
    true_side = inspect.signature(cube_scene).parameters["marker_size"].default
    assert _measure(noisy_water_frame, _targets(slipped)).area_m2 > 0  # passes without the side: the limit
    with pytest.raises(TargetsError, match="marker_side_m"):
        _measure(noisy_water_frame, _targets(slipped, side=true_side))
    truth = _measure(noisy_water_frame, _targets(SCENE_MARKERS, side=true_side)).area_m2
    assert truth == pytest.approx(_measure(noisy_water_frame, _targets(SCENE_MARKERS)).area_m2)
    with pytest.raises(TargetsError, match="marker_side_m"):  # the side itself mistyped
        _measure(noisy_water_frame, _targets(SCENE_MARKERS, side=true_side * 1.1))


def test_marker_side_is_a_positive_length():
    for bad in (0, -0.05, "5 cm", float("nan"), 100):
        with pytest.raises(TargetsError, match="marker_side_m"):
            _targets(SCENE_MARKERS, side=bad)


def test_the_correct_layout_passes_at_every_noise_level():
    for sigma in (0.0, 2.0, 4.0, 8.0):
        frame = render_scene(ENDOSCOPE, cube_scene(), 0.7, FlatPort(), noise_sigma=sigma, seed=int(sigma))
        side = inspect.signature(cube_scene).parameters["marker_size"].default
        result = _measure(frame, _targets(SCENE_MARKERS, side=side))
        assert np.isfinite(result.area_m2) and result.area_m2 > 0
