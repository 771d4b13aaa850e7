"""Projected area Af of an object in a frame: idealize, locate the targets, classify, sum pixel areas.

No ROS here. Af = Σ over object pixels of their metric footprint on the object plane (constant for the
paper's two-target scale, varying over the image for a homography), with an uncertainty combining the
scale (target localisation, calliper distances) and the classification (threshold sensitivity).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .camera_model import BrownCamera
from .classify import Classifier, ClassifyError, polygon_roi
from .idealize import Idealizer
from .scale import PlaneScale, TargetsError, TargetsSpec, detect_markers

MARKER_EXCLUSION = 1.5  # markers are cut out of the default ROI this much larger than their black square


@dataclass
class AreaResult:
    area_m2: float
    area_std_m2: float
    pixel_count: int
    threshold: float
    calibrated: bool
    scale: PlaneScale
    scale_std_m2: float
    threshold_std_m2: float
    missing_targets: list[int] = field(default_factory=list)
    sweep: list[tuple[float, float]] = field(default_factory=list)  # (threshold, Af) around the chosen value
    mask: np.ndarray | None = field(default=None, repr=False)  # uint8 0/255 in the idealized image
    roi: np.ndarray | None = field(default=None, repr=False)
    image: np.ndarray | None = field(default=None, repr=False)  # the idealized frame

    def summary(self) -> dict:
        return {
            "area_m2": self.area_m2, "area_std_m2": self.area_std_m2, "pixel_count": self.pixel_count,
            "scale_m_per_px": self.scale.metres_per_pixel, "scale_kind": self.scale.kind,
            "homography": self.scale.matrix.tolist() if self.scale.kind != "distance" else None,
            "threshold": self.threshold, "calibrated": self.calibrated,
            "scale_std_m2": self.scale_std_m2, "threshold_std_m2": self.threshold_std_m2,
            "missing_targets": list(self.missing_targets), "sweep": [list(s) for s in self.sweep],
        }


class AreaMeasurer:
    """Measures frames of one camera; the idealization maps are built once."""

    def __init__(self, camera: BrownCamera | None, targets: TargetsSpec, classifier: Classifier,
                 roi: np.ndarray | None = None, threshold_delta: float = 5.0, seed: int = 0):
        self.camera = camera
        self.idealizer = Idealizer(camera) if camera is not None else None
        self.targets = targets
        self.classifier = classifier
        self.roi_polygon = None if roi is None else np.asarray(roi, float).reshape(-1, 2)
        self.threshold_delta = threshold_delta
        self._rng = np.random.default_rng(seed)
        self._hand_pixels = self._idealize_points(np.array([p for p, _ in targets.points]).reshape(-1, 2))

    def _idealize_points(self, raw_pixels: np.ndarray) -> np.ndarray:
        """Hand-picked raw-frame pixels -> the idealized image."""
        if self.camera is None or len(raw_pixels) == 0:
            return raw_pixels
        return self.camera.ideal().normalized_to_pixels(self.camera.pixels_to_normalized(raw_pixels))

    def measure(self, frame: np.ndarray) -> AreaResult:
        image = self.idealizer(frame) if self.idealizer is not None else frame
        pixels, planes, holes, missing = [], [], [], []
        if self.targets.markers:
            found = detect_markers(image, self.targets.dictionary)
            for marker_id, plane in self.targets.markers.items():
                if marker_id not in found:
                    missing.append(marker_id)
                    continue
                marker = found[marker_id]
                pixels.append(marker.centre)
                planes.append(plane)
                holes.append(marker.centre + MARKER_EXCLUSION * (marker.corners - marker.centre))
        for (_, plane), pixel in zip(self.targets.points, self._hand_pixels, strict=True):
            pixels.append(pixel)
            planes.append(plane)
        if len(pixels) < 2:
            raise TargetsError(f"only {len(pixels)} target(s) found in the frame; missing marker ids {missing}")
        scale = PlaneScale.fit(np.array(pixels), np.array(planes), self.targets.distance_std_m,
                               self.targets.pixel_std)
        if self.roi_polygon is not None:
            roi = polygon_roi(image.shape, self.roi_polygon)
        else:
            if len(pixels) < 3:
                raise ClassifyError("two targets do not enclose a region; give the region of interest (--roi)")
            hull = cv2.convexHull(np.array(pixels, np.float32)).reshape(-1, 2)
            roi = polygon_roi(image.shape, hull, holes)
        if self.idealizer is not None:
            roi &= self.idealizer.valid_mask()  # never count the black border the remap leaves
        band = self.classifier.index_image(image)
        threshold = self.classifier.resolve_threshold(band, roi)

        areas: dict[float, float] = {}  # the sweep, T and T ± delta share levels: classify each once

        def area_at(level: float) -> float:
            level = float(level)
            if level not in areas:
                v, u = np.nonzero(self.classifier.mask(band, roi, level))
                areas[level] = scale.area(np.column_stack([u, v]))
            return areas[level]

        mask = self.classifier.mask(band, roi, threshold)
        v, u = np.nonzero(mask)
        sample = np.column_stack([u, v])
        area = areas[float(threshold)] = scale.area(sample)
        delta = self.threshold_delta
        sweep = [(level, area_at(level)) for level in threshold + delta * np.arange(-3, 4) if 0 <= level <= 255]
        threshold_std = abs(area_at(min(threshold + delta, 255)) - area_at(max(threshold - delta, 0))) / 2
        if len(sample) > 2000:
            sample = sample[self._rng.choice(len(sample), 2000, replace=False)]
        scale_std = area * scale.relative_area_std(self._rng, sample)
        return AreaResult(
            area_m2=area, area_std_m2=float(np.hypot(scale_std, threshold_std)), pixel_count=len(u),
            threshold=threshold, calibrated=self.camera is not None, scale=scale, scale_std_m2=scale_std,
            threshold_std_m2=threshold_std, missing_targets=missing, sweep=sweep, mask=mask, roi=roi, image=image)
