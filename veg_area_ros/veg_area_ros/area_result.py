"""What a frame's measurement gives: Af, each term of its standard deviation, and everything said about its
trust (`AreaResult`), with the flat `summary` that `--json`, the CSV rows and the area node's info topic show.

No ROS here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .classify import Levels
from .light import FlatField
from .scale import PlaneScale


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
    # a lens model that folds inside the frame holds inside this radius (idealized px) around the image's centre
    model_reach_px: float | None = None
    target_pixels: dict[str, np.ndarray] = field(default_factory=dict)  # "marker 3" / "point 0" -> idealized px
    # the markers' centre localisation std measured from their corners' squareness (px per coordinate), None
    # where not measured; the scale's std uses it where it exceeds the targets file's pixel_std
    marker_std_px: float | None = None
    weight_error_bound: float = 0.0  # relative bound on Af from quantizing the pixel weights
    area_mode: str = "count"
    tone_curve: str = "linear"  # how the band's values were read as light (classify.TONE_CURVES)
    levels: Levels | None = None  # the object/background levels used (None: none could be told apart)
    discretisation_std_m2: float = 0.0  # count mode: whole edge pixels counted or not
    levels_std_m2: float = 0.0  # sub-pixel mode: level estimates, noise, pure zones
    plane_offset_std_m2: float = 0.0  # the object's plane offset from the targets' plane
    calibration_std_m2: float = 0.0  # the calibration's covariance over the ROI (0: the calibration records none)
    edge_length_px: float = 0.0  # the object's boundary in raw pixels, from its mixed pixels
    count_area_m2: float = 0.0  # Af of the whole-pixel count (equals area_m2 in count mode)
    subpixel_applied: bool = False  # sub-pixel mode used the shares (else it counted whole pixels)
    flat_field: FlatField | None = field(default=None, repr=False)  # the uneven light evened before the shares
    exposure: dict | None = None  # clipped highlights or crushed shadows near the object's edges, when there are
    exposure_std_m2: float = 0.0  # what clipping next to the edge may do to Af (in area_std_m2)
    glare: dict | None = None  # pixels brighter than the brighter class's level: a sheen or reflection (checks)
    glare_std_m2: float = 0.0  # what a sheen's lift of the darker class may do to Af (in area_std_m2)
    edge_widths: dict | None = None  # the object's and the printed markers' edge width, px (blur)
    edge_trend: dict | None = None  # the edges moved back by the calibration's trend with exposure (edge_trend)
    edge_trend_std_m2: float = 0.0  # that trend's slope uncertainty at this frame's white level (in area_std_m2)
    warnings: list[str] = field(default_factory=list)  # everything that makes this number less trustworthy

    @property
    def edge_trend_m2(self) -> float:
        """What the calibration's edge trend moved Af by (0 where no trend was applied)."""
        return float((self.edge_trend or {}).get("area_m2", 0.0))

    def summary(self) -> dict:
        return {
            "area_m2": self.area_m2, "area_std_m2": self.area_std_m2, "area_mode": self.area_mode,
            # sub-pixel mode counts whole pixels where the shares are less certain than whole pixels
            "subpixel_applied": self.subpixel_applied,
            "pixel_count": self.pixel_count, "count_area_m2": self.count_area_m2,
            "scale_m_per_px": self.scale.metres_per_pixel, "scale_kind": self.scale.kind,
            "homography": self.scale.matrix.tolist() if self.scale.kind != "distance" else None,
            "object_plane_offset_m": self.scale.plane_offset_m,
            "threshold": self.threshold, "tone_curve": self.tone_curve, "calibrated": self.calibrated,
            "scale_std_m2": self.scale_std_m2, "threshold_std_m2": self.threshold_std_m2,
            "discretisation_std_m2": self.discretisation_std_m2, "levels_std_m2": self.levels_std_m2,
            "plane_offset_std_m2": self.plane_offset_std_m2, "calibration_std_m2": self.calibration_std_m2,
            "levels": self.levels.to_dict() if self.levels is not None else None,
            "edge_length_px": self.edge_length_px,
            "missing_targets": list(self.missing_targets), "marker_std_px": self.marker_std_px,
            "target_pixel_stds_px": self.scale.pixel_stds().tolist(), "sweep": [list(s) for s in self.sweep],
            "weight_error_bound": self.weight_error_bound,
            "light": None if self.flat_field is None else {
                "evened_by": self.flat_field.source, "variation": self.flat_field.variation,
                "misfit": self.flat_field.misfit},
            "exposure": self.exposure, "exposure_std_m2": self.exposure_std_m2, "glare": self.glare,
            "glare_std_m2": self.glare_std_m2,
            "edge_widths": self.edge_widths,
            "edge_trend": self.edge_trend, "edge_trend_m2": self.edge_trend_m2,
            "edge_trend_std_m2": self.edge_trend_std_m2, "warnings": list(self.warnings),
        }
