"""Projected area Af of an object in a frame: the measurement as a short pipeline of named stages.

No ROS here. Af = Σ over the object's pixels of the raw frame of each pixel's metric footprint on the object
plane; the frame itself is never resampled, and one 2-D histogram (band value x weight level) gives Af for
every threshold at once. A frame passes through the stages in order, each its own module:

    locate        the targets and the plane scale          (carries `Tracking`)
    region        the ROI in the idealized image
    weights       each raw pixel's footprint, quantized     (carries `WeightsMemory`)
    light_levels  the band evened, its histogram, levels    (carries `LightMemory`)
    area_terms    Af and each term of its std
    edge_trend    the edges moved back by the calibration's trend with exposure, where it records one
    checks        exposure, blur, border, conditions: the warnings

`AreaMeasurer` holds each stage's settings and what each carries from frame to frame (`Carried`), and calls
them in order. The idealize-then-count path of the paper (`measure_idealized`) stays as the reference the
fast path is tested against. docs/measuring.md explains the two area modes and each term of the std.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .area_result import AreaResult
from .area_terms import area_terms, thresholds_read
from .camera_model import BrownCamera
from .camera_uncertainty import CalibrationSpread, CameraCovariance
from .checks import CheckSettings, check
from .classify import AREA_MODES, Classifier, ClassifyError
from .edge_trend import apply_correction, edge_correction, settings_from
from .idealize import IdealView
from .light import check_background_frame
from .light_levels import LightMemory, LightSettings, levels_for, light_frame
from .locate import Locator, Tracking
from .region import Region, centroid
from .targets import TargetsSpec
from .weights import Weighting, WeightsMemory


@dataclass
class Carried:
    """What the stages carry from one frame to the next, each its own object."""
    tracking: Tracking = field(default_factory=Tracking)
    weights: WeightsMemory = field(default_factory=WeightsMemory)
    light: LightMemory = field(default_factory=LightMemory)


class AreaMeasurer:
    """Measures one camera's frames (`view`: its IdealView, if shared): per-pixel geometry once per camera (over
    the ROI's raw window, or the whole frame once the ROI moves), weights per target layout, the light as it holds."""

    def __init__(self, camera: BrownCamera | None, targets: TargetsSpec, classifier: Classifier,
                 roi: np.ndarray | None = None, threshold_delta: float = 5.0, area_mode: str = "subpixel",
                 levels: tuple[float, float] | None = None, background: np.ndarray | None = None,
                 even_light: bool = True, calibration_conditions: dict | None = None,
                 calibration_spread: CalibrationSpread | None = None, view: IdealView | None = None):
        if area_mode not in AREA_MODES:
            raise ClassifyError(f"area mode must be one of {', '.join(AREA_MODES)}, got {area_mode!r}")
        self.camera, self.targets, self.classifier = camera, targets, classifier
        self.area_mode, self.threshold_delta = area_mode, threshold_delta
        self.view = IdealView.of(camera, view)
        self.light_settings = LightSettings.checked(classifier, area_mode, levels, background, even_light,
                                                    camera.image_size if camera is not None else None)
        self.locator = Locator(targets, self.view, classifier.tone_curve)
        self.region = Region(targets, self.view, roi)
        try:  # how the calibration's views moved their edges with exposure, where it applies (edge_trend)
            self.edge_trend, self.edge_trend_reason = settings_from(
                calibration_conditions if camera is not None else None, classifier.tone_curve, classifier.object,
                classifier.channel, area_mode)
            spread = calibration_spread or CameraCovariance.from_conditions(calibration_conditions, camera)
        except ValueError as exc:
            raise ClassifyError(f"the calibration's {exc}") from None
        self.check_settings = CheckSettings(classifier, area_mode, threshold_delta, self.view, calibration_conditions,
                                            spread is not None)
        self.weighting = Weighting(targets, self.view, self.region, spread)
        self.carried = Carried()

    @property
    def rebuilds(self) -> int:
        """How often the weights were (re)built: once for a steady camera."""
        return self.carried.weights.rebuilds

    @property
    def light_fits(self) -> int:
        """How often the flat field and levels were found: every LIGHT_REFRESH_FRAMES, or on a drift."""
        return self.carried.light.fits

    def carry_on_from(self, previous: object) -> str:
        """Takes over what `previous` carried from frame to frame, as far as both were built alike (`carried_over`):
        "all" of it (tracked markers, weights, light), the targets' "place" (tracked markers and weights, where
        only what reads the light differs: the classifier, area mode, levels or background) or the "markers"
        alone with the camera's pixel geometry (where the ROI differs: its weights and light are its own). A
        measurer rebuilt for a calibration's conditions heard after the first frames (its warnings, an edge trend
        applied frame by frame, the calibration's covariance in the std) then measures the next frame with what
        `previous` carried, not as a first frame, so a live run and the same frames measured offline give the
        same numbers; one rebuilt for a threshold tuned live finds the light again but neither the markers nor
        the footprints (its first frame at 10 MP 0.06-0.09 s instead of 0.3 s); one for a ROI drawn live
        searches no marker. Returns "all", "place", "markers" or "" (nothing)."""
        how = carried_over(self, previous)
        if how == "markers":
            self.carried = Carried(previous.carried.tracking, WeightsMemory(geometry=previous.carried.weights.geometry))
        elif how:
            self.carried = previous.carried if how == "all" else Carried(previous.carried.tracking,
                                                                           previous.carried.weights)
            weights = self.carried.weights.weights
            if weights is not None and self.weighting.spread != previous.weighting.spread:
                weights.calibration = self.weighting.calibration_sensitivity(weights)
        return how

    def start_segment(self) -> None:
        """Forget what is carried from frame to frame (tracked markers, weights, light): the next frame is
        measured as a first frame. A long input measured in segments gives the same rows whether its segments
        run one after another or on different workers. The pixel geometry, the camera's alone, is kept."""
        self.carried.tracking.forget()
        self.carried.weights.forget_layout()
        self.carried.light.forget()

    def measure(self, frame: np.ndarray, keep_images: bool = False, grey: np.ndarray | None = None) -> AreaResult:
        """Af of one raw frame. `keep_images` also returns the idealized frame, its ROI and the object mask
        in it (for overlays and the node's image topics; costs a remap). `grey`: a colour frame's grey
        conversion (cv2.COLOR_BGR2GRAY) where it was made already, beside the decoding: the markers and a grey
        band are read from it, with the same result."""
        self.view.check_size(frame)
        if grey is not None and grey.shape != frame.shape[:2]:
            raise ValueError(f"the grey frame is {grey.shape}, the frame {frame.shape[:2]}")
        light = self.light_settings
        if light.background_band is not None:
            check_background_frame(light.background_band, frame.shape)
        carried = self.carried
        looked_at = frame if grey is None else grey  # what the markers are found in
        located = self.locator.locate(looked_at, carried.tracking)
        weights, factor, carry_error = self.weighting.weights_for(frame.shape, located, carried.weights)
        raw_band = self.classifier.index_image(frame[weights.window], None if grey is None else grey[weights.window])
        lit = light_frame(raw_band, weights, light, carried.light)
        subpixel = self.area_mode == "subpixel"
        wanted = thresholds_read(lit.threshold, self.threshold_delta, self.classifier, subpixel)
        levels = levels_for(lit, wanted, light, carried.light)
        mask = self.classifier.mask(lit.band, weights.roi, lit.threshold)
        terms = area_terms(lit, weights, factor, carry_error, self.classifier, subpixel, self.threshold_delta, levels,
                           weights.relative_calibration_std(mask), located.scale)
        result = AreaResult(
            area_m2=terms.area, area_std_m2=terms.std, pixel_count=terms.count, threshold=lit.threshold,
            calibrated=self.camera is not None, scale=located.scale, scale_std_m2=terms.scale_std,
            threshold_std_m2=terms.threshold_std, missing_targets=list(located.missing), sweep=terms.sweep,
            target_pixels=located.target_pixels, weight_error_bound=weights.error_bound + carry_error,
            area_mode=self.area_mode, tone_curve=self.classifier.tone_curve, levels=terms.levels,
            subpixel_applied=terms.applied, discretisation_std_m2=terms.edge.discretisation,
            levels_std_m2=terms.edge.levels, plane_offset_std_m2=terms.offset_std,
            calibration_std_m2=terms.calibration_std, edge_length_px=terms.edge.length_px,
            count_area_m2=terms.counted, flat_field=lit.flat, marker_std_px=located.marker_std_px)
        if self.edge_trend is not None and terms.applied and terms.count:
            white = max(terms.levels.object, terms.levels.background)
            correction = edge_correction(self.edge_trend, white, self.classifier.object, mask, weights.roi,
                                         float(np.sqrt(terms.counted / terms.count)))
            apply_correction(result, correction)
        elif self.edge_trend is not None or self.edge_trend_reason:  # recorded, not applied: said in the row
            result.edge_trend = {"applied": False, "reason": self.edge_trend_reason or "the shares were not used"}
        mask = check(result, self.check_settings, raw_band, lit.band, mask, looked_at, lit.roi_count, weights, factor,
                     located, carried.tracking.markers, lit.estimator)
        if keep_images:
            raw_mask = np.zeros(frame.shape[:2], np.uint8)
            raw_mask[weights.window] = mask
            result.mask = self.view.image(raw_mask, cv2.INTER_NEAREST)
            result.image = self.view.image(frame)
            result.roi = weights.roi_ideal
            if self.camera is not None and not self.camera.holds_everywhere():
                result.model_reach_px = self.camera.reach[0] * self.camera.c
        return result

    def measure_idealized(self, frame: np.ndarray) -> AreaResult:
        """The paper's path, kept as the reference: remap the frame to the ideal camera, classify there and
        count idealized pixels, each weighted by its metric area."""
        self.view.check_size(frame)
        located = self.locator.locate(frame, self.carried.tracking)
        image = self.view.image(frame)
        roi, polygon, _, _ = self.region.in_ideal(image.shape, located)
        self.region.check_layout(located, polygon)
        band = self.classifier.index_image(image)
        threshold = self.classifier.resolve_threshold(band, roi)

        def area_at(level: float) -> tuple[float, np.ndarray]:
            v, u = np.nonzero(self.classifier.mask(band, roi, level))
            return located.scale.area(np.column_stack([u, v])), u

        area, u = area_at(threshold)
        delta = self.threshold_delta
        threshold_std = abs(area_at(min(threshold + delta, 255))[0] - area_at(max(threshold - delta, 0))[0]) / 2
        scale_std = area * located.scale.relative_area_std_at(centroid(roi))
        return AreaResult(
            area_m2=area, area_std_m2=float(np.hypot(scale_std, threshold_std)), pixel_count=len(u),
            threshold=threshold, calibrated=self.camera is not None, scale=located.scale, scale_std_m2=scale_std,
            threshold_std_m2=threshold_std, missing_targets=located.missing,
            mask=self.classifier.mask(band, roi, threshold), roi=roi, image=image,
            target_pixels=located.target_pixels, marker_std_px=located.marker_std_px)


def carried_over(measurer: AreaMeasurer, previous: object) -> str:
    """How much of what `previous` carries `measurer` can take over: "all" where both were built alike (the same
    camera, targets and background objects, equal classifier, ROI, area mode and levels), "place" (the tracked
    markers and the weights) where only what reads the light differs, "markers" (the tracked markers and the
    camera's pixel geometry) where the ROI differs too, else ""."""
    if not isinstance(previous, AreaMeasurer):
        return ""
    if not (previous.camera == measurer.camera and previous.targets is measurer.targets
            and previous.classifier.tone_curve == measurer.classifier.tone_curve):  # the markers are read through it
        return ""
    ours, others = measurer.region.user_polygon, previous.region.user_polygon
    if (ours is None) != (others is None) or (ours is not None and not np.array_equal(ours, others)):
        return "markers"
    mine, theirs = measurer.light_settings, previous.light_settings
    light = (previous.classifier == measurer.classifier and previous.area_mode == measurer.area_mode
             and previous.threshold_delta == measurer.threshold_delta
             and theirs.background_band is mine.background_band and theirs.even_light == mine.even_light
             and theirs.given_levels == mine.given_levels)
    return "all" if light else "place"
