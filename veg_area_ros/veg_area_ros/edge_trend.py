"""Where a camera puts an edge as its exposure changes, learned from its calibration views. No ROS here.

This stage exists apart because it joins the calibration and the measurement: `veg-area calibrate` (and the
calibration node) learn it from the board's views, the measurement applies it to each frame.

Real JPEG photos of one print do not agree on where its edges are: the half-way point of an edge lies off the
printed side by -0.08 to +0.08 px between OpenCV's webcam photos, and it follows each photo's exposure (the
whiter the paper, the smaller the black squares: a tone curve's shoulder presses a blurred edge's tail towards
white). Neither area mode can see that in one frame. A chessboard's views can: each is a measurement with a
known answer, its error over the board's edge length is how far that view moved its edges, and the views'
white levels say how that follows exposure. Where the views show a trend clearly (its slope over three
standard errors, over a span of white levels), each frame's edges are moved back by the trend at its own
white level, relative to the views' mean: the print's own ink gain is left as it is (a reach in metres, it
is fitted beside the trend where the views' scales differ, so that near views that are also bright ones do not
teach it as a trend with exposure).
The slope's standard error, over the frame's distance from the views' mean, is a term of Af's std; so is how
far the views' edges scatter about the trend (or about their mean, where none is learned) beyond what their own
reported std says, measured on the views with a known answer rather than guessed.
Where many views were measured (LOCAL_MIN_VIEWS), a straight line is not all they can say: a camera's edges
may hold still over most exposures and fall away near the top (a machine-vision camera's views through a dome
housing's air photos: within 0.02 px from 92 to 205 DN, then -0.05 to -0.16 px from 210 to 225 DN). Each frame
then takes, beside the line, the mean of its LOCAL_VIEWS nearest views' residuals in white level, and their
scatter instead of all views' (both with their std): where the line holds, that mean is near zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np
from scipy.optimize import brentq

if TYPE_CHECKING:
    from .area_result import AreaResult

MIN_VIEWS = 6  # a slope and its scatter need a few more views than its two parameters
DECISIVE_SIGMA = 3.0  # the slope this many standard errors from zero
MIN_SPAN_DN = 10.0  # white levels this far apart: below it the views cannot show a trend
MIN_SCALE_RATIO = 1.1  # the nearest view's scale over the farthest's: from it on the print's gain is fitted too
LOCAL_MIN_VIEWS = 24  # views from which each frame also takes its nearest views' residuals (three groups of them)
LOCAL_VIEWS = 8  # a frame's nearest views in white level: their mean residual and scatter


@dataclass(frozen=True)
class EdgeTrend:
    """How far the black side of an edge reaches (px, positive: the black grows) per DN of the white level,
    around `reference_dn` (the views' mean white level), learned in the `tone_curve` the views were read with;
    where no trend was `learned`, the slope is 0 and `slope_std` what the views could not rule out (a frame
    beyond their whites takes it over the distance; 0 in files written before it was kept). `scatter_px`: how
    far the views' edges scatter about it beyond what their own reported std says (0 where their std covers
    it), a term of every frame's std."""

    slope_px_per_dn: float
    slope_std: float
    reference_dn: float
    range_dn: tuple[float, float]
    views: int
    residual_px: float  # the views' scatter about the line
    tone_curve: str
    learned: bool = True
    scatter_px: float = 0.0
    # each view's (white DN, residual about the line px, its std px), where LOCAL_MIN_VIEWS or more were measured
    residuals: tuple[tuple[float, float, float], ...] = ()

    def as_dict(self) -> dict:
        recorded = {"learned": self.learned, "slope_px_per_dn": round(self.slope_px_per_dn, 6),
                    "slope_std": round(self.slope_std, 6), "reference_dn": round(self.reference_dn, 2),
                    "range_dn": [round(v, 1) for v in self.range_dn], "views": self.views,
                    "residual_px": round(self.residual_px, 4), "scatter_px": round(self.scatter_px, 4),
                    "tone_curve": self.tone_curve}
        if self.residuals:
            recorded["residuals"] = [[round(w, 1), round(r, 4), round(s, 4)] for w, r, s in self.residuals]
        return recorded

    @property
    def local(self) -> bool:
        """Whether each frame takes its nearest views' residuals too."""
        return len(self.residuals) >= LOCAL_MIN_VIEWS

    @classmethod
    def from_dict(cls, value: object) -> EdgeTrend:
        """The trend a calibration file's metadata records; ValueError where it is not one."""
        if not isinstance(value, dict):
            raise ValueError(f"edge_trend must be a mapping, got {value!r}")
        try:
            low, high = (float(v) for v in value["range_dn"])
            trend = cls(float(value["slope_px_per_dn"]), float(value["slope_std"]), float(value["reference_dn"]),
                        (low, high), int(value["views"]), float(value.get("residual_px", 0.0)),
                        str(value.get("tone_curve", "linear")), bool(value.get("learned", True)),
                        float(value.get("scatter_px", 0.0)),
                        tuple((float(w), float(r), float(s)) for w, r, s in value.get("residuals", ())))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"edge_trend is not readable ({exc.__class__.__name__}: {exc})") from None
        numbers = (trend.slope_px_per_dn, trend.slope_std, trend.reference_dn, low, high, trend.scatter_px,
                   *(v for view in trend.residuals for v in view))
        if (not all(math.isfinite(v) for v in numbers) or min(trend.slope_std, trend.scatter_px) < 0
                or any(s < 0 for _, _, s in trend.residuals) or not low <= trend.reference_dn <= high):
            raise ValueError(f"edge_trend holds no trend: {value!r}")
        return trend

    def offset_px(self, white_dn: float) -> tuple[float, float, bool]:
        """(how far the frame's black reaches beyond the views' mean, its std, whether `white_dn` lies outside
        the views' range: the trend is then taken at the nearer end, its std at the frame's own level). The
        std holds the views' scatter beyond their own std too: all views', or with `local` the nearest views'
        scatter and their mean residual's std."""
        low, high = self.range_dn
        inside = low <= white_dn <= high
        taken = min(max(white_dn, low), high)
        offset = 0.0
        if self.learned:
            offset = self.slope_px_per_dn * (taken - self.reference_dn)
            slope_part = (self.slope_std * abs(white_dn - self.reference_dn)
                          + abs(self.slope_px_per_dn) * abs(white_dn - taken))
        else:
            # no trend within the views' whites (their scatter covers them); beyond them the edges may follow
            # exposure as fast as the views could not rule out
            slope_part = self.slope_std * abs(white_dn - taken)
        if not self.local:
            extrapolated = not inside and (self.learned or self.slope_std > 0)
            return offset, math.hypot(slope_part, self.scatter_px), extrapolated
        mean, mean_std, scatter = self.nearest_residuals(white_dn)
        return offset + mean, math.hypot(slope_part, scatter, mean_std), not inside

    def nearest_residuals(self, white_dn: float) -> tuple[float, float, float]:
        """(the mean residual of the LOCAL_VIEWS views nearest `white_dn` in white level, weighed by their std
        and scatter; its std; their scatter beyond their own std)."""
        views = np.array(self.residuals, float)
        nearest = views[np.argsort(np.abs(views[:, 0] - white_dn), kind="stable")[:LOCAL_VIEWS]]
        residuals, stds = nearest[:, 1], nearest[:, 2]
        scatter = excess_scatter(residuals - residuals.mean(), list(stds), len(nearest) - 1)
        weights = 1.0 / np.maximum(stds**2 + scatter**2, 1e-12)
        return (float(weights @ residuals / weights.sum()), float(1.0 / math.sqrt(weights.sum())), scatter)


@dataclass(frozen=True)
class ViewEdge:
    """One calibration view as evidence of where the camera puts its edges: how far they moved (px, positive:
    the black grows), its white level (DN), the offset's reported std (px) and the print's scale in the view
    (px per metre: the print's own ink gain moves the edges in proportion to it)."""

    name: str
    offset_px: float
    white_dn: float
    std_px: float
    scale_px_per_m: float


@dataclass
class TrendChoice:
    """What the calibration records of its views' edges (a trend learned, or only their scatter), or None, and
    why."""

    trend: EdgeTrend | None
    reason: str
    gain_px: tuple[float, ...] = ()  # per view, the print's gain's part of its offset (about their mean), if fitted


def fit_edge_trend(offsets_px: list[float], whites_dn: list[float], tone_curve: str,
                   stds_px: list[float] | None = None, scales_px_per_m: list[float] | None = None) -> TrendChoice:
    """The line through each view's edge offset (px) against its white level (DN), taken where it is clear;
    and how far the offsets scatter about it (or about their mean) beyond their reported std (`stds_px`).
    Given each view's scale (`scales_px_per_m`) and views near and far, the print's ink gain (a reach in
    metres, so in px in proportion to the scale) is fitted beside it: where near views are also brighter
    ones, the gain would otherwise pass for a trend with exposure (a GoPro's views: +0.21 +/- 0.06 px per
    10 DN without it, -0.03 +/- 0.05 with it)."""
    n = len(offsets_px)
    if n < MIN_VIEWS:
        return TrendChoice(None, f"not learned: {MIN_VIEWS} or more views of the whole chessboard (or a ChArUco "
                                 f"board's rectangle of corners), whites not clipped, show how the edges follow "
                                 f"exposure; {n} could be measured")
    offsets, whites = np.asarray(offsets_px, float), np.asarray(whites_dn, float)
    span = float(whites.max() - whites.min())
    centre, reach = float(whites.mean()), (float(whites.min()), float(whites.max()))
    # the print's gain, in proportion to the scale, where the views' scales differ enough to show it
    gain = np.empty((n, 0))
    if scales_px_per_m is not None and len(scales_px_per_m) == n:
        scales = np.asarray(scales_px_per_m, float)
        if scales.min() > 0 and scales.max() / scales.min() >= MIN_SCALE_RATIO:
            gain = (scales / scales.mean() - 1.0)[:, None]
    slope = slope_std = 0.0
    learned = False
    if span < MIN_SPAN_DN:
        reason = (f"not learned: the views' whites span {span:.1f} DN, too alike in exposure to show a trend "
                  f"(under {MIN_SPAN_DN:g} DN)")
    else:
        design = np.column_stack([np.ones(n), whites - centre, gain])
        coef, *_ = np.linalg.lstsq(design, offsets, rcond=None)
        residual = offsets - design @ coef
        slope = float(coef[1])
        variance = float(residual @ residual) / max(n - design.shape[1], 1)
        slope_std = math.sqrt(variance * float(np.linalg.inv(design.T @ design)[1, 1]))
        described = (f"{slope * 10:+.3f} +/- {slope_std * 10:.3f} px per 10 DN of white over {n} views "
                     f"({reach[0]:.0f}-{reach[1]:.0f} DN)" + (", the print's gain with the board's size in pixels "
                                                               "taken out" if gain.size else ""))
        learned = abs(slope) > DECISIVE_SIGMA * slope_std
        reason = (f"the edges follow exposure: {described}" if learned else
                  f"not learned: the edges do not clearly follow exposure ({described})")
    if not learned:  # its std kept: how fast the edges may follow exposure beyond the views' whites
        slope = 0.0
    design = np.column_stack([np.ones(n), gain])
    coef, *_ = np.linalg.lstsq(design, offsets - slope * (whites - centre), rcond=None)
    residual = offsets - slope * (whites - centre) - design @ coef
    dof = max(n - design.shape[1] - (1 if learned else 0), 1)
    variance = float(residual @ residual) / dof
    scatter = excess_scatter(residual, stds_px, dof) if stds_px is not None and len(stds_px) == n else 0.0
    if scatter > 0:
        reason += (f"; the views' edges scatter {math.sqrt(variance):.3f} px about it, {scatter:.3f} px beyond "
                   "their reported std: a term of every frame's std")
    gain_part = tuple(float(v) for v in gain[:, 0] * coef[1]) if gain.size else ()
    bound_only = not learned and scatter == 0
    if bound_only:
        if slope_std == 0:  # too few or too alike views to bound a slope: nothing to record
            return TrendChoice(None, reason, gain_part)
        # nothing moves a frame within the views' whites; recorded so that a frame beyond them takes the slope's
        # std over the distance and is said to lie outside
        reason += (f"; recorded for frames whiter or darker than the views ({reach[0]:.0f}-{reach[1]:.0f} DN): "
                   "their std grows with the distance")
    residuals = ()
    if not bound_only and stds_px is not None and len(stds_px) == n and n >= LOCAL_MIN_VIEWS:
        residuals = tuple(sorted(zip(whites.tolist(), residual.tolist(), (float(s) for s in stds_px), strict=True)))
        reason += (f"; each frame also takes the residuals of the {LOCAL_VIEWS} views nearest its white level "
                   f"({n} views measured)")
    return TrendChoice(EdgeTrend(slope, slope_std, centre, reach, n, math.sqrt(variance), tone_curve, learned,
                                 scatter, residuals), reason, gain_part)


def excess_scatter(residuals: np.ndarray, stds: list[float], dof: int) -> float:
    """The scatter s the residuals show beyond their own std: where sum(r² / (std² + s²)) equals the degrees of
    freedom (Paule and Mandel's consensus estimator), 0 where they lie within their std. Views whose std differ
    are weighed by it: a few blurred or clipped views with a large std (a webcam's 0.2-0.45 px beside 0.04 px)
    neither hide the scatter of the sharp ones, as a mean of the squared stds would, nor add to it."""
    r2 = np.square(np.asarray(residuals, float))
    own = np.maximum(np.square(np.asarray(stds, float)), 1e-12)

    def excess(scatter: float) -> float:
        return float(np.sum(r2 / (own + scatter**2))) - dof

    if excess(0.0) <= 0:
        return 0.0
    # the sum falls as the scatter grows; at this bound every view's weight is under its inverse square: <= 0
    return float(brentq(excess, 0.0, math.sqrt(float(r2.sum()) / dof), xtol=1e-12))


def boundary_length_px(mask: np.ndarray, roi: np.ndarray) -> float:
    """The object's boundary in a mask (raw px, through its outer pixels' centres), without where the mask meets
    the ROI's own edge (the object cut by the ROI has no edge there)."""
    contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return 0.0
    # the ROI's edge: its pixels with a neighbour outside it (or past the window), looked up at the contour's
    # points only (a whole-frame erosion cost a 10 MP frame more than the contours)
    padded = cv2.copyMakeBorder(roi, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    total = 0.0
    for contour in contours:
        points = contour.reshape(-1, 2)
        x, y = points[:, 0] + 1, points[:, 1] + 1
        cut = np.zeros(len(points), bool)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                cut |= padded[y + dy, x + dx] == 0
        following = np.roll(points, -1, axis=0)
        steps = np.hypot(*(following - points).T)
        total += float(steps[~(cut & np.roll(cut, -1))].sum())
    return total


def settings_from(conditions: dict | None, tone_curve: str, object_kind: str, channel: str, area_mode: str
                  ) -> tuple[EdgeTrend | None, str]:
    """The trend a calibration's metadata records and whether it applies to frames read this way: (the trend,
    '') where it does, (None, why not) where it does not, (None, '') where none is recorded. ValueError where the
    metadata holds one that cannot be read."""
    recorded = (conditions or {}).get("edge_trend")
    if recorded is None:
        return None, ""
    trend = EdgeTrend.from_dict(recorded)
    if area_mode != "subpixel":
        return None, f"not applied in {area_mode} mode: whole pixels are counted as the paper counts them"
    if object_kind not in ("dark", "bright") or channel != "grey":
        return None, f"learned in grey levels, not applied to the {channel} channel's {object_kind} object"
    if tone_curve != trend.tone_curve:
        return None, f"learned under the {trend.tone_curve} tone curve, the frames are read under {tone_curve}"
    return trend, ""


@dataclass(frozen=True)
class EdgeCorrection:
    """What the trend does to one frame's Af (m²) and its std, and what it rests on."""

    area_m2: float  # added to Af
    std_m2: float
    offset_px: float  # how far the frame's black reaches beyond the views' mean
    white_dn: float
    boundary_px: float
    outside: bool  # the frame's white level lies outside the views'
    range_dn: tuple[float, float]  # the views' white levels
    moved: bool  # a trend (or the nearest views' residuals) moved the edges (else only their scatter is in the std)

    def summary(self) -> dict:
        return {"applied": self.moved, "area_m2": self.area_m2, "std_m2": self.std_m2, "offset_px": self.offset_px,
                "white_dn": self.white_dn, "boundary_px": self.boundary_px, "outside": self.outside,
                "range_dn": list(self.range_dn)}


def edge_correction(trend: EdgeTrend, white_dn: float, object_kind: str, mask: np.ndarray, roi: np.ndarray,
                    metres_per_px: float) -> EdgeCorrection:
    """The frame's edges moved back by the trend at its white level: Af changes by the offset over the object's
    boundary (the mask's, in raw px, at `metres_per_px` on the object: its counted pixels' mean footprint)."""
    offset, offset_std, outside = trend.offset_px(white_dn)
    boundary = boundary_length_px(mask, roi)
    sign = -1.0 if object_kind == "dark" else 1.0  # the black reaching further makes a dark object larger
    return EdgeCorrection(sign * offset * boundary * metres_per_px**2, offset_std * boundary * metres_per_px**2,
                          offset, white_dn, boundary, outside, trend.range_dn, trend.learned or trend.local)


def apply_correction(result: AreaResult, correction: EdgeCorrection) -> None:
    """The correction applied to an AreaResult: Af and its sweep moved, the std's term added (checks.py says a
    white level outside the views')."""
    result.area_m2 += correction.area_m2
    result.sweep = [(level, area + correction.area_m2) for level, area in result.sweep]
    result.edge_trend = correction.summary()
    result.edge_trend_std_m2 = correction.std_m2
    result.area_std_m2 = float(np.hypot(result.area_std_m2, correction.std_m2))
