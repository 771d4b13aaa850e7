"""Af a researcher can publish: sub-pixel area, an uncertainty that covers the truth at any orientation (edges
along the pixel grid included), and an object off the targets' plane."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import calibrated_camera, fitted_conditions

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.classify import (
    PURE_ZONE_SPREADS,
    Classifier,
    ClassifyError,
    LevelEstimator,
    Levels,
    otsu_level,
    to_light,
)
from veg_area_ros.sim.reproduction import CONDITIONS
from veg_area_ros.sim.synthetic import (
    DSLR,
    ENDOSCOPE,
    FlatPort,
    bush_scene,
    cube_scene,
    empty_scene,
    render_scene,
    twig_scene,
)
from veg_area_ros.targets import TargetsError, TargetsSpec

# a square target frame: it stays in view of the endoscope under water when the scene is rolled by 90°
SQUARE_MARKERS = {0: (-0.15, -0.15), 1: (0.15, -0.15), 2: (0.15, 0.15), 3: (-0.15, 0.15)}
CAMERAS = {"endoscope": ENDOSCOPE, "dslr": DSLR}


def targets_for(scene, **extra) -> TargetsSpec:
    return TargetsSpec.from_dict({"dictionary": scene.dictionary,
                                  "markers": {i: list(xy) for i, xy in scene.markers.items()}, **extra})


def cube_scenes() -> list[dict]:
    """52 cube scenes: each camera in air and water, random cube size, sub-pixel position (the scene's origin
    moved by up to 4 mm, several pixels), distance 0.66-0.74 m and roll; the rolls include exactly 0° and 90°
    (edges along the pixel rows and columns) in every group."""
    rng = np.random.default_rng(14)
    plan = [("endoscope", "air", 16), ("endoscope", "water", 16), ("dslr", "air", 10), ("dslr", "water", 10)]
    scenes = []
    for camera, medium, count in plan:
        for k in range(count):
            roll = [0.0, 90.0, 0.0, 90.0][k] if k < 4 else float(rng.uniform(-180, 180))
            scenes.append(dict(camera=camera, medium=medium, side=float(rng.uniform(0.08, 0.12)), roll=roll,
                               centre=tuple(rng.uniform(-0.004, 0.004, 2)), distance=float(rng.uniform(0.66, 0.74)),
                               seed=k))
    return scenes


@pytest.fixture(scope="module")
def cube_results():
    """Every cube scene measured in both modes: (scene, {mode: (relative error, relative std)})."""
    results = []
    for plan in cube_scenes():
        scene = cube_scene(side=plan["side"], markers=SQUARE_MARKERS,
                           pixels_per_metre=2000.0 if plan["camera"] == "endoscope" else 6000.0)
        frame = render_scene(CAMERAS[plan["camera"]], scene, plan["distance"],
                             FlatPort() if plan["medium"] == "water" else None, roll_deg=plan["roll"],
                             centre=plan["centre"], seed=plan["seed"],
                             supersample=3 if plan["camera"] == "endoscope" else 1)
        camera = calibrated_camera(plan["camera"], plan["medium"])
        modes = {}
        for mode in ("subpixel", "count"):
            measurer = AreaMeasurer(camera, targets_for(scene), Classifier(threshold="otsu"), area_mode=mode)
            result = measurer.measure(frame)
            modes[mode] = (result.area_m2 / scene.true_area_m2 - 1, result.area_std_m2 / scene.true_area_m2)
        results.append((plan, modes))
    return results


def _table(results, mode: str) -> str:
    return "\n".join(f"{p['camera']} {p['medium']} roll {p['roll']:7.2f} d {p['distance']:.3f}: "
                     f"{100 * m[mode][0]:+.3f} % ± {100 * m[mode][1]:.3f} %" for p, m in results)


def test_the_scenes_include_edges_along_the_pixel_grid(cube_results):
    for camera in CAMERAS:
        for medium in ("air", "water"):
            rolls = [p["roll"] for p, _ in cube_results if p["camera"] == camera and p["medium"] == medium]
            assert 0.0 in rolls and 90.0 in rolls
    assert len(cube_results) >= 50


@pytest.mark.parametrize("camera,limit", [("endoscope", 0.002), ("dslr", 0.001)])
def test_subpixel_area_is_right_at_every_position_and_orientation(cube_results, camera, limit):
    errors = [m["subpixel"][0] for p, m in cube_results if p["camera"] == camera]
    assert max(abs(e) for e in errors) <= limit, _table(cube_results, "subpixel")


@pytest.mark.parametrize("mode", ["subpixel", "count"])
def test_the_reported_uncertainty_covers_the_true_error(cube_results, mode):
    ratios = np.array([abs(m[mode][0]) / m[mode][1] for _, m in cube_results])
    assert np.mean(ratios <= 2) >= 0.9, _table(cube_results, mode)
    assert ratios.max() <= 3, _table(cube_results, mode)


@pytest.mark.parametrize(("medium", "limit"), [("air", 0.002), ("water", 0.0013)])
@pytest.mark.parametrize(("first_phase", "second_step", "first_seed"), [(0.0, 0.037, 0), (0.05, 0.61, 100)],
                         ids=["tenths", "held-out-phases"])
def test_subpixel_area_holds_at_every_edge_phase(medium, limit, first_phase, second_step, first_seed):
    """The cube's edges along the pixel grid, moved with its markers across one whole pixel in tenths (the
    phase of every edge in its pixel): Af within 0.2 % in air and 0.13 % under water at every phase and within
    2 std, while the count swings by several times that. What is left of the phase in air (-0.15 to +0.17 %)
    is the markers' corners, not the shares: ArUco's corner refinement moves a marker's centre with the phase
    by up to 0.25 px and the plane's scale by 0.14 % (with the true corners Af stays within -0.01..+0.03 %).
    The second set shifts every phase by half a step, walks the other axis by 0.61 px and draws other noise,
    so the bound is not met on the ten phases it was measured on alone (there: -0.18 to +0.16 % in air)."""
    metres_per_pixel = 0.7 / ENDOSCOPE.fx / (1.333 if medium == "water" else 1.0)
    camera = calibrated_camera("endoscope", medium)
    errors = {"subpixel": [], "count": []}
    for k in range(10):
        scene = cube_scene(side=0.1, markers=SQUARE_MARKERS, pixels_per_metre=2000.0)
        frame = render_scene(ENDOSCOPE, scene, 0.7, FlatPort() if medium == "water" else None, roll_deg=0.0,
                             centre=((first_phase + 0.1 * k) * metres_per_pixel,
                                     (second_step * k % 1.0) * metres_per_pixel), seed=first_seed + k)
        for mode in errors:
            result = AreaMeasurer(camera, targets_for(scene), Classifier(threshold="otsu"),
                                  area_mode=mode).measure(frame)
            error = result.area_m2 / scene.true_area_m2 - 1
            errors[mode].append(error)
            if mode == "subpixel":
                assert abs(error) <= limit and abs(error) * scene.true_area_m2 <= 2 * result.area_std_m2, (k, error)
    swing = {mode: max(values) - min(values) for mode, values in errors.items()}
    assert swing["count"] > 3 * swing["subpixel"], swing


def test_counting_errs_on_aligned_edges_where_subpixel_does_not(cube_results):
    """The weakness sub-pixel mode removes shows in the same scenes: edges along the grid (0°, 90°) make the
    count err several times more than the sub-pixel area."""
    aligned = [m for p, m in cube_results if p["roll"] in (0.0, 90.0) and p["camera"] == "endoscope"]
    count = max(abs(m["count"][0]) for m in aligned)
    subpixel = max(abs(m["subpixel"][0]) for m in aligned)
    assert count > 0.003 and count > 3 * subpixel, (count, subpixel)


@pytest.mark.parametrize("medium", ["air", "water"])
@pytest.mark.parametrize("offset", [-0.05, -0.02, 0.02, 0.05])
def test_an_object_off_the_targets_plane(medium, offset):
    scene = cube_scene(markers=SQUARE_MARKERS)
    frame = render_scene(ENDOSCOPE, scene, 0.7, FlatPort() if medium == "water" else None, roll_deg=0.0,
                         object_offset=offset)
    camera = calibrated_camera("endoscope", medium)
    result = AreaMeasurer(camera, targets_for(scene, object_plane_offset_m=offset), Classifier()).measure(frame)
    error = result.area_m2 / scene.true_area_m2 - 1
    assert abs(error) <= 0.005 and abs(error) * scene.true_area_m2 <= 3 * result.area_std_m2, error
    # the offset's 2 mm default uncertainty is in the std: about 2 x 2 mm / 0.7 m of Af
    assert result.plane_offset_std_m2 / result.area_m2 == pytest.approx(2 * 0.002 / (0.7 + offset), rel=0.15)
    assert result.summary()["object_plane_offset_m"] == offset
    ignored = AreaMeasurer(camera, targets_for(scene), Classifier()).measure(frame)
    assert abs(ignored.area_m2 / scene.true_area_m2 - 1) > 0.04  # what taking the targets' plane costs


def test_an_offset_needs_four_targets_and_a_calibration():
    scene = cube_scene(markers=SQUARE_MARKERS)
    two = {"dictionary": scene.dictionary, "markers": {0: [-0.15, -0.15], 1: [0.15, -0.15]}}
    with pytest.raises(TargetsError, match="needs 4 or more targets"):
        TargetsSpec.from_dict({**two, "object_plane_offset_m": 0.03})
    with pytest.raises(TargetsError, match="without 'object_plane_offset_m'"):
        TargetsSpec.from_dict({**two, "object_plane_offset_std_m": 0.001})
    spec = targets_for(scene, object_plane_offset_m=0.03)
    assert spec.object_plane_offset_std_m == 0.002
    with pytest.raises(TargetsError, match="needs a calibration"):
        AreaMeasurer(None, spec, Classifier()).measure(render_scene(ENDOSCOPE, scene, 0.7, roll_deg=0.0))
    # a frame where only three of the four markers are found cannot give the plane's pose
    frame = render_scene(ENDOSCOPE, scene, 0.7, roll_deg=0.0, object_offset=0.03)
    covered = frame.copy()
    u, v = AreaMeasurer(ENDOSCOPE, targets_for(scene), Classifier()).measure(frame).scale.plane_to_pixels(
        np.array([[0.15, 0.15]]))[0]
    covered[int(v) - 30:int(v) + 30, int(u) - 30:int(u) + 30] = 200
    with pytest.raises(TargetsError, match="4 or more targets found"):
        AreaMeasurer(ENDOSCOPE, spec, Classifier()).measure(covered)


@pytest.mark.parametrize("widths", [(0.0015, 0.0025, 0.004), (0.001, 0.0015, 0.002)])
def test_thin_branches_gain_in_subpixel_mode(widths):
    """Twigs 1-3 endoscope pixels wide at 0.7 m under water: the sub-pixel area is nearer the truth than the
    count, at a fixed threshold and at Otsu's."""
    scene = twig_scene(widths)
    frame = render_scene(ENDOSCOPE, scene, 0.7, FlatPort(), roll_deg=0.0)
    camera = calibrated_camera("endoscope", "water")
    for threshold in (120, "otsu"):
        errors = {}
        for mode in ("subpixel", "count"):
            result = AreaMeasurer(camera, targets_for(scene), Classifier(threshold=threshold),
                                  area_mode=mode).measure(frame)
            errors[mode] = result.area_m2 / scene.true_area_m2 - 1
            assert abs(errors[mode]) * scene.true_area_m2 <= 3 * result.area_std_m2, (mode, threshold, errors)
        assert abs(errors["subpixel"]) <= 0.01 and abs(errors["subpixel"]) < abs(errors["count"]), errors


@pytest.mark.parametrize("condition", ["water tank", "flume"])
def test_bush_subpixel_is_no_worse_than_count(condition):
    """The bush at 0.7 m, in the water tank and in the flume (noise 4 DN, blur, 30 % uneven light): the
    sub-pixel error and std are no larger than the count's. In the flume the light is evened first (the
    background's surface fitted to the frame) and the shares hold there too."""
    setting = next(c for c in CONDITIONS if c.name == condition)
    scene = bush_scene()
    frame = render_scene(ENDOSCOPE, scene, 0.7, setting.port, roll_deg=0.0, noise_sigma=setting.noise_sigma,
                         blur_sigma_px=setting.blur_fraction * 640, light_gradient=setting.light_gradient)
    camera = calibrated_camera("endoscope", "water")
    results = {mode: AreaMeasurer(camera, targets_for(scene), Classifier(threshold=120), area_mode=mode).measure(frame)
               for mode in ("subpixel", "count")}
    errors = {mode: abs(r.area_m2 / scene.true_area_m2 - 1) for mode, r in results.items()}
    assert errors["subpixel"] <= errors["count"] + 1e-12, errors
    assert results["subpixel"].area_std_m2 <= results["count"].area_std_m2 + 1e-12
    assert errors["subpixel"] * scene.true_area_m2 <= 2 * results["subpixel"].area_std_m2
    summary = results["subpixel"].summary()
    assert summary["subpixel_applied"] is True and errors["subpixel"] < 0.005
    assert (summary["light"] is not None) == (condition == "flume")
    if condition == "flume":
        assert summary["light"]["evened_by"] == "fitted" and 0.1 < summary["light"]["variation"] < 0.6


def test_levels_from_a_histogram_and_the_fractions_they_give():
    rng = np.random.default_rng(5)
    values = np.concatenate([rng.normal(40, 2, 4000), rng.normal(200, 2, 40000), rng.uniform(40, 200, 500)])
    counts = np.bincount(np.clip(np.rint(values), 0, 255).astype(int), minlength=256)
    levels = LevelEstimator(counts, object_is_high=False).at(120)
    assert levels.object == pytest.approx(40, abs=0.3) and levels.background == pytest.approx(200, abs=0.3)
    assert levels.object_spread == pytest.approx(2, rel=0.2) and levels.background_spread == pytest.approx(2, rel=0.2)
    fractions = levels.fractions()
    assert fractions[120] == pytest.approx(0.5, abs=0.01)
    assert fractions[200] == 0 and fractions[255] == 0 and fractions[40] == 1 and fractions[0] == 1
    zone = PURE_ZONE_SPREADS * max(levels.object_spread, levels.background_spread)  # either side, in DN
    nearest_mixed = int(np.ceil(levels.background - zone)) - 1
    assert fractions[nearest_mixed + 1:].max() == 0 and 0 < fractions[nearest_mixed] < 0.1
    assert fractions[:int(levels.object + zone)].min() == 1 and fractions[int(np.ceil(levels.object + zone)) + 1] < 1
    bright = LevelEstimator(counts[::-1], object_is_high=True).at(135)
    assert bright.object == pytest.approx(215, abs=0.3)
    assert bright.fractions()[255 - 120] == pytest.approx(0.5, abs=0.01)
    assert LevelEstimator(np.bincount([200] * 10, minlength=256), False).at(120) is None  # no object class
    uneven = np.concatenate([rng.normal(40, 2, 4000), rng.uniform(140, 230, 40000)])
    flat = np.bincount(np.clip(np.rint(uneven), 0, 255).astype(int), minlength=256)
    assert not LevelEstimator(flat, False).at(120).resolvable()
    assert Levels(40, 200, 1, 1).resolvable()


def test_area_mode_and_levels_are_validated():
    scene = cube_scene()
    with pytest.raises(ClassifyError, match="area mode"):
        AreaMeasurer(None, targets_for(scene), Classifier(), area_mode="fractional")
    with pytest.raises(ClassifyError, match="too close"):
        AreaMeasurer(None, targets_for(scene), Classifier(), levels=(100, 102))
    with pytest.raises(ClassifyError, match=r"0\.\.255"):
        AreaMeasurer(None, targets_for(scene), Classifier(), levels=(-5, 200))


def test_given_levels_are_used_and_the_terms_are_reported():
    scene = cube_scene()
    frame = render_scene(ENDOSCOPE, scene, 0.7, roll_deg=0.0)
    camera = calibrated_camera("endoscope", "air")
    result = AreaMeasurer(camera, targets_for(scene), Classifier(), levels=(40, 200)).measure(frame)
    summary = result.summary()
    assert summary["levels"]["estimated"] is False and summary["levels"]["object"] == 40
    assert summary["area_mode"] == "subpixel" and summary["discretisation_std_m2"] == 0
    terms = [summary[k] for k in ("scale_std_m2", "threshold_std_m2", "levels_std_m2", "plane_offset_std_m2")]
    assert summary["area_std_m2"] == pytest.approx(np.sqrt(sum(t * t for t in terms)), rel=1e-9)
    assert summary["levels_std_m2"] > 0 and summary["edge_length_px"] > 200
    assert abs(result.area_m2 / scene.true_area_m2 - 1) < 0.002
    count = AreaMeasurer(camera, targets_for(scene), Classifier(), area_mode="count").measure(frame).summary()
    assert count["discretisation_std_m2"] > 0 and count["levels_std_m2"] == 0
    assert count["area_m2"] == count["count_area_m2"]


def test_subpixel_with_morphological_clean_up():
    """Opening and closing act on the binary mask; the shares then come from its one-pixel rings inside and
    outside: the aligned cube stays within 0.2 %, where the cleaned count errs several times more."""
    scene = cube_scene(markers=SQUARE_MARKERS)
    frame = render_scene(ENDOSCOPE, scene, 0.72, FlatPort(), roll_deg=0.0, noise_sigma=2.0)
    camera = calibrated_camera("endoscope", "water")
    classifier = Classifier(threshold=120, open_px=1, close_px=1)
    errors = {mode: AreaMeasurer(camera, targets_for(scene), classifier, area_mode=mode).measure(frame).area_m2
              / scene.true_area_m2 - 1 for mode in ("subpixel", "count")}
    assert abs(errors["subpixel"]) <= 0.002 and abs(errors["subpixel"]) < abs(errors["count"]), errors


@pytest.mark.parametrize("roll", [0.0, 6.0])  # the markers stay in view of the wide frame
def test_dslr_bush_in_the_flume_reads_its_levels_as_deep_inside_as_the_blur_reaches(roll):
    """The DSLR's bush in the flume: its blur (7 px sd at 3872x2592) is wider than the 3 px interior where
    sharper frames read their levels, so 3 px inside the twigs the object's level read 57 DN (truly 40), the
    levels looked unresolvable and sub-pixel mode counted whole pixels (+2.0 % ± 3.6 % in the paper table).
    Read deeper until the levels settle, both the frame's own light and a background frame give shares
    within 0.6 %, within 3 std, with nothing to warn about."""
    setting = next(c for c in CONDITIONS if c.name == "flume")
    scene = bush_scene(pixels_per_metre=6000.0, oversample=3)  # reproduction.SETUPS["dslr"]
    flume = {"noise_sigma": setting.noise_sigma, "blur_sigma_px": setting.blur_fraction * DSLR.width,
             "light_gradient": setting.light_gradient, "supersample": 1, "roll_deg": roll, "seed": 11}
    frame = render_scene(DSLR, scene, 0.7, setting.port, **flume)
    empty = render_scene(DSLR, empty_scene(scene), 0.7, setting.port, **{**flume, "seed": 12})
    camera = calibrated_camera("dslr", "water")  # the water tank's: same medium and distance
    for background in (None, empty):
        result = AreaMeasurer(camera, targets_for(scene), Classifier(threshold=120), background=background,
                              calibration_conditions=fitted_conditions("dslr", "water")).measure(frame)
        error = result.area_m2 / scene.true_area_m2 - 1
        assert result.subpixel_applied, result.warnings
        assert abs(error) <= 0.006 and abs(error) * scene.true_area_m2 <= 3 * result.area_std_m2, error
        assert result.area_std_m2 / scene.true_area_m2 <= 0.01 and result.warnings == []
        assert abs(result.levels.object - 40) < 1.5  # evened by the light's median: near the true 40 DN


TONE_CASES = [("endoscope", 0.5, roll, seed) for seed, roll in enumerate((0.0, 30.0, 90.0, -33.0))] + [
    ("endoscope", 1.2, roll, seed) for seed, roll in enumerate((0.0, 143.0))] + [
    ("dslr", 3.0, roll, seed) for seed, roll in enumerate((30.0, 90.0))]


@pytest.mark.parametrize(("camera_name", "blur", "roll", "seed"), TONE_CASES)
def test_an_srgb_camera_is_measured_in_light(camera_name, blur, roll, seed):
    """A camera that encodes light with the sRGB curve (as most JPEG cameras do): an edge blurred in light is
    no longer a symmetric ramp of grey levels, so read as they are the shares put it a fixed fraction of a pixel
    towards the white and the cube reads low by 0.7-1.1 %, beyond its std (beyond 3 std where the edges cross
    the pixel grid obliquely); at 1.2 px of blur at 640x480 the markers' black cells thin so much that they are
    not found. With tone curve `srgb` Otsu's threshold and the shares are read in light and the markers found in
    light: within 0.3 % and 3 std, in the default sub-pixel mode."""
    scene = cube_scene(side=0.1, markers=SQUARE_MARKERS,
                       pixels_per_metre=2000.0 if camera_name == "endoscope" else 6000.0)
    frame = render_scene(CAMERAS[camera_name], scene, 0.7, roll_deg=roll, seed=seed, blur_sigma_px=blur,
                         noise_sigma=2.0, supersample=3 if camera_name == "endoscope" else 1, tone_curve="srgb")
    camera = calibrated_camera(camera_name, "air")
    found = {}
    for tone in ("linear", "srgb"):
        try:
            result = AreaMeasurer(camera, targets_for(scene), Classifier(tone_curve=tone)).measure(frame)
        except (TargetsError, ClassifyError) as exc:  # too few markers found for a scale, or a region
            found[tone] = str(exc)
            continue
        found[tone] = (result.area_m2 / scene.true_area_m2 - 1, result.area_std_m2 / scene.true_area_m2)
        assert result.subpixel_applied and result.summary()["levels"]["tone_curve"] == tone
        assert result.summary()["tone_curve"] == tone and (tone == "linear" or not result.missing_targets)
    error, std = found["srgb"]
    assert abs(error) <= 0.003 and abs(error) <= 3 * std, found
    if camera_name == "endoscope" and blur > 1:
        assert isinstance(found["linear"], str), found
    else:
        error, std = found["linear"]
        assert error < -0.005 and -error > (std if roll % 90 == 0 else 3 * std), found


def test_the_tone_curve_reads_shares_and_otsu_in_light():
    """`linear` takes the band's values as light (the shares a straight line between the levels); `srgb`
    decodes them first: a pixel half covered in light sits at 0.5 in light, not half way in grey levels, and
    Otsu's split of two classes lies half way between them in light."""
    levels = Levels(40, 200, 1, 1)
    assert levels.fractions()[120] == pytest.approx(0.5)
    srgb = Levels(40, 200, 1, 1, tone_curve="srgb")
    half = (to_light(40, "srgb") + to_light(200, "srgb")) / 2
    encoded_half = np.interp(half, to_light(np.arange(256), "srgb"), np.arange(256))
    assert 140 < encoded_half < 150
    assert np.interp(encoded_half, np.arange(256), srgb.fractions()) == pytest.approx(0.5, abs=0.01)
    assert srgb.fractions()[120] > 0.65 and srgb.fractions()[200] == 0 and srgb.fractions()[40] == 1
    assert srgb.resolvable() and srgb.pure_zones()[0] != levels.pure_zones()[0]
    rng = np.random.default_rng(3)  # two classes and the edges' values between them
    values = np.concatenate([rng.normal(np.repeat([40.0, 200.0], 20000), 6), rng.uniform(40, 200, 4000)])
    counts = np.bincount(np.clip(np.rint(values), 0, 255).astype(int), minlength=256)
    assert abs(otsu_level(counts) - 120) < 5 and abs(otsu_level(counts, "srgb") - encoded_half) < 10
    with pytest.raises(ClassifyError, match="tone curve must be one of linear, srgb"):
        Classifier(tone_curve="gamma2.2")
    with pytest.raises(ClassifyError, match="excess-green"):
        Classifier(object="green", tone_curve="srgb")
