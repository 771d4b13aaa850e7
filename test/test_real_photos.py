"""Af on real JPEG photos of a printed board (test/data/opencv-left: OpenCV's 13 sample photos, the copies of
../shared/data/opencv-left), measured as test/board_photos.py sets them up: the black area of the print inside
the rectangle through the outer squares' centres, the four outer inner corners as hand-picked targets, the
camera calibrated on the same photos. The photos with under 1 % of the board's pixels at 250 or more are held
to the set's spread and to their reported std; the ink's gain shifts all photos of one print alike, so the
spread between photos is what is judged, with the mean's offset only bounded."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from board_photos import SQUARE_M, board_photos, calibrated, detections, metric
from helpers import OPENCV_LEFT, OPENCV_RIGHT, UDACITY_CAMERA, shared

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.board import BoardSpec
from veg_area_ros.calibration import View
from veg_area_ros.classify import Classifier
from veg_area_ros.edge_trend import fit_edge_trend
from veg_area_ros.tone_evidence import choose_tone_curve, chosen_cases, judged_first

BOARD = "chessboard:9x6:1"
THRESHOLDS = ("otsu", 100, 120, 128, 150)


@pytest.fixture(scope="module")
def camera():
    return calibrated(str(OPENCV_LEFT), BOARD)


@pytest.fixture(scope="module")
def photos(camera):
    return board_photos(OPENCV_LEFT, BOARD, camera=camera)


def _evidence(folder, camera):
    """What `veg-area calibrate` judges on the photos (tone_evidence): each view's edge offset and white level
    under the curve it keeps. The board in metres, at the print's likely square (a 1 m square would put a
    far view tens of metres off, which the measurement refuses as a unit slip)."""
    spec = BoardSpec.parse(BOARD)
    board = replace(spec, square=SQUARE_M)
    views = [View(name, metric(detection, spec)) for name, detection in detections(str(folder), BOARD)]
    cases, judged = judged_first(chosen_cases(views, board, camera))
    return choose_tone_curve(((case, cv2.imread(str(folder / case.name), cv2.IMREAD_GRAYSCALE))
                              for case in cases), board, camera, judged)


def _with_the_others_trend(photo, camera, evidence):
    """(what the other views' edges teach, as the calibration fits it; the photo measured with it, or without a
    trend where they teach none)."""
    others = [e for e in evidence.edges[evidence.curve] if e.name != photo.name]
    learned = fit_edge_trend([e.offset_px for e in others], [e.white_dn for e in others], evidence.curve,
                             [e.std_px for e in others], [e.scale_px_per_m for e in others])
    conditions = None if learned.trend is None else {"edge_trend": learned.trend.as_dict()}
    return learned, AreaMeasurer(camera, photo.targets, Classifier(threshold="otsu"), roi=np.array(photo.roi),
                                 calibration_conditions=conditions).measure(photo.frame)


@pytest.fixture(scope="module")
def evidence(camera):
    return _evidence(OPENCV_LEFT, camera)


def _measure(photo, camera, threshold, area_mode: str = "subpixel"):
    measurer = AreaMeasurer(camera, photo.targets, Classifier(threshold=threshold), roi=np.array(photo.roi),
                            area_mode=area_mode)
    return measurer.measure(photo.frame)


def _errors(photos, camera, threshold, area_mode: str = "subpixel") -> tuple[np.ndarray, np.ndarray]:
    """Each well-exposed photo's relative error and reported relative std."""
    results = [(_measure(p, camera, threshold, area_mode), p) for p in photos if p.clipped_share < 0.01]
    return (np.array([r.area_m2 / p.true_area_m2 - 1 for r, p in results]),
            np.array([r.area_std_m2 / p.true_area_m2 for r, p in results]))


def test_the_set_has_the_seven_well_exposed_photos_and_a_known_answer(photos):
    names = sorted(p.name for p in photos if p.clipped_share < 0.01)
    assert names == ["left01.jpg", "left02.jpg", "left06.jpg", "left09.jpg", "left11.jpg", "left13.jpg",
                     "left14.jpg"]
    assert all(p.true_area_m2 == pytest.approx(27 * 0.025**2) for p in photos)  # half of the 9 x 6 squares


@pytest.mark.parametrize("threshold", [128, 150])
def test_a_shaded_photo_is_evened_whatever_the_threshold(photos, camera, threshold):
    """left13.jpg has a 25 % shading gradient across the board. At a threshold of 128 the levels were read
    deeper inside (wide edges), where the eroded white squares held too few cells for a light surface, and
    the whole flat field was dropped: Af +6.5 % (the std 2.7 %). At 150 the dim whites fell on the object's
    side and left no background to fit at all: +5.7 %, counted. Both now keep the light evened and agree with
    Otsu's threshold within 0.3 %."""
    photo = next(p for p in photos if p.name == "left13.jpg")
    chosen, otsu = _measure(photo, camera, threshold), _measure(photo, camera, "otsu")
    assert chosen.flat_field is not None and chosen.flat_field.variation > 0.2
    assert chosen.subpixel_applied
    assert abs(chosen.area_m2 / otsu.area_m2 - 1) < 0.003, (chosen.area_m2, otsu.area_m2)
    assert abs(chosen.area_m2 / photo.true_area_m2 - 1) < 0.01


@pytest.mark.parametrize("threshold", THRESHOLDS)
def test_the_default_mode_holds_on_real_photos_at_any_threshold(photos, camera, threshold):
    """Sub-pixel mode without the calibration's edge trend (a calibration that records none): the seven photos
    spread by at most 0.6 % (0.55-0.57 % measured at every threshold here; with the trend: the next test),
    every photo lies within 3 reported std of the set's mean (2.1 at most), the mean within 1 % of
    the print's black area, and at a fixed threshold the spread is well under half the count's (counting reads
    the photos' shading: 1.9-2.6 %)."""
    errors, stds = _errors(photos, camera, threshold)
    assert np.std(errors, ddof=1) <= 0.006, errors
    assert np.all(np.abs(errors - errors.mean()) <= 3 * stds), (errors, stds)
    assert abs(errors.mean()) < 0.01
    if threshold != "otsu":
        counted, _ = _errors(photos, camera, threshold, "count")
        assert np.std(errors, ddof=1) < 0.5 * np.std(counted, ddof=1), (errors, counted)
        assert np.max(np.abs(errors - errors.mean())) < np.max(np.abs(counted - counted.mean()))


def test_the_calibrations_edge_trend_holds_each_photo_learned_from_the_others(photos, camera, evidence):
    """The default mode with what the calibration records: the seven photos' edges follow their exposure
    (-0.023 px per 10 DN of white, 7.7 standard errors, the print's gain fitted beside it), and each photo
    measured with the trend learned from the other six views alone (not from itself) spreads 0.26 % (0.55 %
    without it; counting 0.48 %), its worst photo nearer the mean than counting's, every photo within 3
    reported std of the set's mean. With the trend learned from all seven, as the calibration file holds it:
    0.21 %."""
    assert evidence.edge_trend.trend is not None, evidence.edge_trend.reason
    well = [p for p in photos if p.clipped_share < 0.01]
    assert sorted(e.name for e in evidence.edges[evidence.curve]) == sorted(p.name for p in well)  # burnt-out: none
    errors, stds, counted = [], [], []
    for photo in well:
        learned, result = _with_the_others_trend(photo, camera, evidence)
        assert learned.trend is not None, (photo.name, learned.reason)
        assert result.edge_trend is not None and result.edge_trend["applied"]
        errors.append(result.area_m2 / photo.true_area_m2 - 1)
        stds.append(result.area_std_m2 / photo.true_area_m2)
        counted.append(_measure(photo, camera, "otsu", "count").area_m2 / photo.true_area_m2 - 1)
    errors, stds, counted = np.array(errors), np.array(stds), np.array(counted)
    assert np.std(errors, ddof=1) <= 0.004, errors
    assert np.std(errors, ddof=1) < np.std(counted, ddof=1), (errors, counted)
    assert np.max(np.abs(errors - errors.mean())) < np.max(np.abs(counted - counted.mean())), (errors, counted)
    assert np.all(np.abs(errors - errors.mean()) <= 3 * stds), (errors, stds)
    assert abs(errors.mean()) < 0.01


@pytest.mark.parametrize("threshold", THRESHOLDS)
def test_a_count_at_any_threshold_reports_what_the_thresholds_place_costs(photos, camera, threshold):
    """Counted at a fixed threshold the photos read the threshold's place between their own levels (at 128:
    -0.7 % to +5.2 %). The count's std said 0.9-1.0 % whatever the threshold: count mode leaves the light
    uneven, so no levels were read and the systematic part of the edge's term was dropped. The count at the
    threshold halfway between the levels the histogram shows now stands in for the shares: every photo lies
    within 3 reported std of the print's area (the ink's gain, -0.25 % in the default mode, is left in)."""
    errors, stds = _errors(photos, camera, threshold, "count")
    assert np.all(np.abs(errors) <= 3 * stds), (errors, stds)
    if threshold == 128:  # the photos whose levels' middle lies farthest from 128 say so
        assert stds.max() > 0.03 and np.argmax(stds) == np.argmax(np.abs(errors)), (errors, stds)


def test_what_is_left_follows_each_photos_exposure_and_the_shares_hold_the_rest_tighter(photos, camera):
    """The scatter left on the seven photos is common to both modes and follows each photo's white level (the
    darker photos read more black: left11 at 195 DN +1.1 %, left01 at 238 DN -0.2 %), as a camera's tone
    curve compressing its highlights would make it (the burnt-out photos continue the trend). With that
    trend taken out, the shares hold each photo within 0.13 % (sd) against counting's 0.23 %: per photo they
    are the tighter reading; the trend is what both modes share and what neither can tell from the frame."""
    measured = [(_measure(p, camera, "otsu"), _measure(p, camera, "otsu", "count"), p)
                for p in photos if p.clipped_share < 0.01]
    white = np.array([shares.levels.background for shares, _, _ in measured])
    residual_sd = {}
    for mode, errors in (("subpixel", [s.area_m2 / p.true_area_m2 - 1 for s, _, p in measured]),
                         ("count", [c.area_m2 / p.true_area_m2 - 1 for _, c, p in measured])):
        errors = np.array(errors)
        assert np.corrcoef(white, errors)[0, 1] < -0.7, (mode, white, errors)
        design = np.column_stack([np.ones_like(white), white])
        trend = np.linalg.lstsq(design, errors, rcond=None)[0]
        assert trend[1] < 0
        residual_sd[mode] = float(np.std(errors - design @ trend, ddof=2))
    assert residual_sd["subpixel"] < 0.75 * residual_sd["count"], residual_sd


def test_a_tone_curve_that_is_not_the_cameras_shifts_every_photo_alike(photos, camera):
    """OpenCV's photos read as sRGB-encoded light (`--tone-curve srgb`): every photo reads about 6 % more
    black, and they spread about 0.5 % (0.50 %; 0.55 % as grey levels), each within 3 reported std of their
    mean. The tone curve moves the mean, not the spread, on a set taken at one distance: which curve is this
    webcam's cannot be told from it (the GoPro's photos, from 20 to 135 px a square, can:
    test/test_tone_evidence.py), so its calibration records none and the values are read as they are."""
    found = {}
    for tone in ("linear", "srgb"):
        results = [(AreaMeasurer(camera, p.targets, Classifier(threshold="otsu", tone_curve=tone),
                                 roi=np.array(p.roi)).measure(p.frame), p) for p in photos if p.clipped_share < 0.01]
        errors = np.array([r.area_m2 / p.true_area_m2 - 1 for r, p in results])
        stds = np.array([r.area_std_m2 / p.true_area_m2 for r, p in results])
        assert np.std(errors, ddof=1) <= {"linear": 0.006, "srgb": 0.0055}[tone], (tone, errors)
        assert np.all(np.abs(errors - errors.mean()) <= 3 * stds), (tone, errors, stds)
        found[tone] = errors
    assert np.all(found["srgb"] - found["linear"] > 0.04), found


def test_the_other_camera_of_the_pair_the_default_mode_against_counting():
    """The right camera of the same stereo pair (test/data/opencv-right, calibrated on its own 13 photos; not
    tuned on): its nine photos with whites under 250 spread 0.71 % in the default mode without an edge trend,
    0.61 % counted: the shares alone do not beat counting on this camera. Its worst photo is 1.04 % from the
    mean against the count's 1.15 %, each within 3 reported std (2.3 at most). (Before the ROI kept the raw
    pixels that idealize past the image's edges, four of these photos lost 0.2-1.4 % of their rectangle, and
    the figures read 0.64 % against 0.67 %.) `right13.jpg` is shaded like `left13.jpg`; its white squares held
    too few 12 px cells for the light's surface, the shading stayed in the shares and it read +5.9 % (std
    4.1 %); 6 px cells fit it: +0.0 %."""
    camera = calibrated(str(OPENCV_RIGHT), BOARD)
    well = [p for p in board_photos(OPENCV_RIGHT, BOARD, camera=camera) if p.clipped_share < 0.01]
    assert len(well) == 9
    shares = [(_measure(p, camera, "otsu"), p) for p in well]
    errors = np.array([r.area_m2 / p.true_area_m2 - 1 for r, p in shares])
    stds = np.array([r.area_std_m2 / p.true_area_m2 for r, p in shares])
    counted = np.array([_measure(p, camera, "otsu", "count").area_m2 / p.true_area_m2 - 1 for p in well])
    shaded = next(r for r, p in shares if p.name == "right13.jpg")
    assert shaded.flat_field is not None and shaded.flat_field.variation > 0.2 and shaded.subpixel_applied
    assert np.std(counted, ddof=1) < np.std(errors, ddof=1) <= 1.2 * np.std(counted, ddof=1), (errors, counted)
    assert np.max(np.abs(errors - errors.mean())) < np.max(np.abs(counted - counted.mean())), (errors, counted)
    assert np.all(np.abs(errors - errors.mean()) <= 3 * stds), (errors, stds)
    assert np.std(errors, ddof=1) <= 0.0075 and abs(errors.mean()) < 0.01


def test_the_other_cameras_edge_trend_learned_from_views_filling_the_frame_holds_each_photo():
    """The right camera's calibration learns its edges' trend with exposure only with the views whose outer
    squares reach the frame's edge measured one square in (4 whole-board views otherwise, too few): -0.009 +/-
    0.003 px per 10 DN of white over 8 views, the print's gain (in proportion to each view's scale) fitted
    beside it. Each photo measured with what the others alone show (a trend where they show one clearly, else
    only their scatter): 0.62 % spread against counting's 0.61 % (0.71 % without the trend): level with
    counting, not better, on this camera; its worst photo 1.07 % from the mean against counting's 1.15 %, each
    within 1.9 reported std."""
    camera = calibrated(str(OPENCV_RIGHT), BOARD)
    evidence = _evidence(OPENCV_RIGHT, camera)
    edges = evidence.edges[evidence.curve]
    assert evidence.edge_trend.trend is not None and evidence.edge_trend.trend.learned, evidence.edge_trend.reason
    assert len(edges) == 8
    well = [p for p in board_photos(OPENCV_RIGHT, BOARD, camera=camera) if p.clipped_share < 0.01]
    errors, stds, counted, plain = [], [], [], []
    for photo in well:
        _, result = _with_the_others_trend(photo, camera, evidence)
        errors.append(result.area_m2 / photo.true_area_m2 - 1)
        stds.append(result.area_std_m2 / photo.true_area_m2)
        counted.append(_measure(photo, camera, "otsu", "count").area_m2 / photo.true_area_m2 - 1)
        plain.append(_measure(photo, camera, "otsu").area_m2 / photo.true_area_m2 - 1)
    errors, stds, counted = np.array(errors), np.array(stds), np.array(counted)
    assert np.std(errors, ddof=1) <= 0.0065 and np.std(errors, ddof=1) < 1.05 * np.std(counted, ddof=1), (
        errors, counted)
    assert np.std(errors, ddof=1) < np.std(plain, ddof=1), (errors, plain)
    assert np.max(np.abs(errors - errors.mean())) < np.max(np.abs(counted - counted.mean())), (errors, counted)
    assert np.all(np.abs(errors - errors.mean()) <= 3 * stds), (errors, stds)
    assert abs(errors.mean()) < 0.01


@pytest.mark.parametrize(("folder", "well", "spread"), [(OPENCV_LEFT, 7, 0.0025), (OPENCV_RIGHT, 9, 0.0050)])
def test_each_webcam_calibrated_on_its_own_photos_as_a_user_measures_it(tmp_path, folder, well, spread):
    """Each camera of the pair as a user measures it: `veg-area calibrate` on all its photos (the file records the
    edge trend its views show, and the reading its views favour), then every photo measured with that file in
    each mode (test/held_out_board.py `--half all`). The well-exposed photos with the shares: left 0.21 % spread
    against counting's 0.48 %, right 0.49 % against 0.61 % (its worst photo 1.03 % from the mean against
    1.15 %); every photo within 1.8 reported std of the mean in both. Unlike the leave-one-out figures above,
    each photo's own view is among those the trend was learned from. The default (auto) reads each camera as
    its views favour, each view judged with the trend of the others: the left camera's 7 views with the shares
    (0.27 % against 0.48 % counted), the right camera's 9 level (0.51 % against 0.50 %), so it counts, as
    counting does there (the shares' in-sample gain, 0.62 % against 0.61 % left out, does not show in them)."""
    import held_out_board

    rows, summary, metadata = held_out_board.check(folder, "chessboard:9x6:0.025", "air", half=held_out_board.ALL,
                                                   work=tmp_path)
    assert metadata["edge_trend"]["learned"], metadata["edge_trend"]
    assert len(held_out_board.well_exposed(rows)) == well
    shares, counted = summary["subpixel"], summary["count"]
    assert shares.spread <= spread and shares.spread < counted.spread, (shares, counted)
    assert shares.worst < counted.worst, (shares, counted)
    assert shares.within_3 == counted.within_3 == well and shares.largest_z < 2, (shares, counted)
    favoured = {"opencv-left": "subpixel", "opencv-right": "count"}[folder.name]
    assert metadata["area_mode"] == favoured, metadata["area_mode_evidence"]
    assert [row.errors["auto"] for row in rows] == [row.errors[favoured] for row in rows]


def test_no_photo_of_either_webcam_says_glare():
    """OpenCV's 26 webcam photos of a matte print, shaded up to 25 % (`left13.jpg`) and some burnt out: none of
    them is brighter than its paper's level over more than 0.1 % of the ROI, or in more than 0.25 % as many
    pixels as its black area has (half the glare mark; 0.17 % at most), and none says glare."""
    from veg_area_ros.glare import GLARE_OBJECT_SHARE

    for folder in (OPENCV_LEFT, OPENCV_RIGHT):
        camera = calibrated(str(folder), BOARD)
        for photo in board_photos(folder, BOARD, camera=camera):
            result = _measure(photo, camera, "otsu")
            assert not [w for w in result.warnings if w.startswith("glare")], (photo.name, result.warnings)
            assert result.glare is None or result.glare["share"] < 0.001, (photo.name, result.glare)
            assert result.glare is None or result.glare["object_share"] < GLARE_OBJECT_SHARE / 2, photo.name


def test_a_rectangle_past_the_idealized_images_edge_keeps_the_raw_pixels_behind_it():
    """The webcam's barrel distortion idealizes its raw corners beyond the idealized image's edges: the
    rectangle of `right09.jpg` reaches 11 px past its left edge, yet the raw frame holds every pixel of it.
    The ROI is drawn from the polygon itself there, so the raw pixels in it cover its area (to the pixel grid's
    0.1 %), and nothing is said to be cut; before, 1.4 % of it was dropped and said, and the photo read 0.9 %
    low."""
    from veg_area_ros.classify import polygon_area

    camera = calibrated(str(OPENCV_RIGHT), BOARD)
    photo = next(p for p in board_photos(OPENCV_RIGHT, BOARD, camera=camera) if p.name == "right09.jpg")
    polygon = np.array(photo.roi)
    assert polygon[:, 0].min() < -5  # past the idealized image's left edge
    measurer = AreaMeasurer(camera, photo.targets, Classifier(threshold="otsu"), roi=polygon)
    result = measurer.measure(photo.frame)
    weights, geometry = measurer.carried.weights.weights, measurer.carried.weights.geometry
    window = tuple(slice(w.start - offset, w.stop - offset)
                   for w, offset in zip(weights.window, (geometry.top, geometry.left), strict=True))
    covered = float(geometry.area[window][weights.roi > 0].sum())
    assert covered / polygon_area(polygon) == pytest.approx(1.0, abs=0.001)
    assert weights.roi_cut_share == 0.0
    assert not [w for w in result.warnings if w.startswith("the ROI reaches beyond the image")], result.warnings


def test_a_third_camera_nobody_tuned_on_the_shares_beat_counting_and_their_std_holds():
    """Udacity's lane-finding camera (test/data/udacity-camera: 1280x720 JPEG photos of a paper chessboard taped
    to a wall, not quite flat, a sheen on some black squares, crushed blacks in others), added after the
    measurement was written. 16 photos show the whole board at 1280x720 (two more are 1281x721 and are left out,
    as `veg-area calibrate` leaves them). The 15 whose first square can be read, each measured with what the
    other views alone teach: their edges do not follow exposure clearly, but they scatter 0.08 px beyond their
    own reported std about their mean (0 with a mean of their squared stds: three blurred or clipped views of
    0.2-0.45 px hid the sharp ones' 0.1-0.2 px), which is a term of each frame's std. The shares spread
    1.06 % against counting's 1.38 %, its worst photo 2.7 % from the mean against the count's 4.3 %; every photo
    within 2.3 reported std of the mean, and the std neither too small nor too large (rms of the photos' z 1.0;
    without the scatter term 1.4, and 2.95 std at most)."""
    camera = calibrated(str(UDACITY_CAMERA), BOARD)
    assert len(detections(str(UDACITY_CAMERA), BOARD)) == 16
    evidence = _evidence(UDACITY_CAMERA, camera)
    assert evidence.edge_trend.trend is not None and not evidence.edge_trend.trend.learned
    assert evidence.edge_trend.trend.scatter_px > 0.05, evidence.edge_trend.reason
    well = [p for p in board_photos(UDACITY_CAMERA, BOARD, camera=camera) if p.clipped_share < 0.01]
    assert len(well) == 15
    errors, stds, counted = [], [], []
    for photo in well:
        learned, result = _with_the_others_trend(photo, camera, evidence)
        assert learned.trend is not None and learned.trend.scatter_px > 0.05, (photo.name, learned.reason)
        errors.append(result.area_m2 / photo.true_area_m2 - 1)
        stds.append(result.area_std_m2 / photo.true_area_m2)
        counted.append(_measure(photo, camera, "otsu", "count").area_m2 / photo.true_area_m2 - 1)
    errors, stds, counted = np.array(errors), np.array(stds), np.array(counted)
    assert np.std(errors, ddof=1) < 0.85 * np.std(counted, ddof=1), (errors, counted)
    assert np.max(np.abs(errors - errors.mean())) < 0.8 * np.max(np.abs(counted - counted.mean())), (errors, counted)
    z = (errors - errors.mean()) / stds
    assert np.all(np.abs(z) <= 3), (errors, stds)
    assert 0.6 <= np.sqrt(np.mean(z**2)) <= 1.5, z


def test_the_held_out_check_calibrates_on_one_half_and_measures_the_other(tmp_path):
    """test/held_out_board.py, the check run on other people's board photos (docs/measuring.md's dome housing):
    `veg-area calibrate` on every other photo, the rest measured in both modes with that file. On OpenCV's
    webcam (7 photos calibrated on, 6 measured, 4 of them well exposed) no photo is in both halves, each
    measured one has its error and std in both modes, the targets' calliper only adds to the std, and every
    well-exposed photo lies within 3 reported std of their mean."""
    import held_out_board

    rows, summary, metadata = held_out_board.check(OPENCV_LEFT, "chessboard:9x6:0.025", "air", half=0,
                                                   model="plumb_bob", work=tmp_path)
    calibrated_on, measured = held_out_board.halves(OPENCV_LEFT, 0)
    names = {row.name for row in rows}
    assert names and names <= {p.name for p in measured} and not names & {p.name for p in calibrated_on}
    assert metadata["medium"] == "air" and (tmp_path / "calibration.yaml").is_file()
    for row in rows:
        for mode in held_out_board.MODES:
            assert abs(row.errors[mode]) < 0.06, row
            assert 0 < row.stds_without_calliper[mode] <= row.stds[mode], row
    well = sum(row.clipped_share < held_out_board.WELL_EXPOSED for row in rows)
    assert well == 4
    assert all(s.within_3 == well and s.spread > 0 for s in summary.values()), summary
    drawn = held_out_board.plot(rows, "webcam", tmp_path / "photos.png")
    assert drawn.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_charuco_webcam_video_weak_as_it_is_holds_each_frame_within_its_std():
    """The real ChArUco webcam video (test/charuco_video_board.py: calibrated on itself, a weak fit; blacks
    crushed next to 25-55 % of the edges; a sheen on the print): its calibration judges the reading on its own
    ChArUco views (their dark print inside a rectangle of found corners), the 12 its fit used (the view it
    rejected, whose corners it does not trust, spread the shares' evidence to 4.2 % and took the count), and
    records the shares (2.3 % against 2.9 % counted) with the edges' trend with exposure learned on them. The dark
    area in the 10 frames that show the four outer corners then spreads 2.40 % in the default mode, worst 4.2 %
    from the mean, against 2.73 % and 4.6 % counted: no worse than counting, every frame within 1 reported std of
    the mean, a std (5-11 %) that says how weak the reference is."""
    import charuco_video_board

    frames, recorded = charuco_video_board.measure(shared("charuco-video/cam_0.mp4"))
    assert len(frames) == 10
    assert recorded.get("area_mode") in ("subpixel", "count"), recorded.get("area_mode_evidence")
    assert recorded["views_rejected"] >= 1  # judged on the views the fit used only
    assert f"in {recorded['views_used']} views" in recorded["area_mode_evidence"], recorded["area_mode_evidence"]
    spreads, worst = {}, {}
    for mode in charuco_video_board.MODES:
        errors = np.array([f[mode][0] for f in frames])
        stds = np.array([f[mode][1] for f in frames])
        assert np.all(np.abs(errors - errors.mean()) <= stds), (mode, errors, stds)
        spreads[mode], worst[mode] = np.std(errors, ddof=1), np.max(np.abs(errors - errors.mean()))
    assert 0 < sum(f["subpixel"][2] for f in frames) < len(frames)
    assert spreads["auto"] <= spreads["count"] + 1e-12 and worst["auto"] <= worst["count"] + 1e-12, (spreads, worst)


def test_levels_given_as_the_photo_shows_them_read_the_shares_and_others_are_said(photos, camera):
    """`--levels` on a real photo: the shares were never read, whatever the levels (the classes' spreads were
    taken from the band's histogram, shading and all: 13 DN for the whites' 3.5 once evened, so the levels were
    'not told apart' and Af counted). Levels near the photo's own interiors now read the shares, within 0.3 % of
    the levels it reads itself; levels that are another light's are said in the result."""
    for photo in (p for p in photos if p.clipped_share < 0.01):
        own = _measure(photo, camera, "otsu")
        near = (round(own.levels.object), round(own.levels.background))
        given = AreaMeasurer(camera, photo.targets, Classifier(threshold="otsu"), roi=np.array(photo.roi),
                             levels=near).measure(photo.frame)
        assert given.subpixel_applied and given.levels.estimated is False, photo.name
        assert abs(given.area_m2 / own.area_m2 - 1) < 0.003, (photo.name, given.area_m2, own.area_m2)
        assert not [w for w in given.warnings if w.startswith("given levels unlike this frame")], photo.name
        far = AreaMeasurer(camera, photo.targets, Classifier(threshold="otsu"), roi=np.array(photo.roi),
                           levels=(near[0] + 20, near[1] - 40)).measure(photo.frame)
        said = [w for w in far.warnings if w.startswith("given levels unlike this frame")]
        assert said and "the object's" in said[0] and "the background's" in said[0], (photo.name, far.warnings)
