"""Two-fold classification of object against background inside a region of interest.

No ROS here. The threshold stays the researcher's: a fixed value on grey or one channel, or Otsu within
the ROI; for plants an excess-green index (2G - R - B). The object is darker or brighter than the
background (`dark`, `bright`) or greener (`green`).

Sub-pixel area: a pixel on the object's edge holds both; its band value lies between the object's and the
background's level in proportion to how much of it the object covers. `Levels` holds the two levels (from
the ROI's band histogram, or given) and turns every band value into an object fraction. Values within a
few noise widths of a level count as pure (0 or 1), so noise and mild texture of a large background do not
add up to area. A camera's band values are encoded light: with the `srgb` tone curve the shares and Otsu's
threshold are read in linear light (an edge blurred in light is a symmetric ramp there, not in encoded levels),
the band itself staying 8-bit; `linear` (the default) takes the values as light.
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import ArrayLike

from .files import MAX_IMAGE_SIDE

OBJECTS = ("dark", "bright", "green")
AREA_MODES = ("subpixel", "count")  # object fraction of each pixel, or the paper's whole-pixel count
MAX_MORPHOLOGY_PX = 100  # an opening or closing radius; specks and pin-holes are a few pixels
PURE_ZONE_SPREADS = 4.0  # band values within this many spreads of a level are taken as pure, not mixed
MIN_SPREAD_DN = 0.5  # the spread of a level is at least the band's quantisation
BAND_VALUES = np.arange(256, dtype=float)
EDGE_ZONE = 0.15  # an edge's pixels: between the two levels' outer 15 % (noise stays out at any contrast)
BAND_POWERS = BAND_VALUES[None, :] ** np.arange(3)[:, None]  # 1, v, v² for the levels' moments
MAX_PURE_ZONES = 0.5  # both pure zones together may cover at most this share of the contrast
MIN_PURE_PIXELS = 50  # a class's interior must hold this many pixels to give its level
LEVEL_ERROR_FLOOR = 0.15  # an estimated level may be off by this share of its spread however many pixels it has
CHANNELS = ("grey", "blue", "green", "red")
EXCESS_GREEN = np.array([[-0.5, 1.0, -0.5, 128.0]])  # B, G, R, offset -> (2G - R - B) / 2 + 128, saturated
TONE_CURVES = ("linear", "srgb")  # how the band's values encode light: as they are, or the sRGB curve (IEC 61966-2-1)


class ClassifyError(ValueError):
    """Settings or a region that cannot classify a frame."""


class SharesOnlyError(ClassifyError):
    """An option of the sub-pixel shares (`option`: 'background' or 'levels') given where they are not read."""

    def __init__(self, message: str, option: str) -> None:
        super().__init__(message)
        self.option = option


def in_edge_zone(values: np.ndarray, low: float, high: float) -> np.ndarray:
    """Which values lie between two levels' outer EDGE_ZONE: an edge's pixels, noise kept out at any contrast."""
    return np.abs(values - (low + high) / 2) < (0.5 - EDGE_ZONE) * (high - low)


def to_light(values: ArrayLike, tone_curve: str) -> np.ndarray:
    """Band values (0..255, float allowed) as light on the same 0..255 scale, through the tone curve."""
    values = np.asarray(values, float)
    if tone_curve == "linear":
        return values
    x = np.clip(values / 255.0, 0.0, None)
    return 255.0 * np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def light_slope(value: float, tone_curve: str) -> float:
    """d light / d band value at `value`: how a spread of band values becomes a spread of light."""
    if tone_curve == "linear":
        return 1.0
    x = max(value / 255.0, 0.0)
    return 1 / 12.92 if x <= 0.04045 else 2.4 / 1.055 * ((x + 0.055) / 1.055) ** 1.4


MAX_ROI_COORDINATE = 2 * MAX_IMAGE_SIDE  # a corner may lie outside the image, not kilometres outside
MIN_GREEN_RANGE = 8  # excess-green levels a colour image spans at least (a grey one: 0, JPEG's chroma noise: 2-4)


@dataclass(frozen=True)
class Classifier:
    threshold: float | str = "otsu"  # 0..255 or "otsu"
    object: str = "dark"
    channel: str = "grey"
    open_px: int = 0  # morphological opening radius (removes specks), 0 = none
    close_px: int = 0  # morphological closing radius (fills pin-holes), 0 = none
    tone_curve: str = "linear"  # how the band's values encode light (TONE_CURVES)

    def __post_init__(self) -> None:
        if self.tone_curve not in TONE_CURVES:
            raise ClassifyError(f"tone curve must be one of {', '.join(TONE_CURVES)}, got {self.tone_curve!r}")
        if self.tone_curve != "linear" and self.object == "green":
            raise ClassifyError("a tone curve applies to a grey or colour channel's levels, not to the excess-green "
                                "index (a difference of encoded channels); use tone curve linear with object green")
        if self.object not in OBJECTS:
            raise ClassifyError(f"object must be one of {', '.join(OBJECTS)}, got {self.object!r}")
        if self.channel not in CHANNELS:
            raise ClassifyError(f"channel must be one of {', '.join(CHANNELS)}, got {self.channel!r}")
        if self.object == "green" and self.channel != "grey":  # it was ignored without a word
            raise ClassifyError(f"channel {self.channel} does not apply to object green: the excess-green index reads "
                                "all three colour channels; leave the channel at grey")
        numeric = isinstance(self.threshold, int | float) and not isinstance(self.threshold, bool)
        if self.threshold != "otsu" and not (numeric and np.isfinite(self.threshold) and 0 <= self.threshold <= 255):
            raise ClassifyError(f"threshold must be 0..255 or 'otsu', got {self.threshold!r}")
        if min(self.open_px, self.close_px) < 0:
            raise ClassifyError("morphology radii must be >= 0")
        if max(self.open_px, self.close_px) > MAX_MORPHOLOGY_PX:  # a kernel larger than any frame: minutes of work
            raise ClassifyError(f"morphology radii must be at most {MAX_MORPHOLOGY_PX} px, got "
                                f"{max(self.open_px, self.close_px)}")

    def index_image(self, image: np.ndarray, grey: np.ndarray | None = None) -> np.ndarray:
        """The single-band image the threshold acts on, uint8, larger = more object-like for 'bright'. `grey`:
        the colour image's grey conversion where it was made already."""
        if grey is not None and image.ndim == 3 and self.object != "green" and self.channel == "grey":
            return np.ascontiguousarray(grey)
        if image.ndim == 2:
            if self.object == "green":
                raise ClassifyError("the excess-green index needs a colour (BGR) image")
            return image
        if self.object == "green":  # ExG = 2G - R - B, halved and centred on 128 (neutral grey), in one pass
            index = cv2.transform(image, EXCESS_GREEN)
            low, high, _, _ = cv2.minMaxLoc(index)
            if high - low < MIN_GREEN_RANGE:  # a grey photo stored in colour: 128 everywhere, any threshold wrong
                raise ClassifyError(f"the image has no colour (its excess-green index spans only {high - low:g} "
                                    "levels: a grey image stored as colour); measure a dark or bright object")
            return index
        if self.channel == "grey":
            return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        return np.ascontiguousarray(image[..., CHANNELS.index(self.channel) - 1])

    def resolve_threshold(self, band: np.ndarray, roi: np.ndarray) -> float:
        if self.threshold != "otsu":
            return float(self.threshold)
        return otsu_level(np.bincount(band[roi > 0], minlength=256), self.tone_curve)

    def object_side(self, band: np.ndarray, threshold: float) -> np.ndarray:
        """Where the band lies on the object's side of the threshold (bool, anywhere in the band)."""
        return band <= threshold if self.object == "dark" else band > threshold

    def mask(self, band: np.ndarray, roi: np.ndarray, threshold: float) -> np.ndarray:
        """Object pixels (uint8 0/255) inside the ROI for a given threshold on the band."""
        mask = (self.object_side(band, threshold) & (roi > 0)).astype(np.uint8) * 255
        for radius, op in ((self.open_px, cv2.MORPH_OPEN), (self.close_px, cv2.MORPH_CLOSE)):
            if radius:
                kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
                mask = cv2.morphologyEx(mask, op, kernel) & roi
        return mask


@dataclass(frozen=True)
class Levels:
    """The band values of pure object and pure background pixels and their spreads (robust sd: noise plus
    texture), in band units (DN)."""

    object: float
    background: float
    object_spread: float = MIN_SPREAD_DN
    background_spread: float = MIN_SPREAD_DN
    estimated: bool = True  # from the frame's ROI, or given by the user
    # how far each level itself may be off (DN, 1 std): its pure pixels' standard error and the light's
    # unevenness that is left; None: not known, the spread is taken (a level may then be off by a whole spread)
    object_error: float | None = None
    background_error: float | None = None
    tone_curve: str = "linear"  # the shares are read in light through this curve (TONE_CURVES)

    def error(self, name: str) -> float:
        """How far the object's or the background's level may be off (DN): its error, else its spread."""
        known = getattr(self, f"{name}_error")
        return getattr(self, f"{name}_spread") if known is None else known

    def with_unevenness(self, relative: float) -> Levels:
        """These levels with a relative unevenness of the light left over the image added to their errors."""
        return replace(self, object_error=math.hypot(self.error("object"), relative * self.object),
                       background_error=math.hypot(self.error("background"), relative * self.background))

    @property
    def contrast(self) -> float:
        return abs(self.background - self.object)

    def share_spreads(self) -> tuple[float, float]:
        """The object's and the background's spreads as shares of the contrast, in light."""
        light = abs(float(to_light(self.background, self.tone_curve) - to_light(self.object, self.tone_curve)))
        return tuple(getattr(self, f"{name}_spread") * light_slope(getattr(self, name), self.tone_curve)
                     / max(light, 1e-9) for name in ("object", "background"))

    def pure_zones(self) -> tuple[float, float]:
        """Fractions within which a pixel counts as pure object (1 - eps..1) or background (0..eps). The two
        zones are equally wide (the wider spread's): a blurred edge's symmetric ramp then loses at one end
        what it gains at the other."""
        if self.tone_curve == "linear":
            eps = PURE_ZONE_SPREADS * max(self.object_spread, self.background_spread) / max(self.contrast, 1e-9)
        else:
            eps = PURE_ZONE_SPREADS * max(self.share_spreads())
        return eps, eps

    def resolvable(self) -> bool:
        """Whether the mixed range between the pure zones is at least half the contrast; else the levels are
        too uneven for sub-pixel shares to beat the whole-pixel count, which is used instead."""
        eps_object, eps_background = self.pure_zones()
        return eps_object + eps_background <= MAX_PURE_ZONES

    def fractions(self, values: np.ndarray | None = None) -> np.ndarray:
        """The object fraction (0..1) of a pixel of each band value (all 256 by default)."""
        if values is None:  # the same levels recur (threshold sweep): computed once per levels
            return _fractions_of_every_value(self)
        if self.tone_curve == "linear":
            fraction = (self.background - np.asarray(values, float)) / (self.background - self.object)
        else:
            background = to_light(self.background, self.tone_curve)
            fraction = ((background - to_light(values, self.tone_curve))
                        / (background - to_light(self.object, self.tone_curve)))
        eps_object, eps_background = self.pure_zones()
        fraction[fraction <= eps_background] = 0.0
        fraction[fraction >= 1 - eps_object] = 1.0
        return fraction

    def mixed(self) -> np.ndarray:
        """Which of the 256 band values are mixed (strictly between the pure zones): the pixels of an edge."""
        fraction = self.fractions()
        return (fraction > 0) & (fraction < 1)

    def to_dict(self) -> dict:
        return {"object": self.object, "background": self.background, "object_spread": self.object_spread,
                "background_spread": self.background_spread, "estimated": self.estimated,
                "object_error": self.object_error, "background_error": self.background_error,
                "tone_curve": self.tone_curve}


@functools.lru_cache(maxsize=64)
def _fractions_of_every_value(levels: Levels) -> np.ndarray:
    fractions = levels.fractions(BAND_VALUES)
    fractions.setflags(write=False)
    return fractions


ONE_CLASS_SPREADS = 3  # class peaks closer than this many background spreads: one class, no object
# ... unless the histogram falls between them below this share of the lower peak: two classes with many edge
# pixels (a board of 16 px squares: a third of its whites mixed, which widen the background's spread)
VALLEY_SHARE = 0.25
VALLEY_SMOOTHING = 5  # bins of the box the histogram is smoothed with before its valley is read


class LevelEstimator:
    """Object and background levels of a 256-bin band histogram of the ROI, split at a threshold: each class's
    mode, its spread (the one-sided RMS deviation from the mode on the side away from the other class, where
    no mixed edge pixel lies) and the mode refined by the class's centroid within two spreads. Built once per
    frame (cumulative sums), then cheap at any threshold. The background's spread is also taken from its
    quantiles on the side of the object (uneven light darkens or brightens it there too): a background
    that varies widely leaves no value mixed, and sub-pixel area becomes the whole-pixel count."""

    def __init__(self, counts: np.ndarray, object_is_high: bool, tone_curve: str = "linear"):
        counts = np.asarray(counts, float)
        self.counts = counts
        self.object_is_high = object_is_high
        self.tone_curve = tone_curve
        sums = np.zeros((3, 257))
        np.cumsum(counts * BAND_POWERS, axis=1, out=sums[:, 1:])
        self._sums = sums.tolist()
        self._levels_at: dict[int, Levels | None] = {}  # by split: the drift check, the empty check and the sweep

    def _sum(self, power: int, first: int, last: int) -> float:
        """Σ counts * value**power over values first..last (inclusive)."""
        return self._sums[power][last + 1] - self._sums[power][first]

    def _quantile(self, first: int, last: int, share: float) -> int:
        """The band value below which `share` of the pixels with values first..last lie."""
        cumulative = self._sums[0]
        goal = cumulative[first] + share * (cumulative[last + 1] - cumulative[first])
        return min(max(bisect.bisect_left(cumulative, goal) - 1, first), last)

    def _class(self, first: int, last: int, far_side: int, background: bool) -> tuple[float, float, float] | None:
        if last < first or self._sum(0, first, last) == 0:
            return None
        mode = first + int(self.counts[first:last + 1].argmax())
        far = (first, mode) if far_side < 0 else (mode, last)
        n, s1, s2 = (self._sum(power, *far) for power in range(3))
        spread = max(math.sqrt(max(s2 - 2 * mode * s1 + mode * mode * n, 0.0) / n), MIN_SPREAD_DN)
        if background:  # uneven light spreads the background both ways; its few mixed pixels barely move quantiles
            spread = max(spread, abs(mode - self._quantile(first, last, 0.16 if far_side > 0 else 0.84)))
        reach = math.floor(2 * spread + 0.5)
        near = (max(first, mode - reach), min(last, mode + reach))
        pure = self._sum(0, *near)
        # the centroid's standard error, and a floor for what a histogram's mode cannot tell (quantisation, the
        # skew the mixed pixels on the near side give it)
        error = math.hypot(spread / math.sqrt(pure), LEVEL_ERROR_FLOOR * spread, MIN_SPREAD_DN / 2)
        return self._sum(1, *near) / pure, spread, error

    def at(self, threshold: float) -> Levels | None:
        """The levels with the classes split at `threshold` (low class: band <= threshold); None when either
        class is empty (nothing to take a level from)."""
        split = min(max(math.floor(threshold), -1), 255)
        if split not in self._levels_at:
            low = self._class(0, split, -1, background=self.object_is_high)
            high = self._class(split + 1, 255, +1, background=not self.object_is_high)
            if low is None or high is None:
                self._levels_at[split] = None
            else:
                (obj, obj_spread, obj_error), (bg, bg_spread, bg_error) = ((high, low) if self.object_is_high
                                                                           else (low, high))
                self._levels_at[split] = Levels(obj, bg, obj_spread, bg_spread, object_error=obj_error,
                                                background_error=bg_error, tone_curve=self.tone_curve)
        return self._levels_at[split]

    def _valley_between(self, split: int) -> bool:
        """Whether the histogram falls deep between the modes of the two sides of `split`: two classes, however
        wide their spreads."""
        return _valley_share(self.counts, split) < VALLEY_SHARE

    def no_object(self, threshold: float) -> str | None:
        """Why the ROI holds no object at this threshold, or None: no pixel on the object's side, or the two
        sides peak within ONE_CLASS_SPREADS of the background's spread of each other (one class of grey levels,
        noise or texture cut in two: Otsu's threshold on an empty scene), where Af would be a large number
        of background pixels."""
        split = min(max(math.floor(threshold), -1), 255)
        low, high = self._sum(0, 0, split), self._sum(0, split + 1, 255)
        if (high if self.object_is_high else low) == 0:
            return f"no pixel of the region of interest lies on the object's side of the threshold {threshold:g}"
        if (low if self.object_is_high else high) == 0:
            return None  # all object: the ROI lies inside it (said as the object touching the ROI's border)
        levels = self.at(threshold)
        if levels is None:
            return None
        apart = abs(levels.background - levels.object)
        if apart < ONE_CLASS_SPREADS * levels.background_spread and not self._valley_between(split):
            return (f"the region of interest's grey levels form one class: the two sides of the threshold "
                    f"{threshold:g} peak {apart:.1f} DN apart, within {ONE_CLASS_SPREADS} times the background's "
                    f"spread ({levels.background_spread:.1f} DN)")
        return None


def _valley_share(counts: np.ndarray, split: int) -> float:
    """The smoothed histogram's lowest point between the modes of its two sides of `split`, as a share of the
    lower mode (1: no valley between them)."""
    smooth = np.convolve(counts, np.ones(VALLEY_SMOOTHING) / VALLEY_SMOOTHING, mode="same")
    low = int(smooth[:split + 1].argmax())
    high = split + 1 + int(smooth[split + 1:].argmax())
    peaks = min(smooth[low], smooth[high])
    return float(smooth[low:high + 1].min() / peaks) if peaks > 0 else 1.0


def pure_level(counts: np.ndarray) -> tuple[float, float, float] | None:
    """The level, spread and standard error (DN) of pixels known to be pure (a class's interior, away from any
    edge), from their 256-bin histogram: the mean within three robust sd of the median (symmetric noise and
    texture average out; nothing mixed skews it). None for fewer than MIN_PURE_PIXELS."""
    counts = np.asarray(counts, float)
    total = counts.sum()
    if total < MIN_PURE_PIXELS:
        return None
    cumulative = np.cumsum(counts)
    median = float(np.searchsorted(cumulative, total / 2))
    low, high = np.searchsorted(cumulative, total * 0.25), np.searchsorted(cumulative, total * 0.75)
    sd = max(float(high - low) / 1.349, MIN_SPREAD_DN)
    window = np.abs(BAND_VALUES - median) <= 3 * sd
    n = counts[window].sum()
    level = float(counts[window] @ BAND_VALUES[window] / n)
    spread = max(float(np.sqrt(counts[window] @ (BAND_VALUES[window] - level) ** 2 / n)), MIN_SPREAD_DN)
    return level, spread, math.hypot(spread / math.sqrt(n), MIN_SPREAD_DN / 2)


def check_levels(levels: Sequence[float] | None) -> tuple[float, float] | None:
    """User-given (object level, background level) as two floats, or None to estimate them per frame; a
    ClassifyError if they cannot tell an edge pixel's share."""
    if levels is None or (isinstance(levels, list | tuple) and len(levels) == 0):
        return None
    try:
        object_level, background_level = (float(v) for v in levels)
    except (TypeError, ValueError) as exc:
        raise ClassifyError(f"levels must be two numbers (object, background), got {levels!r}") from exc
    if not all(np.isfinite(v) and 0 <= v <= 255 for v in (object_level, background_level)):
        raise ClassifyError(f"levels must be two numbers 0..255, got {levels!r}")
    if abs(background_level - object_level) < 4:
        raise ClassifyError(f"object level {object_level:g} and background level {background_level:g} are too "
                            "close to tell an edge pixel's share (at least 4 grey levels apart)")
    return object_level, background_level


def otsu_level(counts: np.ndarray, tone_curve: str = "linear") -> float:
    """Otsu's threshold from a 256-bin histogram of the band in the ROI: the level t that maximises the
    between-class variance of {<= t} and {> t} (the first such level, as OpenCV chooses), the variance of light
    through `tone_curve`."""
    counts = np.asarray(counts, float)
    total = counts.sum()
    if total == 0:
        raise ClassifyError("the region of interest is empty")
    levels = np.arange(len(counts)) if tone_curve == "linear" else to_light(np.arange(len(counts)), tone_curve)
    weight_low = np.cumsum(counts) / total
    mean_low_sum = np.cumsum(counts * levels) / total
    mean_all = mean_low_sum[-1]
    weight_high = 1 - weight_low
    with np.errstate(divide="ignore", invalid="ignore"):
        between = weight_low * weight_high * (mean_low_sum / weight_low - (mean_all - mean_low_sum) / weight_high) ** 2
    eps = np.finfo(np.float32).eps
    between[(np.minimum(weight_low, weight_high) < eps) | ~np.isfinite(between)] = -1
    return float(np.argmax(between)) if between.max() >= 0 else 0.0


def check_polygon(polygon: ArrayLike) -> np.ndarray:
    """A region-of-interest polygon as (N, 2) floats; ClassifyError unless it has 3+ corners enclosing area."""
    polygon = np.asarray(polygon, float).reshape(-1, 2)
    if len(polygon) < 3:
        raise ClassifyError(f"a region of interest needs at least 3 corners, got {len(polygon)}")
    if np.all(np.isfinite(polygon)) and np.max(np.abs(polygon)) > MAX_ROI_COORDINATE:
        raise ClassifyError(f"a region of interest corner at {np.max(np.abs(polygon)):.3g} px lies beyond any image "
                            f"(pixel coordinates up to {MAX_IMAGE_SIDE})")
    if not np.all(np.isfinite(polygon)) or cv2.contourArea(polygon.astype(np.float32)) < 1.0:
        if np.all(np.isfinite(polygon)) and np.all(np.abs(polygon) <= 1.0) and np.ptp(polygon) > 0:
            raise ClassifyError("the region of interest's corners all lie within 1 px of the origin: they look "
                                "like fractions of the image, and a region of interest is in pixels (of the "
                                "idealized image)")
        crossing = crossing_edges(polygon) if np.all(np.isfinite(polygon)) else None
        if crossing is None:
            raise ClassifyError("the region of interest is empty (its corners enclose less than one pixel)")
    crossing = crossing_edges(polygon)
    if crossing is not None:  # its outline and the pixels filled inside it would disagree on what is inside
        first, second = crossing
        raise ClassifyError(f"the region of interest's edges cross (edge {first + 1} and edge {second + 1} of "
                            f"{len(polygon)}): give its corners in order around the region")
    return polygon


def crossing_edges(polygon: np.ndarray) -> tuple[int, int] | None:
    """The first two edges of a closed polygon that cross each other (indices, edge k runs from corner k to
    k + 1), or None: edges that only touch, or neighbours sharing a corner, do not count."""
    start = polygon
    end = np.roll(polygon, -1, axis=0)
    count = len(polygon)

    # the sign of c's side of the line a -> b, for every pair at once
    def side(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        along, to = b - a, c - a
        return np.sign(along[..., 0] * to[..., 1] - along[..., 1] * to[..., 0])

    p, q = start[:, None], end[:, None]
    r, t = start[None, :], end[None, :]
    crosses = (side(p, q, r) * side(p, q, t) < 0) & (side(r, t, p) * side(r, t, q) < 0)
    index = np.arange(count)
    apart = np.abs(index[:, None] - index[None, :])
    neighbours = (apart <= 1) | (apart == count - 1)
    crosses &= ~neighbours & (index[:, None] < index[None, :])
    found = np.argwhere(crosses)
    return (int(found[0][0]), int(found[0][1])) if len(found) else None


def _clip(polygon: np.ndarray, axis: int, limit: float, keep_below: bool) -> np.ndarray:
    """One Sutherland–Hodgman step: the part of the polygon on one side of the line x[axis] = limit."""
    if len(polygon) == 0:
        return polygon
    kept = []
    for start, end in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        start_in = start[axis] <= limit if keep_below else start[axis] >= limit
        end_in = end[axis] <= limit if keep_below else end[axis] >= limit
        if start_in:
            kept.append(start)
        if start_in != end_in:
            t = (limit - start[axis]) / (end[axis] - start[axis])
            kept.append(start + t * (end - start))
    return np.array(kept).reshape(-1, 2)


def roi_area_inside(polygon: ArrayLike, width: int, height: int) -> float:
    """Area (px²) of the part of the polygon inside a width x height image; exact for convex polygons and a
    bound from above for others (enough to refuse a ROI that misses the image)."""
    clipped = check_polygon(polygon)
    for axis, limit, below in ((0, -0.5, False), (0, width - 0.5, True), (1, -0.5, False), (1, height - 0.5, True)):
        clipped = _clip(clipped, axis, limit, below)
    return polygon_area(clipped) if len(clipped) >= 3 else 0.0


def polygon_area(corners: np.ndarray) -> float:
    """The area (px²) a simple polygon (N, 2) encloses (the shoelace formula)."""
    x, y = corners[:, 0], corners[:, 1]
    return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2)


def check_roi_in_image(polygon: ArrayLike, width: int, height: int) -> np.ndarray:
    """The polygon, or ClassifyError when it encloses less than a pixel of the width x height image."""
    if roi_area_inside(polygon, width, height) < 1.0:
        corners = np.asarray(polygon, float).reshape(-1, 2)
        raise ClassifyError(f"the region of interest ({corners.min(axis=0).round(1).tolist()} to "
                            f"{corners.max(axis=0).round(1).tolist()} px) lies outside the {width}x{height} image")
    return check_polygon(polygon)


def polygon_roi(shape: tuple[int, int], polygon: np.ndarray, holes: list[np.ndarray] = ()) -> np.ndarray:
    """uint8 ROI mask: the pixels whose centre lies inside `polygon` (N, 2 px) and outside every hole polygon,
    so that the mask's area is the polygon's on average (OpenCV's fill also takes every pixel its outline
    touches: half a pixel too much all round, +1.5 % on a 30 px square)."""
    roi = centre_mask(shape, check_polygon(polygon))
    for hole in holes:
        roi[centre_mask(shape, np.asarray(hole, float).reshape(-1, 2)) > 0] = 0
    if not roi.any():
        raise ClassifyError("the region of interest is empty")
    return roi


def centre_mask(shape: tuple[int, ...], polygon: np.ndarray) -> np.ndarray:
    """uint8 mask of the pixels whose centre lies inside the polygon (even-odd rule): OpenCV's fill, its
    outline's pixels and their neighbours (the fill takes too many there, and misses a few) tested one by one;
    all within the polygon's bounding box."""
    height, width = shape[:2]
    mask = np.zeros((height, width), np.uint8)
    x0, y0 = (max(int(np.floor(v)) - 2, 0) for v in polygon.min(axis=0))
    x1, y1 = (int(np.ceil(v)) + 3 for v in polygon.max(axis=0))
    x1, y1 = min(x1, width), min(y1, height)
    if x1 <= x0 or y1 <= y0:
        return mask
    local = polygon - (x0, y0)
    box = np.zeros((y1 - y0, x1 - x0), np.uint8)
    shift = 4
    cv2.fillPoly(box, [np.round(local * 2**shift).astype(np.int32)], 255, cv2.LINE_8, shift)
    # two pixels deep: OpenCV's fill of a polygon that leaves the image also takes pixels a whole pixel off it
    inner = cv2.erode(box, np.ones((5, 5), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0)
    outline = cv2.findNonZero(cv2.subtract(cv2.dilate(box, np.ones((3, 3), np.uint8)), inner))
    if outline is not None:
        u, v = outline.reshape(-1, 2).T
        box[v, u] = np.where(_centres_inside(u, v, local), 255, 0).astype(np.uint8)
    mask[y0:y1, x0:x1] = box
    return mask


POINTS_PER_BAND = 4096  # points tested against every edge at once: a bounded temporary for long outlines


def _centres_inside(u: np.ndarray, v: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Whether each point (u, v) lies inside the polygon: the even-odd count of its edges crossed by a ray
    to the right, the edges taken a band of points at a time."""
    x0, y0 = polygon[:, 0], polygon[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    inside = np.zeros(len(u), bool)
    for start in range(0, len(u), POINTS_PER_BAND):
        band = slice(start, start + POINTS_PER_BAND)
        pu, pv = u[band, None].astype(float), v[band, None].astype(float)
        spans = (y0 > pv) != (y1 > pv)
        with np.errstate(divide="ignore", invalid="ignore"):
            crossing = x0 + (pv - y0) * (x1 - x0) / (y1 - y0)
        inside[band] = np.count_nonzero(spans & (pu < crossing), axis=1) % 2 == 1
    return inside
