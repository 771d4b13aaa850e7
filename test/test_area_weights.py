"""Af from precomputed raw-pixel weights: agreement with the paper's idealize-then-count path,
exactness of the weights, their reuse while the targets stay put, and the windowed marker tracking."""

import cv2
import numpy as np
import pytest
from helpers import calibrated_endoscope, shared

from veg_area_ros import markers, weights
from veg_area_ros.area import AreaMeasurer
from veg_area_ros.classify import Classifier, otsu_level
from veg_area_ros.markers import RETRACK_AGREEMENT_PX, detect_markers, retrack_marker, track_markers
from veg_area_ros.sim.synthetic import DSLR, ENDOSCOPE, FlatPort, bush_scene, cube_scene, render_scene
from veg_area_ros.targets import TargetsSpec
from veg_area_ros.weights import SCALE_TOLERANCE, PixelGeometry

CUBE, BUSH = cube_scene(), bush_scene(seed=1)


def targets(scene=CUBE) -> TargetsSpec:
    return TargetsSpec.from_dict({"dictionary": scene.dictionary,
                                  "markers": {i: list(p) for i, p in scene.markers.items()}})


@pytest.fixture(scope="module")
def water_camera():
    return calibrated_endoscope("water")


@pytest.mark.parametrize("scene, classifier, tilt", [
    (CUBE, Classifier(threshold=120), 0.0),
    (CUBE, Classifier(threshold=120), 10.0),
    (CUBE, Classifier(threshold="otsu", open_px=1, close_px=1), 0.0),
    (BUSH, Classifier(threshold=120), -8.0),
    (BUSH, Classifier(threshold=168, object="green"), 0.0),  # ExG 168 = grey 120
])
def test_raw_pixel_weights_agree_with_idealize_then_count(water_camera, scene, classifier, tilt):
    """The two paths classify the object's edge differently (the remap interpolates it): they must agree
    within the edge's own sensitivity, the reference's threshold uncertainty, plus the quantization bound."""
    frame = render_scene(ENDOSCOPE, scene, 0.7, FlatPort(), tilt_deg=tilt)
    if classifier.object == "green":  # the renderer is grey: make the dark plant green, keep the markers
        grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        frame = cv2.merge([grey, 100 + grey // 2, grey])  # linear in grey: ExG = 228 - grey / 2
    measurer = AreaMeasurer(water_camera, targets(scene), classifier, area_mode="count")  # as the paper's path
    fast, reference = measurer.measure(frame), measurer.measure_idealized(frame)
    tolerance = reference.threshold_std_m2 + fast.weight_error_bound * fast.area_m2
    assert abs(fast.area_m2 - reference.area_m2) <= tolerance, (fast.area_m2, reference.area_m2, tolerance)
    assert fast.threshold == pytest.approx(reference.threshold, abs=3)
    assert abs(fast.area_m2 - scene.true_area_m2) <= fast.area_std_m2


def test_dslr_frame_agrees_too():
    frame = render_scene(DSLR, CUBE, 0.7, supersample=1)  # 10 megapixels: supersampling takes a minute
    measurer = AreaMeasurer(DSLR, targets(), Classifier(threshold=120), area_mode="count")
    fast, reference = measurer.measure(frame), measurer.measure_idealized(frame)
    assert fast.area_m2 == pytest.approx(reference.area_m2, rel=0.001)
    assert fast.area_m2 == pytest.approx(CUBE.true_area_m2, rel=0.003)


def test_weights_are_each_pixels_exact_footprint_within_the_stated_bound(water_camera):
    """Independently: every dark raw pixel whose idealized position lies in the ROI rectangle contributes
    (its idealized-image area) x (the homography's metric area there); the ROI edges are background."""
    frame = render_scene(ENDOSCOPE, CUBE, 0.7, FlatPort(), tilt_deg=6.0)
    roi = np.array([[230, 160], [410, 160], [410, 320], [230, 320]], float)
    result = AreaMeasurer(water_camera, targets(), Classifier(threshold=120), roi=roi).measure(frame)
    v, u = np.nonzero(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) <= 120)
    ideal, footprint = water_camera.pixels_to_ideal(np.column_stack([u, v]).astype(float))
    inside = np.all((ideal >= roi[0]) & (ideal <= roi[2]), axis=1)
    near_edge = np.any((np.abs(ideal - roi[0]) < 2) | (np.abs(ideal - roi[2]) < 2), axis=1)
    assert not np.any(near_edge & inside), "the test needs background at the ROI's edges"
    exact = float(np.sum(footprint[inside] * result.scale.pixel_area(ideal[inside])))
    assert result.pixel_count == np.count_nonzero(inside)
    assert 0 < result.weight_error_bound < 1e-3
    assert result.area_m2 == pytest.approx(exact, rel=result.weight_error_bound)


def test_weights_are_reused_while_the_targets_stay_and_rebuilt_when_they_move(water_camera):
    measurer = AreaMeasurer(water_camera, targets(), Classifier(threshold=120))
    steady = [render_scene(ENDOSCOPE, CUBE, 0.7, FlatPort(), seed=k) for k in range(4)]  # new sensor noise
    for frame in steady:
        reused = measurer.measure(frame)
        fresh = AreaMeasurer(water_camera, targets(), Classifier(threshold=120)).measure(frame)
        # carried to this frame's scale: only the scale tolerance and the two quantizations differ
        tolerance = reused.weight_error_bound + fresh.weight_error_bound
        assert reused.weight_error_bound <= fresh.weight_error_bound + SCALE_TOLERANCE
        assert reused.area_m2 == pytest.approx(fresh.area_m2, rel=tolerance)
    assert measurer.rebuilds == 1
    measurer.measure(render_scene(ENDOSCOPE, CUBE, 0.72, FlatPort(), roll_deg=2.0))  # the camera was bumped
    assert measurer.rebuilds == 2


def _same_weights(a, b) -> bool:
    return (a.window == b.window and np.array_equal(a.roi, b.roi) and np.array_equal(a.levels, b.levels)
            and np.array_equal(a.level_area, b.level_area))


@pytest.mark.parametrize("margin", [weights.GEOMETRY_MARGIN_PX, -20])
def test_pixel_geometry_over_the_rois_window_gives_the_whole_frames_weights(water_camera, monkeypatch, margin):
    """The raw pixels' geometry is computed over the window that can hold the ROI (its raw bounding box),
    and the weights are bit for bit those of the whole frame's geometry; a ROI that leaves the window (the
    camera closer) gets the whole frame's; a window too small (a negative margin, which never happens) is
    caught and replaced by the whole frame."""
    monkeypatch.setattr(weights, "GEOMETRY_MARGIN_PX", margin)
    height, width = ENDOSCOPE.image_size[1], ENDOSCOPE.image_size[0]
    windowed = AreaMeasurer(water_camera, targets(), Classifier(threshold=120))
    whole = AreaMeasurer(water_camera, targets(), Classifier(threshold=120))
    whole.carried.weights.geometry = PixelGeometry.build(water_camera, height, width)
    for distance in (0.7, 0.6):
        frame = render_scene(ENDOSCOPE, CUBE, distance, FlatPort(), tilt_deg=6.0)
        a, b = windowed.measure(frame), whole.measure(frame)
        assert _same_weights(windowed.carried.weights.weights, whole.carried.weights.weights)
        assert a.area_m2 == b.area_m2
        if distance == 0.7:
            assert windowed.carried.weights.geometry.full == (margin < 0)
            if margin > 0:  # the ROI's own raw window and the margin around it, and the pixel the lookup may round over
                memory = windowed.carried.weights
                geometry, (rows, columns) = memory.geometry, memory.weights.window
                assert rows.start - margin - 4 <= geometry.top and geometry.bottom <= rows.stop + margin + 4
                assert columns.start - margin - 4 <= geometry.left and geometry.right <= columns.stop + margin + 4
        else:
            assert windowed.carried.weights.geometry.full


@pytest.mark.parametrize("sigma", [2.0, 4.0])
def test_weights_survive_sensor_noise_within_their_stated_bound(water_camera, sigma):
    """Fresh sensor noise of 2 and 4 DN every frame jitters the markers' fit: no rebuild, and every carried Af
    within its weight_error_bound (plus the fresh build's own quantization) of weights built afresh for that
    very frame and fit (the same tracking state, so only the weights differ)."""
    import copy

    measurer = AreaMeasurer(water_camera, targets(), Classifier(threshold=120))
    clean = render_scene(ENDOSCOPE, CUBE, 0.7, FlatPort(), noise_sigma=0.0)
    rng = np.random.default_rng(int(sigma))
    for _ in range(20):
        noise = rng.normal(0, sigma, clean.shape[:2])[..., None]
        frame = np.clip(np.rint(clean + noise), 0, 255).astype(np.uint8)
        rebuilt = copy.deepcopy(measurer)
        rebuilt.carried.weights.weights = None  # the same markers and fit, weights built for this frame
        fresh = rebuilt.measure(frame)
        carried = measurer.measure(frame)
        bound = (carried.weight_error_bound + fresh.weight_error_bound) * fresh.area_m2
        assert abs(carried.area_m2 - fresh.area_m2) <= bound, (carried.area_m2, fresh.area_m2, bound)
        assert carried.scale_std_m2 >= fresh.scale_std_m2 * 0.999  # the carried error is in the std too
    assert measurer.rebuilds == 1


def test_markers_tracked_in_windows_match_a_full_frame_search():
    frame = render_scene(ENDOSCOPE, CUBE, 0.7, FlatPort())
    full = detect_markers(frame, CUBE.dictionary)
    tracked = track_markers(frame, CUBE.dictionary, full)
    assert set(tracked) == set(full) == set(CUBE.markers)
    for marker_id, marker in full.items():
        np.testing.assert_allclose(tracked[marker_id].corners, marker.corners, atol=0.02)
    moved = np.roll(frame, (40, -60), axis=(0, 1))  # far outside every window: found by the full search
    again = track_markers(moved, CUBE.dictionary, full)
    assert set(again) == set(full)
    np.testing.assert_allclose(again[0].centre, full[0].centre + np.array([-60, 40]), atol=0.05)


class DetectionCounter:
    """Counts the ArUco detections track_markers falls back to."""

    def __init__(self, monkeypatch):
        self.shapes = []
        real = markers.detect_markers

        def counted(image, *args, **kwargs):
            self.shapes.append(image.shape[:2])
            return real(image, *args, **kwargs)
        monkeypatch.setattr(markers, "detect_markers", counted)

    @property
    def calls(self) -> int:
        return len(self.shapes)


@pytest.mark.parametrize("camera", [ENDOSCOPE, DSLR])
def test_retracked_markers_land_where_detection_does(monkeypatch, camera):
    """A steady camera (the scene moved by a fraction of a pixel between frames, new noise): every marker is
    re-tracked without any detection, and lands where a full detection on the new frame puts it."""
    supersample = 1 if camera is DSLR else 2
    before = render_scene(camera, CUBE, 0.7, FlatPort(), supersample=supersample, seed=1)
    after = render_scene(camera, CUBE, 0.7007, FlatPort(), roll_deg=4.1, supersample=supersample, seed=2)
    previous, expected = detect_markers(before, CUBE.dictionary), detect_markers(after, CUBE.dictionary)
    assert set(previous) == set(expected) == set(CUBE.markers)
    moved = max(np.max(np.abs(expected[i].corners - previous[i].corners)) for i in expected)
    assert moved > 0.1  # the markers did move: re-tracking had work to do
    counter = DetectionCounter(monkeypatch)
    tracked = track_markers(after, CUBE.dictionary, previous, set(CUBE.markers))
    assert counter.calls == 0
    assert set(tracked) == set(CUBE.markers)
    for marker_id, marker in expected.items():
        np.testing.assert_allclose(tracked[marker_id].corners, marker.corners, atol=RETRACK_AGREEMENT_PX)


def test_an_ill_conditioned_corner_falls_back_to_detection(monkeypatch):
    """Heavy turbidity blur and noise: refinement from different starts disagrees, so the marker is detected
    instead of re-tracked, and the result is detection's."""
    blurred = dict(noise_sigma=6, blur_sigma_px=2.5, light_gradient=0.5, supersample=2)
    before = render_scene(ENDOSCOPE, CUBE, 0.6, FlatPort(), roll_deg=25, tilt_deg=10, seed=1, **blurred)
    after = render_scene(ENDOSCOPE, CUBE, 0.6006, FlatPort(), roll_deg=25.1, tilt_deg=10, seed=2, **blurred)
    previous = detect_markers(before, CUBE.dictionary)
    refused = [i for i in previous if retrack_marker(after, CUBE.dictionary, i, previous[i]) is None]
    assert refused
    counter = DetectionCounter(monkeypatch)
    tracked = track_markers(after, CUBE.dictionary, previous, set(previous))
    assert counter.calls >= len(refused)
    expected = detect_markers(after, CUBE.dictionary)
    for marker_id in refused:
        np.testing.assert_allclose(tracked[marker_id].corners, expected[marker_id].corners, atol=0.02)


def test_retracking_on_a_real_video_agrees_with_detection():
    """Real webcam frames of a ChArUco board (printed white on black, so inverted): each detected marker is
    re-tracked from starts up to 0.7 px off its corners. Most are accepted, and their centres, which set the
    scale, land within 0.2 px of detection's. Corners may differ more where the marker's refinement window is
    on the edge between two sizes (ArUco sizes it from the unrefined contour), hence the bound on centres."""
    video = cv2.VideoCapture(str(shared("charuco-video/cam_0.mp4")))
    rng = np.random.default_rng(3)
    accepted, centre_errors = 0, []
    while True:
        ok, frame = video.read()
        if not ok:
            break
        for marker_id, marker in detect_markers(255 - frame, "DICT_4X4_1000").items():
            start = marker.corners + rng.uniform(-0.7, 0.7, (4, 2))
            guess = markers.DetectedMarker(start.mean(0), start)
            again = retrack_marker(255 - frame, "DICT_4X4_1000", marker_id, guess)
            if again is not None:
                accepted += 1
                centre_errors.append(np.max(np.abs(again.centre - marker.centre)))
    video.release()
    assert accepted >= 300  # of 392 detections: refinement of the others depended on where it started
    assert max(centre_errors) < 0.2
    assert np.percentile(centre_errors, 95) < RETRACK_AGREEMENT_PX


def cover_marker(frame: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """The frame with a grey blob (a leaf) over most of a marker."""
    covered = frame.copy()
    blob = np.vstack([corners[:2], corners[:2].mean(0, keepdims=True) + 0.6 * (corners[2:] - corners[:2])[::-1]])
    cv2.fillConvexPoly(covered, np.round(blob).astype(np.int32), (70, 70, 70))
    return covered


def test_a_hidden_marker_is_sought_where_the_others_place_it(monkeypatch):
    """A leaf over marker 2 for a few frames: it is reported missing, looked for in windows around its last
    place and then where the other three place it, never in the whole frame, and measured again as soon as it
    is uncovered."""
    frame = render_scene(ENDOSCOPE, CUBE, 0.7, FlatPort())
    measurer = AreaMeasurer(ENDOSCOPE, targets(), Classifier(threshold=120))
    first = measurer.measure(frame)
    assert first.missing_targets == []
    covered = cover_marker(frame, detect_markers(frame, CUBE.dictionary)[2].corners)
    counter = DetectionCounter(monkeypatch)
    for _ in range(3):
        assert measurer.measure(covered).missing_targets == [2]
    uncovered = measurer.measure(frame)
    assert uncovered.missing_targets == []
    assert uncovered.target_pixels["marker 2"] == pytest.approx(first.target_pixels["marker 2"], abs=0.02)
    assert counter.calls >= 4  # a window or two per covered frame, and the one that found it again
    assert frame.shape[:2] not in counter.shapes


def test_an_occluded_marker_is_lost_and_found_again_when_uncovered():
    """A leaf drifting over a marker: its code no longer reads, so it is not re-tracked at its old corners, and
    it is missing; once uncovered, with no guess where it is, the whole-frame search finds it."""
    frame = render_scene(ENDOSCOPE, CUBE, 0.7, FlatPort())
    previous = detect_markers(frame, CUBE.dictionary)
    covered = cover_marker(frame, previous[2].corners)
    assert retrack_marker(covered, CUBE.dictionary, 2, previous[2]) is None
    assert retrack_marker(frame, CUBE.dictionary, 2, previous[2]) is not None
    tracked = track_markers(covered, CUBE.dictionary, previous, set(CUBE.markers))
    assert set(tracked) == set(CUBE.markers) - {2}
    again = track_markers(frame, CUBE.dictionary, tracked, set(CUBE.markers))
    assert set(again) == set(CUBE.markers)
    np.testing.assert_allclose(again[2].corners, previous[2].corners, atol=0.02)


def test_otsu_from_the_histogram_is_opencvs_otsu():
    rng = np.random.default_rng(7)
    for _ in range(200):
        n = int(rng.integers(10, 4000))
        modes = rng.uniform(0, 255, 2)
        values = np.clip(np.concatenate([rng.normal(modes[0], rng.uniform(1, 40), n // 2),
                                         rng.normal(modes[1], rng.uniform(1, 40), n - n // 2)]), 0, 255)
        values = values.astype(np.uint8)
        expected, _ = cv2.threshold(values.reshape(-1, 1), 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
        assert otsu_level(np.bincount(values, minlength=256)) == expected
