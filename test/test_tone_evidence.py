"""The camera's tone curve judged on its calibration views (veg_area_ros/tone_evidence.py): a chessboard's black
area inside the rectangle through its outer squares' centres is known, so each view near and far is a
measurement with a known answer; under the camera's curve the far views read as the near ones. Rendered boards
encoded with each curve (computable truth), then the real GoPro and webcam photos through `veg-area calibrate`
and `veg-area measure`."""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
import yaml
from helpers import OPENCV_LEFT, run_cli, shared

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.board import BoardSpec
from veg_area_ros.classify import Classifier, ClassifyError, polygon_roi
from veg_area_ros.settings import MeasurementSettings
from veg_area_ros.sim.synthetic import ENDOSCOPE, board_views, look_at_pose, render_board_views
from veg_area_ros.tone_evidence import (
    MAX_VIEWS,
    MIN_CELL_PX,
    board_case,
    choose_tone_curve,
    corner_rectangles,
    could_be_case,
    judged_first,
)

BOARD = BoardSpec.parse("chessboard:9x6:0.02")
CHARUCO = BoardSpec.parse("charuco:5x4:0.02:0.015:DICT_4X4_50")  # markers of 6 cells of 2.5 mm


@functools.cache
def _poses(near_and_far: bool) -> tuple:
    """Board poses at 0.25-0.7 m (squares of 13-39 px), or all at about 0.4 m and little tilted."""
    if not near_and_far:
        return tuple(board_views(ENDOSCOPE, BOARD, 10, 0.4, np.random.default_rng(3), max_tilt_deg=8))
    rng = np.random.default_rng(5)
    return tuple(pose for distance in (0.25, 0.35, 0.5, 0.7)
                 for pose in board_views(ENDOSCOPE, BOARD, 3, distance, rng, max_tilt_deg=25))


@functools.cache
def _cases(tone_curve: str, near_and_far: bool = True) -> list:
    """(case, image) of each rendered view (blur 0.7 px, 2 DN of noise) encoded with `tone_curve`."""
    images = render_board_views(ENDOSCOPE, BOARD, list(_poses(near_and_far)), noise_sigma=2.0,
                                rng=np.random.default_rng(1), blur_sigma_px=0.7, tone_curve=tone_curve)
    found = []
    for k, image in enumerate(images):
        detection = BOARD.detect(image)
        case = None if detection is None else board_case(f"view{k}", detection, BOARD, ENDOSCOPE)
        if case is not None:
            found.append((case, image))
    return found


def test_a_boards_black_area_is_measured_right_near_and_far():
    """The rendered board's black area inside its rectangle, from 13 to 39 px a square, within 0.35 % in the
    default sub-pixel mode and 0.7 % counted. The ROI is the pixels whose centre lies inside it: OpenCV's fill
    took every pixel its outline touched, and the board read +0.7 % at 38 px a square, +1.9 % at 20 px."""
    cases = _cases("linear")
    assert len(cases) >= 10
    sizes = [case.square_px for case, _ in cases]
    assert min(sizes) < 16 and max(sizes) > 35
    for case, image in cases:
        truth = case.true_area_m2(BOARD, case.first_black(image))
        for mode, bound in (("subpixel", 0.0035), ("count", 0.007)):
            result = AreaMeasurer(ENDOSCOPE, case.targets, Classifier(threshold="otsu"), roi=case.roi,
                                  area_mode=mode).measure(image)
            assert abs(result.area_m2 / truth - 1) < bound, (case.name, case.square_px, mode, result.area_m2 / truth)


def test_a_board_filling_the_frame_is_measured_one_square_in():
    """Held at 13-15 cm the board's outer squares leave the 640x480 frame while its inner corners are all found:
    such a view was no evidence (a webcam's calibration kept 4 of its 9 well-exposed views, too few to learn how
    its edges follow exposure). It is measured inside the rectangle through the centres of the squares one in
    (7 x 4 squares, half of them black), within 0.1 % in the default mode."""
    middle = (4 * BOARD.square, 2.5 * BOARD.square)
    poses = [look_at_pose(distance, tilt_x, tilt_y, roll, plane_point=middle) for distance, tilt_x, tilt_y, roll in
             ((0.14, 10, 0, 3), (0.145, 0, 10, -3), (0.135, 5, 5, 0), (0.15, -8, 4, 2), (0.13, 0, 0, 0))]
    images = render_board_views(ENDOSCOPE, BOARD, poses, noise_sigma=2.0, rng=np.random.default_rng(1),
                                blur_sigma_px=0.7)
    for image in images:
        detection = BOARD.detect(image)
        assert detection is not None
        whole = board_case("view", detection, BOARD, ENDOSCOPE, inside_only=False)
        assert whole.roi.min() < 0 or whole.roi[:, 0].max() > ENDOSCOPE.width - 1 or \
            whole.roi[:, 1].max() > ENDOSCOPE.height - 1  # the outer squares' centres leave the frame
        case = board_case("view", detection, BOARD, ENDOSCOPE)
        assert case is not None and case.inset == 1
        truth = case.true_area_m2(BOARD, case.first_black(image))
        assert truth == pytest.approx(7 * 4 / 2 * BOARD.square**2)
        assert case.edge_length_m(BOARD) == pytest.approx(2 * 7 * 4 * BOARD.square)
        result = AreaMeasurer(ENDOSCOPE, case.targets, Classifier(threshold="otsu"), roi=case.roi).measure(image)
        assert abs(result.area_m2 / truth - 1) < 0.001, result.area_m2 / truth


def test_a_roi_holds_the_pixels_whose_centre_lies_inside_it():
    """Squares of 5-60 px at random places and angles, some leaving the image: the mask holds exactly the
    pixels whose centre the polygon holds, holes likewise taken out; so the area of those inside the image is
    the polygon's on average."""
    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:120, 0:120]
    excess = []
    for _ in range(400):
        angle, side = rng.uniform(0, np.pi), rng.uniform(5, 60)
        rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        square = rng.uniform(-10, 130, 2) + (np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * side / 2) @ rotation.T
        hole = square.mean(axis=0) + (square - square.mean(axis=0)) / 3
        inside = _even_odd(u, v, square) & ~_even_odd(u, v, hole)
        if not inside.any():
            continue
        mask = polygon_roi((120, 120), square, [hole]) > 0
        assert np.array_equal(mask, inside), square
        if square.min() > 0 and square.max() < 119:
            excess.append(np.count_nonzero(mask) / (side**2 * 8 / 9) - 1)
    assert len(excess) > 100
    assert abs(np.mean(excess)) < 0.003, np.mean(excess)  # OpenCV's fill alone: +6 % on 30 px squares


def _even_odd(u: np.ndarray, v: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Whether each pixel centre lies inside the polygon, by matplotlib-free brute force: the winding of a
    convex polygon's edges (all cross products of one sign)."""
    signs = []
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        signs.append((b[0] - a[0]) * (v - a[1]) - (b[1] - a[1]) * (u - a[0]))
    signs = np.array(signs)
    return np.all(signs > 0, axis=0) | np.all(signs < 0, axis=0)


def test_the_views_share_the_cameras_work_and_each_reads_as_a_measurer_of_its_own_would():
    """The views' measurers share the camera's idealizing maps and pixel geometry (over the first view's window,
    then over the whole frame once), which are the camera's alone: each view reads, to the last bit, as a fresh
    measurer of its own reads it, both ways and under both curves. (`veg-area calibrate` of the GoPro's 37 photos
    took 35 s, each of its 102 measurers inverting the lens over the whole image again; 5 s shared, the file the
    same: docs/benchmarks.md.) The four measurements of one view share its pixel weights too: built once a view.
    A measurer refuses another camera's view."""
    from dataclasses import replace

    from veg_area_ros.idealize import IdealView
    from veg_area_ros.weights import Weighting

    cases = _cases("linear")
    built = []
    build = Weighting._build

    def counted_build(self, *args, **kwargs):
        built.append(self)
        return build(self, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Weighting, "_build", counted_build)
        choice = choose_tone_curve(cases, BOARD, ENDOSCOPE)
    assert choice.readings["srgb"] and not choice.left_out
    assert len(built) == len(cases), (len(built), len(cases))  # once a view, not once a measurement
    for curve in ("linear", "srgb"):
        readings = {reading.name: reading for reading in choice.readings[curve]}
        assert len(readings) >= 10
        for case, image in cases:
            if case.name not in readings:
                continue
            truth = case.true_area_m2(BOARD, case.first_black(image))
            fresh = [AreaMeasurer(ENDOSCOPE, replace(case.targets, distance_std_m=0.0),
                                  Classifier(threshold="otsu", tone_curve=curve), roi=case.roi,
                                  area_mode=mode).measure(image).area_m2 / truth - 1
                     for mode in ("subpixel", "count")]
            assert [readings[case.name].default_error, readings[case.name].count_error] == fresh, (curve, case.name)
    other = replace(ENDOSCOPE, k1=ENDOSCOPE.k1 + 0.01)
    case, _ = cases[0]
    with pytest.raises(ValueError, match="another camera"):
        AreaMeasurer(other, case.targets, Classifier(), view=IdealView(ENDOSCOPE))


@pytest.mark.parametrize("tone_curve", ["linear", "srgb"])
def test_the_views_near_and_far_tell_the_curve_the_camera_encodes_with(tone_curve):
    """Boards rendered from 13 to 39 px a square and encoded as a linear camera or an sRGB one: read with the
    other curve the far views drift by 2-8 % against the near ones, with the camera's within their error; the
    camera's curve is taken and the reason says the drifts."""
    choice = choose_tone_curve(_cases(tone_curve), BOARD, ENDOSCOPE)
    assert choice.decided and choice.curve == tone_curve, choice.reason
    other = "srgb" if tone_curve == "linear" else "linear"
    reach = 1 / choice.square_px[0] - 1 / choice.square_px[1]
    assert abs(choice.slopes[tone_curve]["slope"] * reach) < 0.01, choice.slopes
    assert abs(choice.slopes[other]["slope"] * reach) > 0.02, choice.slopes
    assert choice.views >= 10 and not choice.left_out
    assert f"{tone_curve} drifts the least" in choice.reason


def test_the_curve_is_judged_on_its_views_and_the_edges_on_all():
    """The tone curve is read in MAX_VIEWS views evenly over the board's sizes (both curves are measured in
    each); the edges' trend with exposure takes every view measured (up to MAX_TREND_VIEWS): a camera's few
    brightest views, which show where its edges fall away, are seldom among those picked by size."""
    from types import SimpleNamespace

    many = [SimpleNamespace(name=f"v{k}", square_px=10.0 + k) for k in range(40)]
    ordered, names = judged_first(many)
    assert len(names) == MAX_VIEWS and {"v0", "v39"} <= names
    assert {case.name for case in ordered[:MAX_VIEWS]} == names and len(ordered) == len(many)
    cases = _cases("linear")
    judged = {case.name for case, _ in cases[::2]}
    choice = choose_tone_curve(cases, BOARD, ENDOSCOPE, judged)
    assert choice.views == len(judged) < len(cases)
    assert {edge.name for edge in choice.edges["linear"]} - judged  # views outside the judged ones hold edges too
    assert len(choice.edges["linear"]) > len(judged)
    # the judged views read first: the others are read under the curve taken only, and teach the same
    first = sorted(cases, key=lambda pair: pair[0].name not in judged)
    again = choose_tone_curve(first, BOARD, ENDOSCOPE, judged)
    assert again.curve == choice.curve and again.reason == choice.reason
    other = next(curve for curve in again.edges if curve != again.curve)
    assert {edge.name for edge in again.edges[other]} <= judged
    assert [e.offset_px for e in again.edges[again.curve]] == pytest.approx(
        [e.offset_px for e in sorted(choice.edges[choice.curve], key=lambda e: e.name not in judged)])


def test_views_at_one_distance_leave_the_default_and_say_why():
    """Ten views at about 0.4 m, little tilted (squares within 1.3x of each other): not judged, linear kept,
    and the reason says to photograph the board near and far. A circle grid is not judged (no squares to read),
    nor a ChArUco board without views."""
    choice = choose_tone_curve(_cases("srgb", near_and_far=False), BOARD, ENDOSCOPE)
    assert not choice.decided and choice.curve == "linear"
    assert "too alike in distance" in choice.reason and "near and far" in choice.reason
    circles = choose_tone_curve(iter(()), BoardSpec.parse("circles:4x11:0.02"), ENDOSCOPE)
    assert not circles.decided and "circles board" in circles.reason
    charuco = choose_tone_curve(iter(()), CHARUCO, ENDOSCOPE)  # one of the boards read, with no view to read
    assert not charuco.decided and "a rectangle of its corners" in charuco.reason and "0 could be" in charuco.reason


def test_auto_reads_the_calibrations_curve_and_refuses_one_it_does_not_know():
    """`tone_curve` auto (the default) takes the curve the calibration file records, linear where it records
    none; a curve set by hand wins; an excess-green index is read as it is; a file naming an unknown curve is
    refused with its name."""
    settings = MeasurementSettings()
    assert settings.tone_curve == "auto"
    assert settings.classifier({"tone_curve": "srgb"}).tone_curve == "srgb"
    assert settings.classifier({"medium": "air"}).tone_curve == "linear"
    assert settings.classifier(None).tone_curve == "linear"
    assert MeasurementSettings(tone_curve="linear").classifier({"tone_curve": "srgb"}).tone_curve == "linear"
    assert MeasurementSettings(object="green").classifier({"tone_curve": "srgb"}).tone_curve == "linear"
    with pytest.raises(ClassifyError, match="'gamma22'"):
        settings.classifier({"tone_curve": "gamma22"})
    with pytest.raises(ClassifyError, match="tone_curve must be one of auto, linear, srgb"):
        MeasurementSettings(tone_curve="log")


def test_a_real_gopros_calibration_records_srgb_and_measure_reads_its_photos_with_it(tmp_path):
    """`veg-area calibrate` on the 35 real GoPro photos (../shared/data/gopro-wide): its 10 views with the whole
    board inside the frame, 20-135 px a square, read 4.1 % apart (far against near) as grey levels and 0.7 %
    apart through the sRGB curve: srgb is recorded with the evidence. `measure` of a photo with that file
    reads it through srgb by default (and says so), through linear when told, and an excess-green index as it
    is (said). The report draws the evidence."""
    from board_photos import board_photos

    from veg_area_ros.calib_io import read_calibration

    folder = shared("gopro-wide")
    calibration = tmp_path / "gopro.yaml"
    done = run_cli("calibrate", str(folder), "--board", "chessboard:8x6:0.025", "--medium", "air", "-o",
                   str(calibration), "-q", "--report", str(tmp_path / "report"))
    assert done.returncode == 0, done.stderr
    assert "tone curve srgb: " in done.stdout
    assert (tmp_path / "report" / "tone_curve.png").stat().st_size > 10_000  # the evidence drawn
    assert (tmp_path / "report" / "area_mode.png").stat().st_size > 10_000  # and which reading its views favour
    block = yaml.safe_load(calibration.read_text())["veg_area_ros"]
    assert block["tone_curve"] == "srgb", block.get("tone_curve_evidence")
    assert "srgb drifts the least" in block["tone_curve_evidence"]
    camera = read_calibration(calibration).camera
    photo = next(p for p in board_photos(folder, "chessboard:8x6:0.025", camera=camera) if p.name == "GOPR0059.jpg")
    targets = tmp_path / "targets.yaml"
    points = [{"pixel": [float(c) for c in pixel], "plane": [float(c) for c in plane]}
              for pixel, plane in photo.targets.points]
    targets.write_text(yaml.safe_dump({"points": points}))
    roi = ",".join(f"{c:.3f}" for corner in photo.roi for c in corner)
    measured = {}
    for option in ([], ["--tone-curve", "linear"]):
        done = run_cli("measure", str(folder / photo.name), "--calibration", str(calibration), "--targets",
                       str(targets), "--roi", roi, "--json", *option, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        measured[tuple(option)] = json.loads(done.stdout.splitlines()[-1])
        assert ("tone curve srgb, as" in done.stderr) == (not option), done.stderr
    assert measured[()]["tone_curve"] == "srgb" and measured[("--tone-curve", "linear")]["tone_curve"] == "linear"
    green = run_cli("measure", str(folder / photo.name), "--calibration", str(calibration), "--targets",
                    str(targets), "--roi", roi, "--object", "green", cwd=tmp_path)
    assert "tone curve linear: " in green.stderr and "does not apply to --object green" in green.stderr


def test_webcam_photos_at_one_distance_record_no_curve_and_say_why_and_their_edge_trend(tmp_path):
    """OpenCV's 13 webcam photos (test/data/opencv-left), all at one distance (35-43 px a square): the
    calibration records no tone curve, and says why in the output and the file. Their exposures differ (whites
    195-238 DN) and their edges follow it: the file records the trend, and `measure` of a photo with that file
    moves its edges back by the trend at its own white level, said in the row (`edge_trend`)."""
    from board_photos import board_photos

    from veg_area_ros.calib_io import read_calibration

    webcam = tmp_path / "webcam.yaml"
    done = run_cli("calibrate", str(OPENCV_LEFT), "--board", "chessboard:9x6:0.025", "--medium", "air",
                   "-o", str(webcam), "-q", "--report", str(tmp_path / "report"))
    assert done.returncode == 0, done.stderr
    assert "tone curve linear (the default): not judged" in done.stdout
    assert (tmp_path / "report" / "edge_trend.png").stat().st_size > 10_000  # the evidence drawn
    assert "edge trend with exposure: the edges follow exposure: -0.0" in done.stdout, done.stdout
    block = yaml.safe_load(webcam.read_text())["veg_area_ros"]
    assert "tone_curve" not in block and "too alike in distance" in block["tone_curve_evidence"]
    trend = block["edge_trend"]
    assert trend["views"] == 7 and trend["slope_px_per_dn"] < -3 * trend["slope_std"], trend
    assert trend["tone_curve"] == "linear" and trend["range_dn"][1] - trend["range_dn"][0] > 30
    camera = read_calibration(webcam).camera
    photo = next(p for p in board_photos(OPENCV_LEFT, "chessboard:9x6:0.025", camera=camera)
                 if p.name == "left11.jpg")  # the darkest: its black reaches farthest
    targets = tmp_path / "targets.yaml"
    points = [{"pixel": [float(c) for c in pixel], "plane": [float(c) for c in plane]}
              for pixel, plane in photo.targets.points]
    targets.write_text(yaml.safe_dump({"points": points}))
    roi = ",".join(f"{c:.3f}" for corner in photo.roi for c in corner)
    done = run_cli("measure", str(OPENCV_LEFT / photo.name), "--calibration", str(webcam), "--targets",
                   str(targets), "--roi", roi, "--json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    row = json.loads(done.stdout.splitlines()[-1])
    shift = row["edge_trend"]
    assert shift["applied"] and shift["offset_px"] > 0.03 and shift["area_m2"] < 0, shift
    assert row["edge_trend_std_m2"] > 0 and not shift["outside"]
    assert abs(row["area_m2"] / photo.true_area_m2 - 1) < abs(row["count_area_m2"] / photo.true_area_m2 - 1)
    # the calibration's own uncertainty: recorded, carried to Af, small where the targets frame the object
    assert block["camera_covariance"]["parameters"] == ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"]
    assert 0 < row["calibration_std_m2"] < 1e-3 * row["area_m2"], row["calibration_std_m2"]


def test_a_live_calibration_keeps_its_views_frames_and_judges_the_curve_on_them(monkeypatch):
    """The calibration node's store (`KeptFrames`): each kept view's grey frame, PNG-encoded (lossless), then
    judged at the fit as `veg-area calibrate` judges files: the sRGB renders near and far give srgb. A partly
    seen board keeps no frame; past the byte budget none is kept, and the reason says how many."""
    import veg_area_ros.tone_evidence as tone_evidence
    from veg_area_ros.calibration import View
    from veg_area_ros.tone_evidence import KeptFrames

    cases = _cases("srgb")
    kept = KeptFrames(BOARD)
    views = []
    for case, image in cases:
        detection = BOARD.detect(image)
        views.append(View(case.name, detection))
        kept.offer(case.name, detection, np.dstack([image] * 3))  # a colour frame is kept in grey
    assert set(kept.frames) == {case.name for case, _ in cases}
    partial = BOARD.detect(cases[0][1])
    kept.offer("partial", type(partial)(partial.image_points[:10], partial.object_points[:10], partial.ids[:10]),
               cases[0][1])
    assert "partial" not in kept.frames
    choice = kept.judge(views, ENDOSCOPE)
    assert choice.decided and choice.curve == "srgb", choice.reason

    monkeypatch.setattr(tone_evidence, "MAX_KEPT_BYTES", 1)
    small = KeptFrames(BOARD)
    for view, (_, image) in zip(views, cases, strict=True):
        small.offer(view.name, view.detection, image)
    assert len(small.frames) == 1 and small.over_budget == len(views) - 1
    assert not small.judge(views, ENDOSCOPE).decided
    assert f"({len(views) - 1} views past the first 1 kept no frame)" in small.judge(views, ENDOSCOPE).reason


def _charuco_views(tone_curve: str, distances: tuple[float, ...] = (0.15, 0.17, 0.195, 0.22)) -> list[np.ndarray]:
    """The ChArUco board rendered (blur 0.7 px, 2 DN of noise) three times at each distance, a little tilted:
    47-69 px a square at 0.15-0.22 m (marker cells of 5.9-8.6 px)."""
    middle = (2.5 * CHARUCO.square, 2 * CHARUCO.square)
    poses = [look_at_pose(distance, tilt_x, tilt_y, roll, plane_point=middle) for distance in distances
             for tilt_x, tilt_y, roll in ((12, -5, 3), (-8, 10, -4), (4, -12, 8))]
    return render_board_views(ENDOSCOPE, CHARUCO, poses, noise_sigma=2.0, rng=np.random.default_rng(1),
                              blur_sigma_px=0.7, tone_curve=tone_curve)


@functools.cache
def _charuco_cases(tone_curve: str, inverted: bool = False) -> list:
    """(case, image) of each rendered ChArUco view; `inverted`: printed white on black (light inverted)."""
    found = []
    for k, image in enumerate(_charuco_views(tone_curve)):
        image = 245 - image if inverted else image
        detection = CHARUCO.detect(image)
        assert detection is not None and detection.inverted == inverted
        case = board_case(f"view{k}", detection, CHARUCO, ENDOSCOPE)
        if case is not None:
            found.append((case, image))
    return found


def test_a_charuco_boards_dark_print_is_known_exactly_inside_any_rectangle_of_its_corners():
    """A ChArUco board's dark area inside a rectangle (its black squares and its markers' black cells, from the
    dictionary's bits as OpenCV places them) and the length of its edges there are computed exactly: they
    equal the pixels of OpenCV's own drawing at 120 px a square (where every cell is whole pixels), for the
    whole board, the rectangle through the outer squares' centres, a smaller one, and the print inverted.
    A partly found board is measured inside the largest rectangle whose four corners were found."""
    from veg_area_ros.tone_evidence import _drawn_dark

    per_square = 120
    drawing = CHARUCO.texture(per_square / CHARUCO.square) < 128  # pixel (0, 0) at squares (-0.5, -0.5)
    metres = CHARUCO.square / per_square
    for rectangle in ((0, 0, 5, 4), (0.5, 0.5, 4.5, 3.5), (1.5, 0.5, 3.5, 2.5)):
        for inverted in (False, True):
            x0, y0, x1, y1 = (round((value + 0.5) * per_square) for value in rectangle)
            dark = drawing[y0:y1, x0:x1] != inverted
            edges = np.count_nonzero(dark[:, 1:] != dark[:, :-1]) + np.count_nonzero(dark[1:] != dark[:-1])
            area_m2, edge_m = _drawn_dark(CHARUCO, rectangle, inverted)
            assert area_m2 == pytest.approx(np.count_nonzero(dark) * metres**2, rel=1e-9), (rectangle, inverted)
            assert edge_m == pytest.approx(edges * metres, rel=1e-9), (rectangle, inverted)
    cols, _ = CHARUCO.corner_grid()  # 4 x 3 corners
    assert corner_rectangles(CHARUCO, range(12))[0] == (0, 0, 3, 2)
    found = [0, 1, 2, 4, 5, 6, 8, 9, 10]  # the last column of corners not found
    assert corner_rectangles(CHARUCO, found)[0] == (0, 0, 2, 2)
    assert all({r0 * cols + c0, r0 * cols + c1, r1 * cols + c0, r1 * cols + c1} <= set(found)
               for c0, r0, c1, r1 in corner_rectangles(CHARUCO, found))
    assert corner_rectangles(CHARUCO, [0, 1, 2, 3]) == []  # one row: no rectangle


@pytest.mark.parametrize("inverted", [False, True])
def test_a_charuco_board_near_and_far_is_a_measurement_with_a_known_answer(inverted):
    """ChArUco views from 47 to 69 px a square, printed black on white or white on black: each one's dark area
    inside the rectangle through the outer squares' centres reads within 0.5 % of the print's in the default
    mode (its edges are four times a chessboard's). Views whose marker cells are under MIN_CELL_PX are no
    evidence: there the cells' interiors are too small for the levels, the view is counted, and the count's
    threshold moves every cell edge alike (more than 1 % off at 3.6 px a cell)."""
    cases = _charuco_cases("linear", inverted)
    assert len(cases) == 12
    for case, image in cases:
        truth = case.known_area_m2(CHARUCO, image)
        assert case.targets.points[0][1] == pytest.approx((CHARUCO.square, CHARUCO.square))
        result = AreaMeasurer(ENDOSCOPE, case.targets, Classifier(threshold="otsu"), roi=case.roi).measure(image)
        assert result.subpixel_applied and abs(result.area_m2 / truth - 1) < 0.005, (case.name, result.area_m2 / truth)
    far = _charuco_views("linear", (0.36,))[0]
    far = 245 - far if inverted else far
    detection = CHARUCO.detect(far)
    assert board_case("far", detection, CHARUCO, ENDOSCOPE) is None
    whole = board_case("far", detection, CHARUCO, ENDOSCOPE, inside_only=False)
    assert whole.square_px * CHARUCO.marker_cell() / CHARUCO.square < MIN_CELL_PX
    result = AreaMeasurer(ENDOSCOPE, whole.targets, Classifier(threshold="otsu"), roi=whole.roi).measure(far)
    assert abs(result.area_m2 / whole.known_area_m2(CHARUCO, far) - 1) > 0.01


@pytest.mark.parametrize("tone_curve", ["linear", "srgb"])
def test_a_charuco_boards_views_tell_the_curve_and_the_reading(tone_curve):
    """The curve is judged on ChArUco views as on a chessboard's: rendered near and far with either curve, the
    camera's is taken; the reading (shares or count) and the edges' trend are judged on them too. A live
    calibration keeps a ChArUco view's frame, and a board found without a rectangle of corners is no case."""
    from veg_area_ros.calibration import View
    from veg_area_ros.tone_evidence import KeptFrames

    cases = _charuco_cases(tone_curve)
    assert len(cases) >= 10
    choice = choose_tone_curve(cases, CHARUCO, ENDOSCOPE)
    assert choice.decided and choice.curve == tone_curve, choice.reason
    assert choice.reading is not None and choice.reading.decided and choice.reading.views == len(cases)
    assert choice.edge_trend is not None
    kept = KeptFrames(CHARUCO)
    views = []
    for case, image in cases:
        detection = CHARUCO.detect(image)
        views.append(View(case.name, detection))
        kept.offer(case.name, detection, image)
    assert set(kept.frames) == {case.name for case, _ in cases}
    assert kept.judge(views, ENDOSCOPE).curve == tone_curve
    row = views[0].detection
    one_row = type(row)(row.image_points[:4], row.object_points[:4], np.arange(4))
    assert not could_be_case(CHARUCO, one_row) and board_case("row", one_row, CHARUCO, ENDOSCOPE) is None
