"""The measurement as named stages (locate, region, weights, light_levels, area_terms, checks): a frame's path
through `AreaMeasurer.measure` calls each stage once or twice, in order; what a stage carries from frame to frame
is its own object (`AreaMeasurer.carried`), not an attribute of the orchestrator; the orchestrator is short and
every stage module under 400 lines. The results themselves are held by test_golden_area.py."""

from __future__ import annotations

import ast
import sys
from collections import Counter

import numpy as np
import pytest
from helpers import SOURCE, recorded_conditions

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.classify import Classifier
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets

STAGES = ("locate", "region", "weights", "light_levels", "area_terms", "checks")
PACKAGE = SOURCE / "veg_area_ros"


def _calls_from_measure(measurer: AreaMeasurer, frame: np.ndarray) -> list[str]:
    """The package modules of the Python functions `measure` itself calls, in order."""
    called = []

    def profile(frame_, event, _arg):
        if event == "call" and frame_.f_back is not None and frame_.f_back.f_code is AreaMeasurer.measure.__code__:
            path = frame_.f_code.co_filename
            if path.startswith(str(PACKAGE)) or "/veg_area_ros/" in path:
                called.append(path.rsplit("/", 1)[-1].removesuffix(".py"))

    sys.setprofile(profile)
    try:
        measurer.measure(frame)
    finally:
        sys.setprofile(None)
    return called


def test_a_frame_calls_each_stage_once_or_twice_in_order():
    frames = [render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=seed, light_gradient=0.2) for seed in range(2)]
    for area_mode in ("subpixel", "count"):
        measurer = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120), area_mode=area_mode)
        for frame in frames:  # the first frame builds what the second one carries
            called = _calls_from_measure(measurer, frame)
            visits = Counter(module for module in called if module in STAGES)
            assert set(visits) == {"locate", "weights", "light_levels", "area_terms", "checks"}, called
            assert max(visits.values()) <= 2, visits
            first = [module for k, module in enumerate(called) if module in STAGES and module not in called[:k]]
            assert first == ["locate", "weights", "light_levels", "area_terms", "checks"], called


def test_what_a_stage_carries_is_its_own_object_and_start_segment_forgets_it():
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7)
    measurer = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120))
    first = measurer.measure(frame)
    carried = measurer.carried
    assert carried.tracking.markers and carried.weights.weights is not None and carried.light.light is not None
    assert not [name for name in vars(measurer) if name.startswith("_")]  # no cache of a stage on the orchestrator
    geometry = carried.weights.geometry
    measurer.start_segment()
    assert not carried.tracking.markers and carried.tracking.last_located is None
    assert carried.weights.weights is None and carried.light.light is None
    assert carried.weights.geometry is geometry  # the camera's own, kept across segments
    assert measurer.measure(frame).summary() == first.summary()  # a first frame again: the same row


def test_a_measurer_rebuilt_for_its_conditions_carries_on_and_one_built_otherwise_starts_afresh():
    """The area node rebuilds its measurer when a calibration's conditions arrive after the first frames: the
    sequence goes on (markers tracked, not found again), so the live node's rows equal an offline run's."""
    frames = [render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=seed, noise_sigma=3.0) for seed in range(3)]
    conditions = {**recorded_conditions(ENDOSCOPE), "calibration_distance_m": 0.7}
    one = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120), calibration_conditions=conditions)
    straight = [one.measure(frame).summary() for frame in frames]
    targets = scene_targets()
    first = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120))
    unheard = first.measure(frames[0]).summary()  # the same but for saying the conditions are not known yet
    assert unheard.pop("warnings") != straight[0]["warnings"]
    assert unheard == {k: v for k, v in straight[0].items() if k != "warnings"}
    rebuilt = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120), calibration_conditions=conditions)
    assert rebuilt.carry_on_from(first) == "all" and rebuilt.carried is first.carried
    assert [rebuilt.measure(frame).summary() for frame in frames[1:]] == straight[1:]
    # what carrying changes: a measurer starting afresh at the second frame finds the markers again
    fresh = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120), calibration_conditions=conditions)
    assert fresh.measure(frames[1]).summary() != straight[1]
    # built otherwise (other targets, another tone curve to read the markers through): nothing
    for other in (AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120)),
                  AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120, tone_curve="srgb"))):
        assert other.carry_on_from(first) == "" and other.carried is not first.carried
        assert not other.carried.tracking.markers and other.carried.weights.weights is None


def _measure_counting_marker_searches(monkeypatch, measurer: AreaMeasurer, frame: np.ndarray) -> tuple:
    """The measurer's result for the frame and the shapes of the images markers were searched in meanwhile."""
    from veg_area_ros import markers

    searched = []
    detect = markers.detect_markers
    monkeypatch.setattr(markers, "detect_markers", lambda image, *args: searched.append(image.shape) or
                        detect(image, *args))
    result = measurer.measure(frame)
    monkeypatch.undo()
    return result, searched


@pytest.mark.parametrize("area_mode", ["subpixel", "count"])
def test_a_threshold_tuned_live_keeps_the_targets_place_and_reads_the_light_again(monkeypatch, area_mode):
    """A threshold tuned live (or the object, channel, area mode, levels, background) rebuilds the area node's
    measurer: the markers' tracking and the pixel weights do not depend on it and are taken over (at 10 MP the
    first frame then costs 0.06-0.09 s instead of 0.3 s), the light is found again. The next frame then searches
    no marker, builds no weights, and reads Af at the new threshold as a fresh measurer does, within a fifth of
    its std (the place carried from earlier frames against one found on this frame's noise)."""
    frames = [render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=seed, noise_sigma=3.0) for seed in range(3)]
    targets = scene_targets()
    first = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120), area_mode=area_mode)
    at_120 = [first.measure(frame) for frame in frames[:2]][-1]
    tuned = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=90), area_mode=area_mode)
    assert tuned.carry_on_from(first) == "place"
    assert tuned.carried.tracking is first.carried.tracking and tuned.carried.weights is first.carried.weights
    assert tuned.carried.light is not first.carried.light and tuned.carried.light.light is None
    carried, searched = _measure_counting_marker_searches(monkeypatch, tuned, frames[2])
    assert searched == [] and tuned.rebuilds == 1
    assert tuned.light_fits == (1 if area_mode == "subpixel" else 0)
    fresh = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=90), area_mode=area_mode).measure(frames[2])
    assert carried.threshold == fresh.threshold == 90
    assert abs(carried.area_m2 - fresh.area_m2) < 0.2 * fresh.area_std_m2
    if area_mode == "count":  # the new threshold is what was read: counted, the cube's edge pixels move
        assert abs(carried.area_m2 - at_120.area_m2) > 0.5 * fresh.area_std_m2


def test_a_roi_drawn_live_keeps_the_tracked_markers_and_the_pixel_geometry_and_builds_its_own_weights(monkeypatch):
    """A ROI drawn live (the console, `ros2 param set roi`) rebuilds the area node's measurer: the markers do not
    depend on it and are taken over with the camera's pixel geometry; the weights and the light are the new ROI's
    own. The next frame searches no marker and reads Af over the new ROI within a fifth of its std of a fresh
    measurer's (one that found the markers on this frame's noise)."""
    frames = [render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=seed, noise_sigma=3.0) for seed in range(3)]
    targets = scene_targets()
    first = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120))
    whole = [first.measure(frame) for frame in frames[:2]][-1]
    roi = [[250, 180], [320, 180], [320, 300], [250, 300]]  # the cube's left half (it spans x 280-359)
    drawn = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120), roi=roi)
    assert drawn.carry_on_from(first) == "markers"
    assert drawn.carried.tracking is first.carried.tracking
    assert drawn.carried.weights is not first.carried.weights and drawn.carried.weights.weights is None
    assert drawn.carried.weights.geometry is first.carried.weights.geometry
    assert drawn.carried.light is not first.carried.light and drawn.carried.light.light is None
    carried, searched = _measure_counting_marker_searches(monkeypatch, drawn, frames[2])
    assert searched == [] and drawn.rebuilds == 1
    fresh = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120), roi=roi).measure(frames[2])
    assert abs(carried.area_m2 - fresh.area_m2) < 0.2 * fresh.area_std_m2
    assert 0.4 < carried.area_m2 / whole.area_m2 < 0.6  # the new ROI is what was measured: half the cube


def _class_lines(path, name: str) -> int:
    tree = ast.parse(path.read_text())
    node = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == name)
    return node.end_lineno - node.lineno + 1


def test_the_orchestrator_is_short_and_each_stage_module_is_under_400_lines():
    assert _class_lines(PACKAGE / "area.py", "AreaMeasurer") < 150
    for stage in STAGES:
        text = (PACKAGE / f"{stage}.py").read_text()
        assert len(text.splitlines()) < 400, stage
        assert "exists because" in text.split('"""')[1] or "exists apart" in text.split('"""')[1], stage


def test_settings_that_replace_a_measurer_of_the_same_camera_take_over_its_cameras_work():
    """A parameter tuned live (the threshold, the ROI) rebuilds the area node's measurer: the camera's own work,
    its idealizing maps and pixel geometry (seconds at 4K for a wide-angle model OpenCV cannot map), is taken
    over from the measurer replaced where it is the same camera, and each frame reads as with a fresh measurer;
    another camera's is not taken."""
    from dataclasses import replace

    from veg_area_ros.settings import MeasurementSettings

    frames = [render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=seed, noise_sigma=3.0) for seed in range(2)]
    targets = scene_targets()
    first = MeasurementSettings(threshold=120).measurer(ENDOSCOPE, targets)
    first.measure(frames[0])
    tuned = MeasurementSettings(threshold=110)
    taken = tuned.measurer(ENDOSCOPE, targets, previous=first)
    assert taken.view is first.view and taken.carried.weights.geometry is first.carried.weights.geometry
    fresh = tuned.measurer(ENDOSCOPE, targets)
    assert fresh.view is not first.view and fresh.carried.weights.geometry is None
    assert [taken.measure(f).summary() for f in frames] == [fresh.measure(f).summary() for f in frames]
    other = tuned.measurer(replace(ENDOSCOPE, k1=ENDOSCOPE.k1 + 0.01), targets, previous=first)
    assert other.view is not first.view and other.carried.weights.geometry is None
