"""How a camera's edges follow its exposure (edge_trend): learned from a chessboard's views where the evidence is
clear, nowhere else; applied to a frame as its edges moved back over the object's boundary, with the slope's
uncertainty in the std. The real photos' case is in test_real_photos.py."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import recorded_conditions

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.board import BoardSpec
from veg_area_ros.classify import Classifier, ClassifyError
from veg_area_ros.edge_trend import (
    LOCAL_MIN_VIEWS,
    LOCAL_VIEWS,
    EdgeTrend,
    boundary_length_px,
    excess_scatter,
    fit_edge_trend,
)
from veg_area_ros.sim.synthetic import (
    ENDOSCOPE,
    board_views,
    cube_scene,
    render_board_views,
    render_scene,
    scene_targets,
)
from veg_area_ros.tone_evidence import board_case, choose_tone_curve


def test_a_clear_trend_is_learned_with_its_error_and_a_weak_or_narrow_one_is_not():
    rng = np.random.default_rng(0)
    whites = np.linspace(190, 240, 9)
    offsets = 0.05 - 0.003 * (whites - 215) + rng.normal(0, 0.01, whites.size)
    learned = fit_edge_trend(list(offsets), list(whites), "linear")
    assert learned.trend is not None and "follow exposure" in learned.reason
    trend = learned.trend
    assert abs(trend.slope_px_per_dn + 0.003) < 3 * trend.slope_std and trend.slope_std < 0.001
    assert trend.reference_dn == pytest.approx(whites.mean()) and trend.range_dn == (190.0, 240.0)
    assert EdgeTrend.from_dict(trend.as_dict()) == EdgeTrend.from_dict(trend.as_dict())
    flat_offsets = list(0.05 + rng.normal(0, 0.01, whites.size))
    flat = fit_edge_trend(flat_offsets, list(whites), "linear")
    assert "do not clearly follow" in flat.reason and "recorded for frames whiter or darker" in flat.reason
    # nothing learned, no scatter: recorded only to bound frames beyond the views' whites (nothing moves within)
    bound = flat.trend
    assert bound is not None and not bound.learned and bound.scatter_px == 0 and not bound.local
    assert bound.slope_px_per_dn == 0 and 0 < bound.slope_std < 0.001
    assert bound.offset_px(200.0) == (0.0, 0.0, False)
    assert bound.offset_px(260.0) == (0.0, pytest.approx(20 * bound.slope_std), True)
    assert bound.offset_px(170.0)[2] and EdgeTrend.from_dict(bound.as_dict()).slope_std > 0
    # their std covers their scatter: no scatter term; it does not: the scatter beyond it, as a std term
    assert fit_edge_trend(flat_offsets, list(whites), "linear", [0.02] * whites.size).trend.scatter_px == 0
    scattered = fit_edge_trend(flat_offsets, list(whites), "linear", [0.002] * whites.size)
    kept = scattered.trend
    assert kept is not None and not kept.learned and kept.slope_px_per_dn == 0
    assert kept.scatter_px == pytest.approx(np.sqrt(np.var(flat_offsets, ddof=1) - 0.002**2))
    assert "beyond their reported std" in scattered.reason
    # no trend: nothing moved; within the views' whites their scatter alone, beyond them the slope the views
    # could not rule out, over the distance, and said
    assert kept.slope_std > 0
    assert kept.offset_px(215.0) == (0.0, kept.scatter_px, False)
    assert kept.offset_px(300.0) == (0.0, pytest.approx(np.hypot(kept.slope_std * 60, kept.scatter_px)), True)
    assert EdgeTrend.from_dict(kept.as_dict()).slope_std == pytest.approx(kept.slope_std, abs=1e-6)
    # a file written before the std was kept (0): as then, nothing grows, nothing is said
    assert replace(kept, slope_std=0.0).offset_px(300.0) == (0.0, kept.scatter_px, False)
    assert EdgeTrend.from_dict(kept.as_dict()).scatter_px == pytest.approx(kept.scatter_px, abs=1e-4)
    narrow = fit_edge_trend(list(offsets), list(215 + 0.1 * (whites - 215)), "linear")
    assert narrow.trend is None and "too alike in exposure" in narrow.reason
    few = fit_edge_trend(list(offsets[:5]), list(whites[:5]), "linear")
    assert few.trend is None and "5 could be measured" in few.reason


def _shoulder(count: int, seed: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Views whose edges hold still from 90 to 205 DN and fall 0.12 px towards the white above 210 DN, as a
    dome housing's machine-vision camera's air photos do (92-225 DN), each with a std of 0.02 px."""
    rng = np.random.default_rng(seed)
    whites = np.concatenate([np.linspace(90, 205, count - count // 6), np.linspace(210, 225, count // 6)])
    offsets = np.where(whites >= 210, -0.12, 0.0) + rng.normal(0, 0.02, count)
    return whites, offsets, np.full(count, 0.02)


def test_many_views_give_each_frame_its_nearest_views_residuals_where_a_line_cannot_follow_them():
    """A shoulder near the top of the exposures: a line through 48 views leaves the bright views 0.08 px off
    and takes the flat ones' scatter from the bright ones. With LOCAL_MIN_VIEWS or more each frame also takes
    the mean residual of its LOCAL_VIEWS nearest views in white level (and their scatter and that mean's std):
    a bright frame is moved back to within its std of the shoulder, a middling one stays near zero with a
    smaller std than the line's, and the file holds the residuals. Fewer views keep the line alone."""
    whites, offsets, stds = _shoulder(48)
    choice = fit_edge_trend(list(offsets), list(whites), "linear", list(stds))
    trend = choice.trend
    assert trend is not None and trend.local and len(trend.residuals) == 48
    assert f"residuals of the {LOCAL_VIEWS} views nearest its white level" in choice.reason
    line_bright = trend.slope_px_per_dn * (222 - trend.reference_dn)
    assert abs(line_bright + 0.12) > 0.05  # what the line alone would leave at 222 DN
    bright, bright_std, outside = trend.offset_px(222.0)
    assert abs(bright + 0.12) < 2 * bright_std and bright_std < 0.03 and not outside
    middle, middle_std, _ = trend.offset_px(150.0)
    assert abs(middle) < 0.03 and middle_std < trend.scatter_px
    again = EdgeTrend.from_dict(trend.as_dict())
    assert again.local and again.offset_px(222.0) == pytest.approx((bright, bright_std, False), abs=1e-3)
    few = fit_edge_trend(list(offsets[::3]), list(whites[::3]), "linear", list(stds[::3])).trend
    assert len(offsets[::3]) < LOCAL_MIN_VIEWS and few is not None and not few.local
    assert "nearest" not in fit_edge_trend(list(offsets[::3]), list(whites[::3]), "linear", list(stds[::3])).reason
    # views with no shoulder: the nearest views' mean stays within its std of zero everywhere
    flat = fit_edge_trend(list(np.random.default_rng(6).normal(0, 0.02, 48)), list(whites), "linear",
                          list(stds)).trend
    for white in (95.0, 150.0, 220.0):
        offset, offset_std, _ = (flat.offset_px(white) if flat is not None else (0.0, 0.0, False))
        assert abs(offset) <= 3 * max(offset_std, 0.007), (white, offset, offset_std)


def test_a_files_residuals_that_are_not_numbers_are_refused():
    whites, offsets, stds = _shoulder(30)
    recorded = fit_edge_trend(list(offsets), list(whites), "linear", list(stds)).trend.as_dict()
    for bad in ([[200.0, float("nan"), 0.02]], [[200.0, 0.01, -0.02]], [[200.0, 0.01]], "none"):
        with pytest.raises(ValueError, match="edge_trend"):
            EdgeTrend.from_dict({**recorded, "residuals": bad})


def test_a_prints_gain_seen_nearer_in_brighter_views_is_not_taken_for_a_trend_with_exposure():
    """A print's ink gain is a reach in metres: in pixels it grows with the view's scale. Where the near views
    are also the bright ones (a GoPro's: 20-164 px a square, whites 149-163 DN) that gain alone looked like a
    trend with exposure (+0.21 px per 10 DN there, and measuring with it spread the photos 0.74 % against
    0.33 %). Given the views' scales the gain is fitted beside the trend: none is learned where there is none,
    and a real one under a gain is found within its error."""
    rng = np.random.default_rng(2)
    scales = np.linspace(800, 6500, 21)  # px per metre of the print
    whites = 149 + 14 * (scales - scales.min()) / np.ptp(scales) + rng.normal(0, 4, scales.size)
    gain = 4e-5 * scales  # 0.04 mm of ink at each edge
    offsets = gain + rng.normal(0, 0.03, scales.size)
    assert fit_edge_trend(list(offsets), list(whites), "srgb").trend.learned  # the gain passes for a trend
    fitted = fit_edge_trend(list(offsets), list(whites), "srgb", scales_px_per_m=list(scales))
    assert fitted.trend is None or not fitted.trend.learned, fitted.reason
    assert "the print's gain" in fitted.reason
    assert np.allclose(fitted.gain_px, gain - gain.mean(), atol=0.05)
    real = offsets - 0.02 * (whites - whites.mean())
    found = fit_edge_trend(list(real), list(whites), "srgb", scales_px_per_m=list(scales)).trend
    assert found is not None and found.learned
    assert abs(found.slope_px_per_dn + 0.02) < 3 * found.slope_std
    # views all at one distance: no gain to fit, the trend as before
    alike = fit_edge_trend(list(real), list(whites), "srgb", scales_px_per_m=[3000.0] * scales.size)
    assert alike.gain_px == () and "the print's gain" not in alike.reason


def test_a_few_blurred_views_neither_hide_the_sharp_ones_scatter_nor_add_to_it():
    """Sharp views (std 0.04 px) whose edges scatter 0.1 px about their mean, beside three blurred or clipped
    ones (0.3-0.45 px) that lie within their std: a mean of the squared stds (0.15 px) hid the 0.09 px beyond;
    weighed by each view's std, it is found (as on a held-out webcam's views: 0.08 px, test_real_photos), and
    views within their own std show none."""
    rng = np.random.default_rng(7)
    sharp = np.linspace(-1.0, 1.0, 12)
    sharp = 0.1 * rng.permutation(sharp - sharp.mean()) / np.std(sharp, ddof=1)  # sd 0.1 px exactly
    blurred = np.array([0.2, -0.25, 0.1])
    offsets = [*sharp, *blurred]
    stds = [0.04] * 12 + [0.3, 0.45, 0.35]
    whites = list(np.linspace(150, 160, 15))
    mean_of_squares = np.sqrt(max(np.var(offsets, ddof=1) - np.mean(np.square(stds)), 0))
    assert mean_of_squares == 0
    choice = fit_edge_trend(offsets, whites, "linear", stds)
    assert choice.trend is not None and not choice.trend.learned
    assert 0.07 < choice.trend.scatter_px < 0.12, choice.reason
    assert "beyond their reported std" in choice.reason
    residuals = np.array(offsets) - np.mean(offsets)
    scatter = excess_scatter(residuals, stds, len(offsets) - 1)
    assert np.sum(residuals**2 / (np.square(stds) + scatter**2)) == pytest.approx(len(offsets) - 1, rel=1e-6)
    within = 0.7 * np.array(stds) * np.resize([1.0, -1.0], 15)  # each view 0.7 of its own std off
    assert fit_edge_trend(list(within), whites, "linear", stds).trend.scatter_px == 0
    assert excess_scatter(within - within.mean(), stds, 14) == 0.0


def test_the_trend_is_taken_at_the_nearer_end_outside_its_views_and_its_std_grows_with_the_distance():
    trend = EdgeTrend(-0.003, 0.0005, 215.0, (195.0, 235.0), 7, 0.02, "linear")
    assert trend.offset_px(215.0) == (0.0, 0.0, False)
    inside, inside_std, outside_flag = trend.offset_px(225.0)
    assert inside == pytest.approx(-0.03) and inside_std == pytest.approx(0.005) and not outside_flag
    beyond, beyond_std, flag = trend.offset_px(255.0)
    assert beyond == pytest.approx(-0.06) and flag  # at 235, not extrapolated to 255
    assert beyond_std == pytest.approx(0.0005 * 40 + 0.003 * 20)


@pytest.mark.parametrize("value", [[], {"slope_px_per_dn": "x"}, {"slope_px_per_dn": 0.1, "slope_std": -1,
                                   "reference_dn": 200, "range_dn": [190, 210], "views": 7},
                                   {"slope_px_per_dn": 0.1, "slope_std": 0.01, "reference_dn": 250,
                                    "range_dn": [190, 210], "views": 7}])
def test_a_calibrations_unreadable_trend_is_refused_by_the_measurement(value):
    with pytest.raises(ClassifyError, match="edge_trend"):
        AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120),
                     calibration_conditions={"edge_trend": value})


def test_the_boundary_leaves_out_where_the_roi_cuts_the_object():
    roi = np.zeros((100, 100), np.uint8)
    roi[10:90, 10:90] = 255
    mask = np.zeros_like(roi)
    mask[30:60, 30:60] = 255  # a 30 px square inside: its boundary through the outer pixels' centres
    assert boundary_length_px(mask, roi) == pytest.approx(4 * 29)
    mask[:] = 0
    mask[10:40, 10:90] = 255  # a band along the ROI's top: only its lower side is the object's edge
    assert boundary_length_px(mask, roi) == pytest.approx(79, abs=2)


def test_the_correction_moves_af_by_the_offset_over_the_boundary_and_only_where_it_applies():
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7, noise_sigma=2.0)
    plain = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120),
                         calibration_conditions=recorded_conditions(ENDOSCOPE, "air")).measure(frame)
    white = max(plain.levels.object, plain.levels.background)
    trend = EdgeTrend(-0.004, 0.0005, white - 10, (white - 30, white + 30), 8, 0.02, "linear")
    conditions = {**recorded_conditions(ENDOSCOPE, "air"), "edge_trend": trend.as_dict()}
    corrected = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120),
                             calibration_conditions=conditions).measure(frame)
    shift = corrected.edge_trend
    assert shift["applied"] and shift["offset_px"] == pytest.approx(-0.04, abs=1e-4)
    # the cube's square, about 4 x 76 px at 0.7 m: the black reaches 0.04 px less far, Af grows by that band
    assert 280 < shift["boundary_px"] < 320
    metres_per_px2 = plain.count_area_m2 / plain.pixel_count
    moved = -shift["offset_px"] * shift["boundary_px"] * metres_per_px2
    assert corrected.area_m2 - plain.area_m2 == pytest.approx(moved, rel=1e-6)
    assert corrected.edge_trend_std_m2 == pytest.approx(0.0005 * 10 * shift["boundary_px"] * metres_per_px2, rel=1e-3)
    assert corrected.area_std_m2 == pytest.approx(np.hypot(plain.area_std_m2, corrected.edge_trend_std_m2))
    assert not corrected.warnings
    # another tone curve, another channel, count mode, or no calibration: not applied
    for measurer in (AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120, tone_curve="srgb"),
                                  calibration_conditions=conditions),
                     AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120, channel="red"),
                                  calibration_conditions=conditions),
                     AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120), area_mode="count",
                                  calibration_conditions=conditions),
                     AreaMeasurer(None, scene_targets(), Classifier(threshold=120), calibration_conditions=conditions)):
        said = measurer.measure(frame).edge_trend
        assert said is None if measurer.camera is None else (not said["applied"] and said["reason"]), said
    # a camera whose views' edges scatter beyond their std, with no trend: Af as it was, the scatter in its std
    only_scatter = EdgeTrend(0.0, 0.0, white, (white - 30, white + 30), 8, 0.03, "linear", False, 0.03)
    widened = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120),
                           calibration_conditions={"edge_trend": only_scatter.as_dict()}).measure(frame)
    assert widened.area_m2 == plain.area_m2 and not widened.edge_trend["applied"]
    assert widened.edge_trend_std_m2 == pytest.approx(0.03 * shift["boundary_px"] * metres_per_px2, rel=1e-3)
    # a frame whiter than every view: taken at the views' end and said
    far = EdgeTrend(-0.004, 0.0005, white - 50, (white - 60, white - 40), 8, 0.02, "linear")
    outside = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120),
                           calibration_conditions={"edge_trend": far.as_dict()}).measure(frame)
    assert outside.edge_trend["offset_px"] == pytest.approx(-0.04, abs=1e-4)
    assert any(w.startswith("exposure outside the calibration's") for w in outside.warnings), outside.warnings
    # no trend, no scatter, only the slope the views could not rule out: within their whites Af and its std as
    # without it, nothing said; whiter than every view by 20 DN, Af unmoved, its std grown by 20 slope stds, said
    for centre, grown in ((white, False), (white - 40, True)):
        bound = EdgeTrend(0.0, 0.002, centre, (centre - 20, centre + 20), 8, 0.01, "linear", False)
        bounded = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120),
                               calibration_conditions={**recorded_conditions(ENDOSCOPE, "air"),
                                                       "edge_trend": bound.as_dict()}).measure(frame)
        assert bounded.area_m2 == plain.area_m2 and not bounded.edge_trend["applied"]
        said = any(w.startswith("exposure outside the calibration's") for w in bounded.warnings)
        assert said == grown and bounded.edge_trend["outside"] == grown, bounded.warnings
        beyond = white - bounded.edge_trend["range_dn"][1]  # the file keeps the range to 0.1 DN
        expected = 0.002 * beyond * shift["boundary_px"] * metres_per_px2 if grown else 0.0
        assert bounded.edge_trend_std_m2 == pytest.approx(expected, rel=1e-3, abs=1e-15)
        assert bounded.area_std_m2 == pytest.approx(np.hypot(plain.area_std_m2, expected))


def test_a_linear_cameras_views_at_many_exposures_teach_no_trend():
    """Rendered boards (blur 0.7 px, 2 DN of noise) of a camera whose grey levels are light, whites from 164 to
    239 DN: their edges stay put (offsets within 0.02 px), so nothing is learned and nothing is corrected."""
    board = BoardSpec.parse("chessboard:9x6:0.02")
    poses = board_views(ENDOSCOPE, board, 12, 0.4, np.random.default_rng(3), max_tilt_deg=8)
    cases = []
    for k, (pose, gain) in enumerate(zip(poses, np.linspace(0.7, 1.05, 12), strict=True)):
        image = render_board_views(ENDOSCOPE, board, [pose], noise_sigma=2.0, rng=np.random.default_rng(k),
                                   blur_sigma_px=0.7, gain=gain)[0]
        detection = board.detect(image)
        case = None if detection is None else board_case(f"view{k}", detection, board, ENDOSCOPE)
        if case is not None:
            cases.append((case, image))
    choice = choose_tone_curve(cases, board, ENDOSCOPE)
    whites = [e.white_dn for e in choice.edges[choice.curve]]
    offsets = [e.offset_px for e in choice.edges[choice.curve]]
    assert len(whites) >= 8 and max(whites) - min(whites) > 50, whites
    assert np.max(np.abs(offsets)) < 0.03, offsets
    assert not choice.edge_trend.trend.learned and "do not clearly follow" in choice.edge_trend.reason
    assert not choice.as_dict()["edge_trend"]["learned"]
    # recorded without a slope or scatter: a frame within the views' whites is not moved, one beyond is said
    recorded = choice.metadata()["edge_trend"]
    assert not recorded["learned"] and recorded["slope_px_per_dn"] == 0 and recorded["scatter_px"] == 0
