"""Stage 4 of a frame's measurement, the area and its terms: Af from the 2-D histogram of the lit frame (band
value x weight level), whole pixels counted or their sub-pixel shares read, and each term of its standard
deviation (scale, threshold, the edge's discretisation or levels, the object plane's offset).

It exists because Af and its uncertainty are pure arithmetic on one histogram, apart from how the frame was
lit, located or weighted: every threshold of the sweep, the threshold term and the choice between the shares
and the count are read from the same sums. Takes a `LitFrame`, the `Weights` with their carrying factor and
the levels at the thresholds it names (`thresholds_read`); gives `AreaTerms`. Carries nothing from frame to
frame.

No ROS here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from .classify import Classifier, Levels, to_light
from .light_levels import LitFrame
from .scale import PlaneScale, relative_area_std
from .weights import Weights


@dataclass
class EdgeTerms:
    discretisation: float = 0.0  # m², count mode
    levels: float = 0.0  # m², sub-pixel mode
    length_px: float = 0.0


@dataclass
class AreaTerms:
    """Af of one frame with each term of its standard deviation (m²)."""
    area: float  # in the mode used: the shares, or counted where they were less certain
    counted: float  # Af of the whole-pixel count
    count: int  # pixels counted
    levels: Levels | None
    applied: bool  # the shares were used
    edge: EdgeTerms
    threshold_std: float
    scale_std: float
    offset_std: float
    calibration_std: float  # the calibration's covariance over the ROI
    std: float  # all of them in quadrature
    sweep: list[tuple[float, float]] = field(default_factory=list)  # (threshold, Af) around the chosen one


def _sweep(threshold: float, delta: float) -> list[float]:
    return [level for level in threshold + delta * np.arange(-3, 4) if 0 <= level <= 255]


def thresholds_read(threshold: float, delta: float, classifier: Classifier, subpixel: bool) -> list[float]:
    """The thresholds whose levels `area_terms` reads, in the order it reads them: the chosen one, and where the
    shares are read at every threshold (sub-pixel mode, or a cleaned mask) the threshold term's and the sweep's."""
    if not (subpixel or classifier.open_px or classifier.close_px):
        return [threshold]
    return [threshold, min(threshold + delta, 255), max(threshold - delta, 0), *_sweep(threshold, delta)]


def area_terms(lit: LitFrame, weights: Weights, factor: float, carried: float, classifier: Classifier,
               subpixel: bool, delta: float, levels: dict[float, Levels | None],
               relative_calibration_std: float = 0.0, scale: PlaneScale | None = None) -> AreaTerms:
    """Af at the lit frame's threshold in sub-pixel mode (`subpixel`) or counted, its terms, and the sweep of
    thresholds `delta` apart; `carried` is the relative error of carrying the weights to this frame's fit;
    `levels` the levels at `thresholds_read`; `relative_calibration_std` the calibration's own over the
    object's pixels (`Weights.relative_calibration_std`); `scale` this frame's fit, whose targets' localisation
    stds the scale term takes (by default the fit the weights were built with)."""
    levels_at = levels.__getitem__
    # area (m²) and number of the ROI's pixels at every band value, from one 2-D histogram
    roi_area = lit.histogram @ weights.level_area * factor
    roi_count = lit.roi_count
    morphology = classifier.open_px or classifier.close_px
    cumulative_area, cumulative_count = np.cumsum(roi_area), np.cumsum(roi_count)
    outcomes: dict[float, tuple[float, float, int, Levels | None]] = {}

    def measured(level: float) -> tuple[float, float, int, Levels | None]:
        """(Af in this mode, Af counted, pixels counted, levels) at a threshold, once per threshold."""
        if level not in outcomes:
            outcomes[level] = outcome(level)
        return outcomes[level]

    def counted_at(level: float) -> tuple[float, int]:
        """Af counted at a threshold (m²) and its pixels: from the histogram, or the cleaned mask's."""
        if morphology:
            return weights.mask_area(classifier.mask(lit.band, weights.roi, level), factor)
        index = int(np.floor(level))
        if classifier.object == "dark":  # band <= level
            return float(cumulative_area[index]), int(cumulative_count[index])
        return float(cumulative_area[-1] - cumulative_area[index]), int(cumulative_count[-1] - cumulative_count[index])

    def outcome(level: float) -> tuple[float, float, int, Levels | None]:
        if not morphology:
            counted, count = counted_at(level)
            if not subpixel:  # levels only for the uncertainty, at the chosen threshold
                return counted, counted, count, None
            levels = levels_at(level)
            area = float(roi_area @ levels.fractions()) if levels is not None else counted
            return area, counted, count, levels
        levels = levels_at(level)
        mask = classifier.mask(lit.band, weights.roi, level)
        counted, count = weights.mask_area(mask, factor)
        if not subpixel or levels is None:
            return counted, counted, count, levels
        # the cleaned mask counts whole inside; its one-pixel rings inside and outside count their fraction
        kernel = np.ones((3, 3), np.uint8)
        inner = cv2.subtract(mask, cv2.erode(mask, kernel))
        outer = cv2.subtract(cv2.dilate(mask, kernel), mask) & weights.roi
        fractions = levels.fractions()
        area = (counted - weights.histogram(lit.band, inner) @ weights.level_area * factor @ (1 - fractions)
                + weights.histogram(lit.band, outer) @ weights.level_area * factor @ fractions)
        return float(area), counted, count, levels

    threshold = lit.threshold
    area, counted, count, levels = measured(threshold)
    if levels is None:
        levels = levels_at(threshold)

    def edge_terms(fractional: bool) -> EdgeTerms:
        return _edge_terms(roi_area, roi_count, levels, counted, count, fractional,
                           lambda lv: float(roi_area @ lv.fractions()))

    def threshold_term(pick: int) -> float:  # pick 0: Af from the shares, 1: counted
        return abs(measured(min(threshold + delta, 255))[pick] - measured(max(threshold - delta, 0))[pick]) / 2

    applied = subpixel and levels is not None
    edge = edge_terms(applied)
    if levels is None:  # counted without levels to read shares from (count mode leaves the light uneven)
        halfway = _halfway(lit.estimator.at(threshold))
        if halfway is not None:  # the count where the two levels the histogram shows meet stands in for them
            edge = replace(edge, discretisation=max(edge.discretisation, abs(counted - counted_at(halfway)[0])))
    threshold_std = threshold_term(0 if applied else 1)
    if applied:  # shares less certain than whole pixels (uneven levels): the count is the better estimate
        counting, counting_threshold_std = edge_terms(False), threshold_term(1)
        if np.hypot(edge.levels, threshold_std) > np.hypot(counting.discretisation, counting_threshold_std):
            applied, edge, area, threshold_std = False, counting, counted, counting_threshold_std
    sweep = [(float(level), measured(level)[0 if applied else 1]) for level in _sweep(threshold, delta)]
    relative_scale_std = relative_area_std(weights.scale_variances, (scale or weights.scale).pixel_stds())
    scale_std = area * float(np.hypot(relative_scale_std, carried))  # carrying errs like the scale
    offset_std = area * weights.relative_offset_std
    calibration_std = area * relative_calibration_std
    std = float(np.sqrt(scale_std**2 + threshold_std**2 + edge.discretisation**2 + edge.levels**2 + offset_std**2
                        + calibration_std**2))
    return AreaTerms(area, counted, count, levels, applied, edge, threshold_std, scale_std, offset_std,
                     calibration_std, std, sweep)


def _halfway(levels: Levels | None) -> float | None:
    """The band value halfway in light between the two levels: where a blurred edge's pixel is half covered,
    so the threshold that puts a symmetric edge where it is. None without levels."""
    if levels is None:
        return None
    light = to_light(np.arange(256.0), levels.tone_curve)
    middle = (to_light(levels.object, levels.tone_curve) + to_light(levels.background, levels.tone_curve)) / 2
    return float(np.interp(middle, light, np.arange(256.0)))


def _edge_terms(roi_area: np.ndarray, roi_count: np.ndarray, levels: Levels | None, counted_area: float,
                counted_pixels: int, subpixel: bool, subpixel_area: Callable[[Levels], float]) -> EdgeTerms:
    """The uncertainty that the object's edge adds, from its mixed pixels (band values strictly between the
    pure zones of the two levels): their number / (1 - both zones) bounds the edge length L in pixels (a
    blurred edge has more mixed pixels per unit length), w is their mean metric area.
    Count mode: an edge pixel covered by a fraction phi is counted whole or not at all. Where the edge crosses
    the pixel grid at random phases these errors are independent, sd w sqrt(L / 12); along an edge that follows
    the grid every pixel errs alike, a systematic error that the sub-pixel area of the same frame measures:
    the term is the larger of |Af counted - Af sub-pixel| and the random part. Where no band value tells edge
    pixels apart, L is taken as a disc's perimeter for the counted area (the least any shape has) and the
    errors as alike along two halves of it: w L / sqrt(24).
    Sub-pixel mode: each level moved by its error (Af's sensitivity to the levels: the level's standard error
    and the light's unevenness left, or its whole spread where that is not known), per-pixel noise of the
    background's spread over the contrast, and the pure zones: an edge pixel whose fraction lies within a zone
    is counted 0 or 1, error up to the zone (sd per pixel sqrt((eps_o³ + eps_b³) / 3) at random phases; along
    the grid the change of Af when the zones are twice as wide)."""
    mixed = levels.mixed() if levels is not None else np.zeros(256, bool)
    mixed_count = float(roi_count[mixed].sum())
    if mixed_count == 0:  # no value tells edge pixels apart (uneven levels): the least boundary the object has
        if subpixel or counted_pixels == 0:
            return EdgeTerms()
        length = 2 * float(np.sqrt(np.pi * counted_pixels))  # a disc's perimeter, px
        return EdgeTerms(discretisation=counted_area / counted_pixels * length / float(np.sqrt(24)),
                         length_px=length)
    eps_object, eps_background = levels.pure_zones()
    length = mixed_count / max(1.0 - eps_object - eps_background, 0.1)
    weight = float(roi_area[mixed].sum()) / mixed_count
    if not subpixel:
        systematic = abs(counted_area - subpixel_area(levels))
        return EdgeTerms(discretisation=max(systematic, weight * float(np.sqrt(length / 12))), length_px=length)
    sensitivity = []
    for name in ("object", "background"):
        shift = levels.error(name)
        moved = [subpixel_area(Levels(**{**levels.to_dict(), name: getattr(levels, name) + sign * shift}))
                 for sign in (1, -1)]
        sensitivity.append((moved[0] - moved[1]) / 2)
    noise = weight * np.sqrt(mixed_count) * levels.share_spreads()[1]
    # the pure zones: an edge pixel within one is counted 0 or 1. Where the edge crosses the grid at random
    # phases the errors are independent; where it follows the grid they repeat along it, and what they add up
    # to shows as the change of Af when both zones are made twice as wide (an error growing with the zones'
    # width, linearly or faster, is bounded by that change)
    random_zones = weight * np.sqrt(length * (eps_object**3 + eps_background**3) / 3)
    wider = Levels(**{**levels.to_dict(), "object_spread": 2 * levels.object_spread,
                      "background_spread": 2 * levels.background_spread})
    zones = max(random_zones, abs(subpixel_area(wider) - subpixel_area(levels)))
    return EdgeTerms(levels=float(np.sqrt(sensitivity[0] ** 2 + sensitivity[1] ** 2 + noise**2 + zones**2)),
                     length_px=length)
