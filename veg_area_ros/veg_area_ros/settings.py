"""The researcher's measurement settings (threshold, object, band, ROI, morphology, area mode, levels, sweep
step) with one set of defaults and one validation, shared by `veg-area measure` and the area node, and the
measurer they build for a camera. No ROS here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .area import AreaMeasurer
from .camera_model import BrownCamera
from .classify import (
    AREA_MODES,
    TONE_CURVES,
    Classifier,
    ClassifyError,
    SharesOnlyError,
    check_levels,
    check_polygon,
)
from .flat_port import FlatPortCamera
from .port_area import PortAreaMeasurer
from .targets import TargetsSpec

THRESHOLD_MODES = ("fixed", "otsu")
# auto: the curve the calibration file records, judged on its own board views (tone_evidence), else linear
TONE_CURVE_CHOICES = ("auto", *TONE_CURVES)
MAX_SWEEP_STEP = 127  # grey levels: threshold +/- a wider step lies outside 0..255 whatever the threshold
AREA_MODE_CHOICES = ("auto", *AREA_MODES)  # auto: the reading the calibration's views favour, else the shares
NO_ROI = (0.0,)  # how a ROS parameter (typed, never empty on the command line) says "inside the targets"
NO_LEVELS = (0.0,)


def roi_polygon(values: Sequence[float] | None) -> list[float] | None:
    """The ROI rule: a flat x1,y1,x2,y2,... list of at least three finite corner pairs enclosing area, or
    None (empty, or [0.0]) for the default region inside the targets. ClassifyError says why not."""
    values = [float(v) for v in (values or ())]
    if not values or tuple(values) == NO_ROI:
        return None
    if len(values) % 2 or len(values) < 6 or not all(math.isfinite(v) for v in values):
        raise ClassifyError("the ROI needs at least 3 x,y corner pairs of finite numbers, in idealized-image pixels")
    check_polygon(values)
    return values


def given_levels(values: Sequence[float] | None) -> tuple[float, float] | None:
    """[object, background] grey levels, or None (empty, or [0.0]) to estimate them in each frame."""
    values = list(values or ())
    if not values or tuple(values) == NO_LEVELS:
        return None
    return check_levels(values)


@dataclass(frozen=True)
class MeasurementSettings:
    """How each frame is classified and measured. `threshold` is a grey level 0..255 or 'otsu' (picked per
    frame inside the ROI); `roi` a flat polygon in idealized pixels or None (inside the targets, markers
    excluded); `levels` the object's and background's grey levels or None (estimated per frame)."""

    threshold: float | str = "otsu"
    object: str = "dark"
    channel: str = "grey"
    roi: tuple[float, ...] | None = None
    open_px: int = 0
    close_px: int = 0
    area_mode: str = "auto"  # each edge pixel's share or whole pixels (AREA_MODE_CHOICES)
    levels: tuple[float, float] | None = None
    sweep_step: float = 5.0
    tone_curve: str = "auto"  # how the camera encodes light in its grey levels (TONE_CURVE_CHOICES)

    def __post_init__(self) -> None:
        roi = roi_polygon(self.roi)
        object.__setattr__(self, "roi", None if roi is None else tuple(roi))
        object.__setattr__(self, "levels", given_levels(self.levels))
        if self.tone_curve not in TONE_CURVE_CHOICES:
            raise ClassifyError(f"tone_curve must be one of {', '.join(TONE_CURVE_CHOICES)}, got {self.tone_curve!r}")
        if self.area_mode not in AREA_MODE_CHOICES:
            raise ClassifyError(f"area_mode must be one of {', '.join(AREA_MODE_CHOICES)}, got {self.area_mode!r}")
        if not (math.isfinite(self.sweep_step) and 0 < self.sweep_step <= MAX_SWEEP_STEP):
            raise ClassifyError(f"the sweep step must be a positive number of grey levels up to {MAX_SWEEP_STEP} "
                                f"(a wider step leaves the band at both ends of any threshold, and the threshold "
                                f"term would be about half the ROI's area), got {self.sweep_step:g}")
        self.classifier()  # threshold, object, channel and morphology checked once, here

    @property
    def threshold_mode(self) -> str:
        return "otsu" if self.threshold == "otsu" else "fixed"

    def with_threshold(self, mode: str, value: float) -> MeasurementSettings:
        """The node's two parameters (threshold_mode, threshold) as one setting."""
        if mode not in THRESHOLD_MODES:
            raise ClassifyError(f"threshold_mode must be fixed or otsu, got {mode!r}")
        return replace(self, threshold="otsu" if mode == "otsu" else float(value))

    def tone_curve_for(self, calibration: dict | None) -> str:
        """The tone curve frames are read with: the one set, or for 'auto' the one the calibration file's
        metadata records (judged on its views by `veg-area calibrate`), else linear. An excess-green index is
        read as it is."""
        if self.tone_curve != "auto":
            return self.tone_curve
        curve = (calibration or {}).get("tone_curve", "linear")
        if curve not in TONE_CURVES:
            raise ClassifyError(f"the calibration file's tone_curve {curve!r} is none of {', '.join(TONE_CURVES)}")
        return "linear" if self.object == "green" else curve

    def area_mode_for(self, calibration: dict | None) -> str:
        """The reading frames are measured with: the mode set, or for 'auto' the one the calibration file's
        metadata records (judged on its views by `veg-area calibrate`: reading_evidence), else the shares."""
        if self.area_mode != "auto":
            return self.area_mode
        mode = (calibration or {}).get("area_mode", "subpixel")
        if mode not in AREA_MODES:
            raise ClassifyError(f"the calibration file's area_mode {mode!r} is none of {', '.join(AREA_MODES)}")
        return mode

    def classifier(self, calibration: dict | None = None) -> Classifier:
        """The classifier; `calibration`: the calibration file's metadata ('auto' reads its tone curve)."""
        return Classifier(threshold=self.threshold, object=self.object, channel=self.channel,
                          open_px=int(self.open_px), close_px=int(self.close_px),
                          tone_curve=self.tone_curve_for(calibration))

    def measurer(self, camera: BrownCamera | None, targets: TargetsSpec, port_camera: FlatPortCamera | None = None,
                 background: np.ndarray | None = None, calibration_conditions: dict | None = None,
                 previous: AreaMeasurer | PortAreaMeasurer | None = None) -> AreaMeasurer | PortAreaMeasurer:
        """The measurer for frames of `camera` (None: uncalibrated); with `port_camera`, the exact flat-port model
        of that camera's calibration file. `background`: a frame of the empty scene to even the light with;
        `calibration_conditions`: the calibration file's metadata (medium, distance, said when the frames
        leave them; the tone curve and area mode 'auto' take); `previous`: the measurer these settings replace,
        whose camera's own work (idealizing maps, pixel geometry) is taken over where it is the same camera's
        (a wide-angle model's maps take seconds at 4K: a threshold tuned live would stall on each change).
        Raises ClassifyError or TargetsError with the reason."""
        area_mode = self.area_mode_for(calibration_conditions)
        if area_mode != "subpixel" and self.area_mode == "auto":
            for given, option, what, does in (
                    (background, "background", "a background frame", "evens the light for sub-pixel shares"),
                    (self.levels, "levels", "given levels", "are the sub-pixel shares' object and background levels")):
                if given is not None:
                    raise SharesOnlyError(
                        f"{what} {does}, and area mode auto counts whole pixels here: the "
                        "calibration file's views read better counted "
                        f"({calibration_conditions.get('area_mode_evidence', 'no evidence recorded')}); set the "
                        f"area mode to subpixel to read the shares with {what}", option)
        options = dict(roi=None if self.roi is None else list(self.roi), threshold_delta=self.sweep_step,
                       area_mode=area_mode, levels=self.levels, background=background)
        if port_camera is not None:  # the port model holds at any distance; its file records its uncertainty
            return PortAreaMeasurer(port_camera, targets, self.classifier(calibration_conditions),
                                    calibration_conditions, **options)
        same = isinstance(previous, AreaMeasurer) and camera is not None and previous.camera == camera
        measurer = AreaMeasurer(camera, targets, self.classifier(calibration_conditions),
                                calibration_conditions=calibration_conditions, view=previous.view if same else None,
                                **options)
        if same:
            measurer.carried.weights.geometry = previous.carried.weights.geometry
        return measurer
