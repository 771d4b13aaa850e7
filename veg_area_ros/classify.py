"""Two-fold classification of object against background inside a region of interest.

No ROS here. The threshold stays the researcher's: a fixed value on grey or one channel, or Otsu within
the ROI; for plants an excess-green index (2G - R - B). The object is darker or brighter than the
background (`dark`, `bright`) or greener (`green`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

OBJECTS = ("dark", "bright", "green")
CHANNELS = ("grey", "blue", "green", "red")
EXCESS_GREEN = np.array([[-0.5, 1.0, -0.5, 128.0]])  # B, G, R, offset -> (2G - R - B) / 2 + 128, saturated


class ClassifyError(ValueError):
    """Settings or a region that cannot classify a frame."""


@dataclass(frozen=True)
class Classifier:
    threshold: float | str = "otsu"  # 0..255 or "otsu"
    object: str = "dark"
    channel: str = "grey"
    open_px: int = 0  # morphological opening radius (removes specks), 0 = none
    close_px: int = 0  # morphological closing radius (fills pin-holes), 0 = none

    def __post_init__(self) -> None:
        if self.object not in OBJECTS:
            raise ClassifyError(f"object must be one of {', '.join(OBJECTS)}, got {self.object!r}")
        if self.channel not in CHANNELS:
            raise ClassifyError(f"channel must be one of {', '.join(CHANNELS)}, got {self.channel!r}")
        numeric = isinstance(self.threshold, int | float) and not isinstance(self.threshold, bool)
        if self.threshold != "otsu" and not (numeric and np.isfinite(self.threshold) and 0 <= self.threshold <= 255):
            raise ClassifyError(f"threshold must be 0..255 or 'otsu', got {self.threshold!r}")
        if min(self.open_px, self.close_px) < 0:
            raise ClassifyError("morphology radii must be >= 0")

    def index_image(self, image: np.ndarray) -> np.ndarray:
        """The single-band image the threshold acts on, uint8, larger = more object-like for 'bright'."""
        if image.ndim == 2:
            if self.object == "green":
                raise ClassifyError("the excess-green index needs a colour (BGR) image")
            return image
        if self.object == "green":  # ExG = 2G - R - B, halved and centred on 128 (neutral grey), in one pass
            return cv2.transform(image, EXCESS_GREEN)
        if self.channel == "grey":
            return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        return np.ascontiguousarray(image[..., CHANNELS.index(self.channel) - 1])

    def resolve_threshold(self, band: np.ndarray, roi: np.ndarray) -> float:
        if self.threshold != "otsu":
            return float(self.threshold)
        return otsu_level(np.bincount(band[roi > 0], minlength=256))

    def mask(self, band: np.ndarray, roi: np.ndarray, threshold: float) -> np.ndarray:
        """Object pixels (uint8 0/255) inside the ROI for a given threshold on the band."""
        mask = band <= threshold if self.object == "dark" else band > threshold
        mask = (mask & (roi > 0)).astype(np.uint8) * 255
        for radius, op in ((self.open_px, cv2.MORPH_OPEN), (self.close_px, cv2.MORPH_CLOSE)):
            if radius:
                kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
                mask = cv2.morphologyEx(mask, op, kernel) & roi
        return mask


def otsu_level(counts: np.ndarray) -> float:
    """Otsu's threshold from a 256-bin histogram of the band in the ROI: the level t that maximises the
    between-class variance of {<= t} and {> t} (the first such level, as OpenCV chooses)."""
    counts = np.asarray(counts, float)
    total = counts.sum()
    if total == 0:
        raise ClassifyError("the region of interest is empty")
    levels = np.arange(len(counts))
    weight_low = np.cumsum(counts) / total
    mean_low_sum = np.cumsum(counts * levels) / total
    mean_all = mean_low_sum[-1]
    weight_high = 1 - weight_low
    with np.errstate(divide="ignore", invalid="ignore"):
        between = weight_low * weight_high * (mean_low_sum / weight_low - (mean_all - mean_low_sum) / weight_high) ** 2
    eps = np.finfo(np.float32).eps
    between[(np.minimum(weight_low, weight_high) < eps) | ~np.isfinite(between)] = -1
    return float(np.argmax(between)) if between.max() >= 0 else 0.0


def check_polygon(polygon) -> np.ndarray:
    """A region-of-interest polygon as (N, 2) floats; ClassifyError unless it has 3+ corners enclosing area."""
    polygon = np.asarray(polygon, float).reshape(-1, 2)
    if len(polygon) < 3:
        raise ClassifyError(f"a region of interest needs at least 3 corners, got {len(polygon)}")
    if not np.all(np.isfinite(polygon)) or cv2.contourArea(polygon.astype(np.float32)) < 1.0:
        raise ClassifyError("the region of interest is empty (its corners enclose no area)")
    return polygon


def polygon_roi(shape: tuple[int, int], polygon: np.ndarray, holes: list[np.ndarray] = ()) -> np.ndarray:
    """uint8 ROI mask: inside `polygon` (N, 2 px) and outside every hole polygon."""
    roi = np.zeros(shape[:2], np.uint8)
    polygon = check_polygon(polygon)
    shift = 4
    cv2.fillPoly(roi, [np.round(polygon * 2**shift).astype(np.int32)], 255, cv2.LINE_8, shift)
    for hole in holes:
        cv2.fillPoly(roi, [np.round(np.asarray(hole, float) * 2**shift).astype(np.int32)], 0, cv2.LINE_8, shift)
    if not roi.any():
        raise ClassifyError("the region of interest is empty")
    return roi
