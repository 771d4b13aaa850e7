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
from .classify import Classifier, ClassifyError, check_polygon, polygon_roi
from .idealize import Idealizer
from .scale import DetectedMarker, PlaneScale, TargetsError, TargetsSpec, detect_markers, marker_centre

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
    target_pixels: dict[str, np.ndarray] = field(default_factory=dict)  # "marker 3" / "point 0" -> idealized px

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
        self.roi_polygon = None if roi is None else check_polygon(roi)  # refused now, not at every frame
        self.threshold_delta = threshold_delta
        self._rng = np.random.default_rng(seed)
        self._hand_pixels = self._idealize_points(np.array([p for p, _ in targets.points]).reshape(-1, 2))

    def _idealize_points(self, raw_pixels: np.ndarray) -> np.ndarray:
        """Hand-picked raw-frame pixels -> the idealized image."""
        if self.camera is None or len(raw_pixels) == 0:
            return raw_pixels
        return self.idealizer.ideal.normalized_to_pixels(self.camera.pixels_to_normalized(raw_pixels))

    def _find_markers(self, frame: np.ndarray) -> dict:
        """Markers found in the raw frame (all of it: idealization pushes the periphery of a barrel-distorted
        frame out of view), their corners mapped into the idealized image, the centre intersected there."""
        found = detect_markers(frame, self.targets.dictionary)
        if self.camera is None:
            return found
        return {marker_id: DetectedMarker(marker_centre(ideal), ideal)
                for marker_id, marker in found.items()
                for ideal in [self._idealize_points(marker.corners)]}

    def measure(self, frame: np.ndarray) -> AreaResult:
        image = self.idealizer(frame) if self.idealizer is not None else frame
        pixels, planes, holes, missing, labels = [], [], [], [], []
        offsets = []  # marker corners relative to their centre, to cut missing markers out of the ROI
        if self.targets.markers:
            found = self._find_markers(frame)
            for marker_id, plane in self.targets.markers.items():
                if marker_id not in found:
                    missing.append(marker_id)
                    continue
                marker = found[marker_id]
                pixels.append(marker.centre)
                planes.append(plane)
                labels.append(f"marker {marker_id}")
                offsets.append(marker.corners - marker.centre)
                holes.append(marker.centre + MARKER_EXCLUSION * offsets[-1])
        for k, ((_, plane), pixel) in enumerate(zip(self.targets.points, self._hand_pixels, strict=True)):
            pixels.append(pixel)
            planes.append(plane)
            labels.append(f"point {k}")
        if len(pixels) < 2:
            raise TargetsError(f"only {len(pixels)} target(s) found in the frame; missing marker ids {missing}")
        scale = PlaneScale.fit(np.array(pixels), np.array(planes), self.targets.distance_std_m,
                               self.targets.pixel_std)
        if self.roi_polygon is not None:
            roi = polygon_roi(image.shape, self.roi_polygon)
        else:
            if scale.kind == "distance":
                raise ClassifyError("two targets do not enclose a region; give the region of interest (--roi)")
            # the frame of ALL listed targets: a missing one is placed by the others' fit, for the ROI only
            corners = scale.plane_to_pixels(self.targets.all_planes())
            for marker_id in missing:
                centre = scale.plane_to_pixels(self.targets.markers[marker_id][None])[0]
                holes.append(centre + MARKER_EXCLUSION * np.mean(offsets, axis=0))
            hull = cv2.convexHull(corners.astype(np.float32)).reshape(-1, 2)
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
            threshold_std_m2=threshold_std, missing_targets=missing, sweep=sweep, mask=mask, roi=roi, image=image,
            target_pixels=dict(zip(labels, pixels, strict=True)))


def draw_overlay(result: AreaResult) -> np.ndarray:
    """The idealized frame with the object mask tinted red, the ROI outlined in yellow, the targets marked
    in green and Af written in the corner (BGR)."""
    image = result.image
    canvas = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    if result.mask is not None:
        tinted = canvas.copy()
        tinted[result.mask > 0] = (0, 0, 255)
        canvas = cv2.addWeighted(canvas, 0.55, tinted, 0.45, 0)
    if result.roi is not None:
        contours, _ = cv2.findContours(result.roi, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(canvas, contours, -1, (0, 255, 255), 1, cv2.LINE_AA)
    size = max(6, canvas.shape[1] // 80)
    for label, (u, v) in result.target_pixels.items():
        centre = (round(u), round(v))
        cv2.drawMarker(canvas, centre, (0, 255, 0), cv2.MARKER_CROSS, 2 * size, 1, cv2.LINE_AA)
        cv2.putText(canvas, label, (centre[0] + size, centre[1] - size), cv2.FONT_HERSHEY_SIMPLEX,
                    size / 25, (0, 255, 0), 1, cv2.LINE_AA)
    text = (f"Af = {result.area_m2 * 1e4:.2f} +/- {result.area_std_m2 * 1e4:.2f} cm2, T = {result.threshold:g}, "
            f"{'calibrated' if result.calibrated else 'UNCALIBRATED'}")
    font_scale = max(0.4, canvas.shape[1] / 1400)
    thickness = max(1, round(font_scale * 1.5))
    (text_w, text_h), baseline = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font_scale, thickness)
    cv2.rectangle(canvas, (0, 0), (text_w + 2 * size, text_h + baseline + 2 * size), (0, 0, 0), cv2.FILLED)
    cv2.putText(canvas, text, (size, text_h + size), cv2.FONT_HERSHEY_SIMPLEX, font_scale, (255, 255, 255),
                thickness, cv2.LINE_AA)
    return canvas
