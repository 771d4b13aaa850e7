"""Stage 5 of a frame's measurement, the checks: everything that makes this Af less trustworthy, said in the
result itself: clipped exposure near the object's edges (and what it may do to Af), glare (a sheen or a
specular reflection), an object cut by the ROI's border, a threshold sweep that does not settle, edges blurred
beyond the printed markers', targets missing, a calibration used outside its conditions, and no object at all.

It exists because trust is judged after the number is made, from the same frame, mask and terms, and each
check is one rule a reader can find here. Takes the measured `AreaResult` with the frame's band, mask, weights
and targets; fills its `exposure`, `glare`, `edge_widths` and `warnings` (and zeroes Af where no object was found).
Carries nothing from frame to frame but the markers' edge width, which it keeps on the layout's `Weights`.

No ROS here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import cv2
import numpy as np

from .area_result import AreaResult
from .classify import BAND_VALUES, Classifier, LevelEstimator, Levels, in_edge_zone
from .glare import GLARE_EDGE_REACH_PX, glare_in, lifted_read_as_brighter
from .idealize import IdealView
from .light_levels import INTERIOR_PX
from .locate import Located
from .markers import DetectedMarker
from .scale import relative_area_std
from .weights import Weights

if TYPE_CHECKING:
    from collections.abc import Iterable

ROI_CUT_SHARE = 1e-3  # of the ROI without a pixel behind it: said (the remap's border is never counted)
NEARLY_ALL = 0.98  # of the ROI's pixels taken for object: the classification took the background too
# of the ROI's border taken for object: what surrounds the object was classified as object (a plant's stem
# crossing the border takes a few per cent of it, a board's squares along a ROI through its corners about half)
SURROUNDS = 0.75
GIVEN_LEVELS_APART_DN = 8.0  # given levels this far from the frame's (and beyond its spread) are another light's
SHARES_APART = 0.2  # sub-pixel Af this far from the count (real photos: a few %): the levels are not this frame's
CLIP_HIGH, CLIP_LOW = 250, 5  # band values a sensor or JPEG has clipped: whites burnt out, shadows crushed
CLIP_REACH_PX = 2  # blooming and the lens's blur carry a clipped pixel's light this far into its neighbours
CLIP_EDGE_SHARE = 0.10  # clipping next to this share of the object's edge pixels matters (real photos: 17 %, Af -1.2 %)
BORDER_TOUCH_SHARE = 0.01  # object pixels on the ROI's border, as a share of the object's: the area is cut
SWEEP_UNSETTLED = 0.02  # Af moving this much (relative) per sweep step around the threshold: no stable edge
BLUR_RATIO = 2.0  # the object's edges this much (and a pixel) wider than the markers': blurred on its own
# the markers' measured localisation (target_error) alone making Af this uncertain (relative): said, beside the
# std that holds it. Rendered: the endoscope's markers at 0.6 m at the 0.1 px floor 0.045 %, dim, noisy and
# blurred ones (0.22 px) 0.10 %; a DSLR's blurred by 7 px at 0.7 m (0.9-1.5 px) 0.08-0.13 %
LOOSE_MARKERS_SHARE = 0.0025
DISTANCE_TOLERANCE = 0.15  # targets this much (relative) nearer or farther than the calibration: said

# warnings about an object's edges, levels or extent: void where no object was found
OBJECT_WARNINGS = ("counted whole pixels", "object touches the ROI's border", "object surrounds the rest",
                   "threshold sweep does not settle",
                   "edges wider than the markers'", "glare")


@dataclass
class CheckSettings:
    """What the checks need to know of the measurement's settings."""
    classifier: Classifier
    area_mode: str
    threshold_delta: float
    view: IdealView
    calibration_conditions: dict | None  # the calibration file's medium and distance
    calibration_uncertainty_known: bool = True  # the calibration records its uncertainty (it is in Af's std)


def _loose_markers_share(located: Located, weights: Weights) -> float:
    """Af's relative std from the markers' measured localisation alone (0 where it was not measured)."""
    if located.marker_std_px is None:
        return 0.0
    markers = np.array([label.startswith("marker ") for label in located.labels])
    return relative_area_std((weights.scale_variances[0], 0.0), np.where(markers, located.scale.pixel_stds(), 0.0))


def check(result: AreaResult, settings: CheckSettings, raw_band: np.ndarray, band: np.ndarray, mask: np.ndarray,
          looked_at: np.ndarray, roi_count: np.ndarray, weights: Weights, factor: float, located: Located,
          markers: dict[int, DetectedMarker], estimator: LevelEstimator) -> np.ndarray:
    """Fills the result's exposure (adding what clipping may do to its std), glare, edge widths and warnings;
    where no object was found, Af becomes 0 with its reason. `band`: the band the levels were read from (its
    light evened). Returns the object mask over the weights' window."""
    result.exposure = _exposure(raw_band, mask, weights, factor, settings.classifier)
    result.glare = glare_in(band, weights, result.levels, settings.classifier, markers, mask)
    if result.exposure is not None and result.exposure["affected_area_m2"] > 0:
        # each edge pixel next to the clipping may be off by up to half a pixel, all the same way; in the std
        # from the first such pixel (a step at the warning's share would jump with the model's last decimals)
        result.exposure_std_m2 = result.exposure["affected_area_m2"] * 0.5 / np.sqrt(3)
        result.area_std_m2 = float(np.hypot(result.area_std_m2, result.exposure_std_m2))
    result.edge_widths = _edge_widths(looked_at, mask, roi_count, weights, result.levels, markers)
    if result.glare is not None and result.glare["matters"]:
        reach = max(GLARE_EDGE_REACH_PX, math.ceil((result.edge_widths or {}).get("markers_px") or 0))
        result.glare["lifted_read_m2"] = lifted_read_as_brighter(band, mask, weights, factor, result, reach)
        result.glare_std_m2 = result.glare["lifted_read_m2"]
        result.area_std_m2 = float(np.hypot(result.area_std_m2, result.glare_std_m2))
    result.warnings = _warnings(result, mask, weights, located, settings)
    unlike = _given_levels_unlike_the_frame(result, estimator)
    if unlike:
        result.warnings.append(unlike)
    absent = estimator.no_object(result.threshold)
    if absent is not None:  # never a large number from the background's noise or texture
        mask = np.zeros_like(mask)
        result.area_m2 = result.count_area_m2 = result.area_std_m2 = 0.0
        for term in fields(result):  # each term of the std with it (a threshold term of 0.05 m² stood beside 0)
            if term.name.endswith("_std_m2"):
                setattr(result, term.name, 0.0)
        result.pixel_count, result.subpixel_applied = 0, False
        result.warnings = [f"no object found: {absent}; Af is 0"] + [
            w for w in result.warnings if w.split(":", 1)[0] not in OBJECT_WARNINGS]
    return mask


def _given_levels_unlike_the_frame(result: AreaResult, estimator: LevelEstimator) -> str | None:
    """What to say where the shares were read at given levels that this frame's own object or background
    lies far from (beyond twice its spread and GIVEN_LEVELS_APART_DN): another light, or a slip in --levels."""
    given = result.levels
    if given is None or given.estimated or not result.subpixel_applied:
        return None
    seen = estimator.at(result.threshold)
    if seen is None:
        return None
    apart = [(name, level, found) for name, level, found, spread in (
        ("object", given.object, seen.object, seen.object_spread),
        ("background", given.background, seen.background, seen.background_spread))
        if abs(level - found) > max(GIVEN_LEVELS_APART_DN, 2 * spread)]
    if not apart:
        return None
    told = ", ".join(f"the {name}'s {level:.0f} DN where this frame shows {found:.0f}" for name, level, found in apart)
    return (f"given levels unlike this frame: {told}; the shares are read at levels the frame does not show and "
            "Af's std does not hold it (give this light's levels, or leave --levels out to read them per frame)")


def _roi_holds(roi_ideal: np.ndarray, pixel: np.ndarray) -> bool:
    """Whether the ROI (idealized mask) covers this idealized pixel."""
    x, y = round(float(pixel[0])), round(float(pixel[1]))
    return 0 <= y < roi_ideal.shape[0] and 0 <= x < roi_ideal.shape[1] and bool(roi_ideal[y, x])


def _outline(mask: np.ndarray) -> int:
    """The pixels of a class (uint8 mask) that touch the other class: its one-pixel outline."""
    return cv2.countNonZero(cv2.subtract(mask, cv2.erode(mask, np.ones((3, 3), np.uint8))))


def _marker_edge_width(frame: np.ndarray, markers: Iterable[DetectedMarker]) -> float | None:
    """The printed markers' edge width in px (median over the markers): in each marker's box, the pixels
    between its black's and white's outer 15 % per pixel of the outline at their midpoint."""
    widths = []
    height, width = frame.shape[:2]
    for marker in markers:
        (x0, y0), (x1, y1) = marker.corners.min(axis=0), marker.corners.max(axis=0)
        grow = 0.2 * max(x1 - x0, y1 - y0)  # the white quiet zone around the black square
        left, top = max(int(x0 - grow), 0), max(int(y0 - grow), 0)
        right, bottom = min(int(np.ceil(x1 + grow)), width), min(int(np.ceil(y1 + grow)), height)
        patch = frame[top:bottom, left:right]
        if patch.size == 0:
            continue
        grey = patch if patch.ndim == 2 else cv2.cvtColor(patch, cv2.COLOR_BGR2GRAY)
        low, high = np.percentile(grey, (5, 95))
        if high - low < 20:
            continue
        outline = _outline((grey <= (low + high) / 2).astype(np.uint8))
        mixed = np.count_nonzero(in_edge_zone(grey, low, high))
        if outline:
            widths.append(mixed / outline)
    return float(np.median(widths)) if widths else None


def _exposure(raw_band: np.ndarray, mask: np.ndarray, weights: Weights, factor: float, classifier: Classifier
              ) -> dict | None:
    """Clipped highlights or crushed shadows where they matter: next to the object's edge pixels (within
    CLIP_REACH_PX: blooming and blur carry the lost light there) and among the pure pixels a level is read
    from. None when nothing in the ROI is clipped (one min/max over the ROI: no cost on a good exposure)."""
    low, high, _, _ = cv2.minMaxLoc(raw_band, weights.roi)
    if high < CLIP_HIGH and low > CLIP_LOW:
        return None
    kernel = np.ones((3, 3), np.uint8)
    edge = cv2.morphologyEx(mask, cv2.MORPH_GRADIENT, kernel) & weights.roi  # both sides of the boundary
    edges = max(cv2.countNonZero(edge), 1)
    reach = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * CLIP_REACH_PX + 1,) * 2)
    interior = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * INTERIOR_PX + 1,) * 2)
    object_is_bright = classifier.object != "dark"
    found = {"matters": False, "affected_area_m2": 0.0}
    for side, clipped in (("highlights", cv2.compare(raw_band, CLIP_HIGH, cv2.CMP_GE)),
                          ("shadows", cv2.compare(raw_band, CLIP_LOW, cv2.CMP_LE))):
        if not cv2.countNonZero(cv2.bitwise_and(clipped, weights.roi)):
            continue
        touched = cv2.bitwise_and(edge, cv2.dilate(clipped, reach))
        touched_count = cv2.countNonZero(touched)
        share = touched_count / edges
        # the class on the clipped side: the background for a dark object's highlights
        clipped_is_object = object_is_bright == (side == "highlights")
        members = mask if clipped_is_object else cv2.subtract(weights.roi, mask)
        pure = cv2.erode(members, interior)
        level_share = cv2.countNonZero(cv2.bitwise_and(pure, clipped)) / max(cv2.countNonZero(pure), 1)
        # a white background's noise clips far from any edge on most frames: nothing touched, no area to sum
        area = weights.mask_area(touched, factor)[0] if touched_count else 0.0
        matters = share >= CLIP_EDGE_SHARE
        found[side] = {"edge_share": share, "level_share": level_share, "affected_area_m2": area,
                       "clipped_class": "object" if clipped_is_object else "background",
                       "reads": "high" if clipped_is_object else "low", "matters": matters}
        found["affected_area_m2"] += area
        found["matters"] = found["matters"] or matters
    return found if len(found) > 2 else None


def _warnings(result: AreaResult, mask: np.ndarray, weights: Weights, located: Located, settings: CheckSettings
              ) -> list[str]:
    """Everything that makes this Af less trustworthy, one line each, said in the result itself."""
    said = []
    for side in ("highlights", "shadows"):
        clip = (result.exposure or {}).get(side)
        if clip and clip["matters"]:
            said.append(f"clipped {side}: {100 * clip['edge_share']:.0f} % of the object's edge pixels lie "
                        f"next to {'burnt-out' if side == 'highlights' else 'crushed'} pixels "
                        f"({100 * clip['level_share']:.1f} % of the {clip['clipped_class']}'s pure pixels are "
                        f"clipped): Af reads {clip['reads']} (1.5-5 % on real photos); the std has "
                        f"{100 * result.exposure_std_m2 / max(result.area_m2, 1e-300):.1f} % for it; "
                        f"{'shorten the exposure' if side == 'highlights' else 'lengthen the exposure'}")
    glare = result.glare
    if glare and glare["matters"]:
        darker, brighter = (("object", "background") if glare["reads"] == "low" else ("background", "object"))
        said.append(f"glare: {100 * glare['share']:.1f} % of the ROI ({100 * glare['object_share']:.1f} % of the "
                    f"object's pixels) is brighter than the {brighter}'s level "
                    f"(over {glare['above_dn']:.0f} DN), a sheen or specular reflection; where it lifts the "
                    f"{darker} too, its pixels read as {brighter} and Af reads {glare['reads']} (by 1-2.5 % on "
                    "photos of a glossy print); the std has "
                    f"{100 * result.glare_std_m2 / max(result.area_m2, 1e-300):.1f} % for it; light from the side or "
                    "through a diffuser, or turn the camera")
    if settings.area_mode == "subpixel" and not result.subpixel_applied:
        said.append("counted whole pixels: the object's and the background's levels could not be told apart "
                    "well enough for sub-pixel shares (uneven light or texture); the std is the count's")
    roi_pixels = cv2.countNonZero(weights.roi)
    if roi_pixels and result.pixel_count >= NEARLY_ALL * roi_pixels:
        said.append(f"the object fills {100 * result.pixel_count / roi_pixels:.0f} % of the ROI: the threshold or "
                    "levels take nearly everything for object (check --threshold, --levels and --object)")
    if result.subpixel_applied and result.count_area_m2 > 0 and abs(result.area_m2 / result.count_area_m2 - 1) > \
            SHARES_APART:
        said.append(f"the sub-pixel shares make Af {100 * (result.area_m2 / result.count_area_m2 - 1):+.0f} % of the "
                    "whole-pixel count: the levels do not match this frame's object and background (given "
                    "--levels, or another light); Af is doubtful")
    if located.missing:
        said.append(f"targets missing: marker(s) {located.missing} not found; the scale comes from the others "
                    "and the ROI places the missing ones by their fit")
    loose = _loose_markers_share(located, weights)
    if loose > LOOSE_MARKERS_SHARE:
        causes = "blur, noise, a dim or bent print" if settings.view.calibrated else (
            "measured without a calibration, the lens's distortion bends them; or blur, noise, a dim or bent print")
        said.append(f"markers located loosely: their corners miss squares on the plane by {located.marker_std_px:.2f} "
                    f"px at their centres ({causes}), which alone makes Af uncertain by {100 * loose:.2f} % (in "
                    "its std)")
    if weights.roi_cut_share > ROI_CUT_SHARE:
        reach = settings.view.camera.reach_px() if settings.view.camera is not None else None
        said.append(f"the ROI reaches beyond the image: {100 * weights.roi_cut_share:.1f} % of it has no pixel "
                    + ("(outside the frame, or past "
                       f"{reach:.0f} px from the principal point, where the lens model folds) " if reach else
                       "(outside the frame) ")
                    + "and is not measured; Af is the part inside")
    held = [label.split()[1] for label, pixel in zip(located.labels, located.pixels, strict=False)
            if label.startswith("marker ") and _roi_holds(weights.roi_ideal, pixel)]
    if held:  # only a user's ROI can: the default one cuts the marker squares out
        said.append(f"the ROI holds marker(s) {', '.join(held)}: their dark print is classified like the object "
                    "and counted in Af (draw the ROI between the targets, or use the default ROI, which cuts the "
                    "markers out)")
    border = weights.border()
    touching = cv2.countNonZero(mask & border)
    ring = cv2.countNonZero(border)
    if ring and touching >= SURROUNDS * ring:
        said.append(f"object surrounds the rest: it covers {100 * touching / ring:.0f} % of the ROI's border, so "
                    "what was measured is most likely the background (check --object, --threshold and "
                    "--channel); Af is doubtful")
    elif touching >= max(5, BORDER_TOUCH_SHARE * max(result.pixel_count, 1)):
        said.append(f"object touches the ROI's border: {touching} of its pixels lie on it, so Af is cut there "
                    "(widen the ROI, or move the targets)")
    if result.area_m2 > 0 and result.threshold_std_m2 / result.area_m2 > SWEEP_UNSETTLED:
        said.append(f"threshold sweep does not settle: Af changes by "
                    f"{100 * result.threshold_std_m2 / result.area_m2:.1f} % per {settings.threshold_delta:g} grey "
                    "levels around the threshold (no clear edge there)")
    widths = result.edge_widths
    if widths and widths["object_px"] > BLUR_RATIO * widths["markers_px"] + 1.0:
        said.append(f"edges wider than the markers': the object's edges are {widths['object_px']:.1f} px wide, "
                    f"the printed markers' {widths['markers_px']:.1f} px (a plant moving in the current, or "
                    "out of focus): its edge shares are blurred together and Af is less certain")
    said.extend(_condition_warnings(located, settings))
    trend = result.edge_trend
    if trend and trend.get("outside"):
        low, high = trend["range_dn"]
        said.append(f"exposure outside the calibration's: whites at {trend['white_dn']:.0f} DN, its views' "
                    f"{low:.0f}-{high:.0f} DN; how the edges follow exposure is taken at the nearer end, its std "
                    "grows with the distance")
    return said


def _edge_widths(frame: np.ndarray, mask: np.ndarray, counts: np.ndarray, weights: Weights,
                 levels: Levels | None, markers: dict[int, DetectedMarker]) -> dict | None:
    """How wide (px) the object's edges are, against the printed markers' in the same frame, each as the
    pixels between the two levels' outer 15 % per pixel of outline. Blur of the water or the lens widens
    both alike; a plant moving in the current (or out of focus) widens only its own. The markers' width is
    found once per target layout."""
    if levels is None or not markers:
        return None
    low, high = sorted((levels.object, levels.background))
    if high - low < 20:
        return None
    inside = in_edge_zone(BAND_VALUES, low, high)
    outline = _outline(mask)
    if outline == 0:
        return None
    if not weights.marker_edge_found:  # printed edges: once per target layout
        weights.marker_edge_px = _marker_edge_width(frame, markers.values())
        weights.marker_edge_found = True
    found = weights.marker_edge_px
    if found is None:
        return None
    return {"object_px": float(counts[inside].sum()) / outline, "markers_px": found}


def _condition_warnings(located: Located, settings: CheckSettings) -> list[str]:
    """A calibration used outside its conditions (the calibration file's metadata): another distance of the
    targets' plane, or no medium recorded; or a calibration that records no uncertainty, whose term Af's std
    then leaves out. A plumb_bob calibration absorbs refraction at one distance only."""
    if not settings.view.calibrated:
        return []
    conditions = settings.calibration_conditions or {}
    said = []
    if "medium" not in conditions:  # a camera_info or file from another tool, or one set by hand
        said.append("calibration conditions not recorded (no medium, distance or uncertainty beside the "
                    "camera_info): a calibration holds only in the medium and at the distance it was made at, which "
                    "cannot be checked, and Af's std leaves out its uncertainty (veg-area calibrate --medium "
                    "air|water records them)")
    elif not settings.calibration_uncertainty_known:
        said.append("calibration uncertainty not recorded: Af's std leaves out the calibration's own "
                    "(veg-area calibrate and the calibration node record it)")
    if conditions.get("medium") == "unspecified":
        said.append("calibration medium unspecified: a calibration holds only in the medium it was made in "
                    "(recalibrate with --medium air|water)")
    calibrated_at = conditions.get("calibration_distance_m")
    if calibrated_at and located.scale.kind != "distance":
        focal = float(settings.view.ideal_matrix[0, 0])
        distance = located.scale.metres_per_pixel * focal
        if abs(distance / calibrated_at - 1) > DISTANCE_TOLERANCE:
            said.append(f"calibrated at {calibrated_at:g} m, measuring at about {distance:.2f} m"
                        f"{' in ' + conditions['medium'] if conditions.get('medium') == 'water' else ''}: "
                        "refraction is absorbed at the calibration's distance only (errors of a few percent); "
                        "calibrate at this distance or use the flat-port model")
    return said
