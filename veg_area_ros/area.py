"""Projected area Af of an object in a frame: locate the targets, classify, sum pixel areas.

No ROS here. Af = Σ over the object's pixels of the raw frame of each pixel's metric footprint on the object
plane: the idealized-image area the pixel covers (from the calibration) times the metric area of an
idealized pixel there (from the scale or homography). The weights are built once and rebuilt only when the
targets move; the frame itself is never resampled, and one 2-D histogram (band value x weight level) gives
Af for every threshold at once — the sweep and the threshold sensitivity come free. The idealize-then-count
path of the paper (`measure_idealized`) stays as the reference the fast path is tested against.

The weights are quantized into 256 levels (each level's weight is the mean of its pixels' exact weights) and,
while the targets stay put, carried to each frame's scale fit by its ratio at the ROI's centre; every result
reports the bound both put on Af (`weight_error_bound`, relative: 2e-4 to 1e-3 for the endoscope).

Two area modes. `count` is the paper's: a pixel is object or not, so each edge pixel errs by up to half a
pixel, the same way all along an edge that lies along the pixel grid. `subpixel` (the default) counts each
pixel's object fraction from its band value between the object's and the background's level (`Levels`),
from the same histogram. The uncertainty has a term for each: pixel discretisation in count mode (from the
edge length, estimated by the mixed pixels), levels, noise and pure zones in sub-pixel mode.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from .camera_model import BrownCamera
from .classify import (
    AREA_MODES,
    BAND_VALUES,
    MIN_SPREAD_DN,
    Classifier,
    ClassifyError,
    LevelEstimator,
    Levels,
    check_levels,
    check_polygon,
    check_roi_in_image,
    polygon_roi,
    pure_level,
)
from .flat_port import FlatPortCamera, PortError, absorbed_camera, estimate_pose
from .idealize import Idealizer
from .light import FlatField, check_background_frame, flat_field
from .markers import DetectedMarker, detect_markers, marker_centre, track_markers
from .scale import PlaneScale, marker_layout_problem
from .targets import TargetsError, TargetsSpec

CLIP_HIGH, CLIP_LOW = 250, 5  # band values a sensor or JPEG has clipped: whites burnt out, shadows crushed
CLIP_REACH_PX = 2  # blooming and the lens's blur carry a clipped pixel's light this far into its neighbours
CLIP_EDGE_SHARE = 0.10  # clipping next to this share of the object's edge pixels matters (real photos: 17 %, Af -1.2 %)
BORDER_TOUCH_SHARE = 0.01  # object pixels on the ROI's border, as a share of the object's: the area is cut
SWEEP_UNSETTLED = 0.02  # Af moving this much (relative) per sweep step around the threshold: no stable edge
EDGE_ZONE = 0.15  # an edge's pixels: between the two levels' outer 15 % (noise stays out at any contrast)
BLUR_RATIO = 2.0  # the object's edges this much (and a pixel) wider than the markers': blurred on its own
DISTANCE_TOLERANCE = 0.15  # targets this much (relative) nearer or farther than the calibration: said
LIGHT_REFRESH_FRAMES = 20  # a steady camera's light and levels are found afresh this often (and on a drift)
INTERIOR_PX = 3  # a class's interior: this far inside it, a blurred edge (1 px sd) adds under 0.1 % of the contrast
MAX_INTERIOR_PX = 30  # ... or deeper while the levels still move (a DSLR's turbid water: 7 px sd), up to this
MARKER_EXCLUSION = 1.5  # markers are cut out of the default ROI this much larger than their black square
WEIGHT_LEVELS = 256  # one uint8 level image, so one OpenCV 2-D histogram per frame
GEOMETRY_MARGIN_PX = 16  # raw px around the ROI's window: a small move of the ROI needs no new geometry
ROI_TOLERANCE_PX = 0.5  # targets moved further than this (idealized px) since the weights were built: rebuild
NO_CALIBRATION_FOR_OFFSET = ("an object plane offset needs a calibration (the camera's pinhole); measure with "
                             "one, or put the targets in the object's plane")
SCALE_TOLERANCE = 2e-4  # the scale changed unevenly by more than this (relative) over the ROI: rebuild...
CARRY_SHARE = 1.0  # ...unless that is within Af's relative scale std: sensor noise jitters the fit by about that


# warnings about an object's edges, levels or extent: void where no object was found
OBJECT_WARNINGS = ("counted whole pixels", "object touches the ROI's border", "threshold sweep does not settle",
                   "edges wider than the markers'")


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
    weight_error_bound: float = 0.0  # relative bound on Af from quantizing the pixel weights
    area_mode: str = "count"
    levels: Levels | None = None  # the object/background levels used (None: none could be told apart)
    discretisation_std_m2: float = 0.0  # count mode: whole edge pixels counted or not
    levels_std_m2: float = 0.0  # sub-pixel mode: level estimates, noise, pure zones
    plane_offset_std_m2: float = 0.0  # the object's plane offset from the targets' plane
    edge_length_px: float = 0.0  # the object's boundary in raw pixels, from its mixed pixels
    count_area_m2: float = 0.0  # Af of the whole-pixel count (equals area_m2 in count mode)
    subpixel_applied: bool = False  # sub-pixel mode used the shares (else it counted whole pixels)
    flat_field: FlatField | None = field(default=None, repr=False)  # the uneven light evened before the shares
    exposure: dict | None = None  # clipped highlights or crushed shadows near the object's edges, when there are
    exposure_std_m2: float = 0.0  # what clipping may do to Af, where it matters (in area_std_m2)
    edge_widths: dict | None = None  # the object's and the printed markers' edge width, px (blur)
    warnings: list[str] = field(default_factory=list)  # everything that makes this number less trustworthy

    def summary(self) -> dict:
        return {
            "area_m2": self.area_m2, "area_std_m2": self.area_std_m2, "area_mode": self.area_mode,
            # sub-pixel mode counts whole pixels where the shares are less certain than whole pixels
            "subpixel_applied": self.subpixel_applied,
            "pixel_count": self.pixel_count, "count_area_m2": self.count_area_m2,
            "scale_m_per_px": self.scale.metres_per_pixel, "scale_kind": self.scale.kind,
            "homography": self.scale.matrix.tolist() if self.scale.kind != "distance" else None,
            "object_plane_offset_m": self.scale.plane_offset_m,
            "threshold": self.threshold, "calibrated": self.calibrated,
            "scale_std_m2": self.scale_std_m2, "threshold_std_m2": self.threshold_std_m2,
            "discretisation_std_m2": self.discretisation_std_m2, "levels_std_m2": self.levels_std_m2,
            "plane_offset_std_m2": self.plane_offset_std_m2,
            "levels": self.levels.to_dict() if self.levels is not None else None,
            "edge_length_px": self.edge_length_px,
            "missing_targets": list(self.missing_targets), "sweep": [list(s) for s in self.sweep],
            "weight_error_bound": self.weight_error_bound,
            "light": None if self.flat_field is None else {
                "evened_by": self.flat_field.source, "variation": self.flat_field.variation,
                "misfit": self.flat_field.misfit},
            "exposure": self.exposure, "exposure_std_m2": self.exposure_std_m2, "edge_widths": self.edge_widths,
            "warnings": list(self.warnings),
        }


@dataclass
class _Located:
    """The targets of one frame, in the idealized image, and the scale they give."""
    scale: PlaneScale
    pixels: list[np.ndarray]
    labels: list[str]
    missing: list[int]
    holes: list[np.ndarray]  # marker squares (enlarged) to cut out of the default ROI
    offsets: list[np.ndarray]  # found markers' corners relative to their centre


@dataclass
class _Geometry:
    """Raw pixels' positions in the idealized image (float32 maps) and the idealized-image area each covers, over
    the raw window [top:bottom, left:right]."""
    top: int
    left: int
    ideal_u: np.ndarray
    ideal_v: np.ndarray
    area: np.ndarray
    frame_shape: tuple[int, int]  # (height, width) of the raw frame

    @classmethod
    def build(cls, camera: BrownCamera | None, height: int, width: int,
              window: tuple[int, int, int, int] | None = None) -> _Geometry:
        """Over `window` (top, bottom, left, right) of a height x width frame; None: the whole frame."""
        top, bottom, left, right = window if window is not None else (0, height, 0, width)
        ideal_u = np.empty((bottom - top, right - left), np.float32)
        ideal_v, area = np.empty_like(ideal_u), np.ones_like(ideal_u)
        u = np.arange(left, right, dtype=float)
        if camera is None:  # the raw frame is the idealized image
            ideal_u[:] = u
            ideal_v[:] = np.arange(top, bottom, dtype=np.float32)[:, None]
        else:
            for first in range(top, bottom, 256):
                rows = np.arange(first, min(first + 256, bottom), dtype=float)
                uv = np.column_stack([np.tile(u, len(rows)), np.repeat(rows, len(u))])
                ideal, block_area = camera.pixels_to_ideal(uv)
                block = slice(first - top, first - top + len(rows))
                ideal_u[block] = ideal[:, 0].reshape(len(rows), len(u))
                ideal_v[block] = ideal[:, 1].reshape(len(rows), len(u))
                area[block] = block_area.reshape(len(rows), len(u))
        return cls(top, left, ideal_u, ideal_v, area, (height, width))

    @property
    def full(self) -> bool:
        """The window is the whole frame."""
        return (self.top, self.left, *self.ideal_u.shape) == (0, 0, *self.frame_shape)

    @property
    def bottom(self) -> int:
        return self.top + self.ideal_u.shape[0]

    @property
    def right(self) -> int:
        return self.left + self.ideal_u.shape[1]

    def covers(self, top: int, bottom: int, left: int, right: int) -> bool:
        return self.top <= top and bottom <= self.bottom and self.left <= left and right <= self.right

    def roi(self, roi_ideal: np.ndarray) -> tuple[np.ndarray, tuple[int, int, int, int]]:
        """The ROI over the window's raw pixels and its bounding box there (x, y, w, h)."""
        roi_raw = cv2.remap(roi_ideal, self.ideal_u, self.ideal_v, cv2.INTER_NEAREST,
                            borderMode=cv2.BORDER_CONSTANT)
        return roi_raw, cv2.boundingRect(roi_raw)

    def reaches_inner_edge(self, x: int, y: int, w: int, h: int) -> bool:
        """Whether a box (in the window) touches an edge of the window that is not an edge of the frame: the
        ROI may go on beyond it."""
        height, width = self.ideal_u.shape
        return ((x == 0 and self.left > 0) or (y == 0 and self.top > 0)
                or (x + w == width and self.right < self.frame_shape[1])
                or (y + h == height and self.bottom < self.frame_shape[0]))


@dataclass
class _Weights:
    """Per-pixel metric areas of the raw frame inside the ROI, quantized to levels, for one target layout."""
    window: tuple[slice, slice]  # the ROI's bounding box in the raw frame
    roi: np.ndarray  # uint8 raw-frame ROI inside the window
    levels: np.ndarray  # uint8 weight level of every window pixel
    level_area: np.ndarray  # (WEIGHT_LEVELS,) m², the mean exact weight of the ROI pixels at each level
    error_bound: float  # max over ROI pixels of |quantized - exact| / exact
    roi_ideal: np.ndarray  # the same ROI in the idealized image (for overlays)
    scale: PlaneScale  # the fit the weights were built with
    labels: list[str]
    pixels: np.ndarray  # target positions the weights were built with
    corners: np.ndarray  # ROI polygon corners (idealized px): where a homography's change is extreme
    centre: np.ndarray  # ROI centroid (idealized px)
    relative_scale_std: float
    relative_offset_std: float  # relative std of Af from the object plane offset's uncertainty
    _border: np.ndarray | None = None
    marker_edge_px: float | None = None  # the printed markers' edge width in this layout (px)
    marker_edge_found: bool = False

    def border(self) -> np.ndarray:
        """The ROI's one-pixel border ring (its outline and the markers' holes), once per layout."""
        if self._border is None:
            inner = cv2.erode(self.roi, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0)
            self._border = cv2.subtract(self.roi, inner)  # the window's edge is the ROI's edge too
        return self._border


@dataclass
class _Light:
    """What a steady camera's frames share about the light, found in one frame and carried to the next."""
    weights: _Weights  # the layout it was found for
    unevenness: float | None  # relative, left for the levels' errors; None: no surface, a level may be off by a spread
    flat: FlatField | None = None  # applied to every frame (None: the light is even, or could not be fitted)
    levels: Levels | None = None  # from the classes' interiors
    seen_levels: Levels | None = None  # the histogram's levels in the frame it was found in: what drift is held to
    age: int = 0  # frames carried since


def _outline(mask: np.ndarray) -> int:
    """The pixels of a class (uint8 mask) that touch the other class: its one-pixel outline."""
    return cv2.countNonZero(cv2.subtract(mask, cv2.erode(mask, np.ones((3, 3), np.uint8))))


def _marker_edge_width(frame: np.ndarray, markers) -> float | None:
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
        mixed = np.count_nonzero(np.abs(grey - (low + high) / 2) < (0.5 - EDGE_ZONE) * (high - low))
        if outline:
            widths.append(mixed / outline)
    return float(np.median(widths)) if widths else None


def _centroid(mask: np.ndarray) -> np.ndarray:
    moments = cv2.moments(mask, binaryImage=True)
    return np.array([moments["m10"], moments["m01"]]) / moments["m00"]


class AreaMeasurer:
    """Measures the frames of one camera: per-pixel geometry once per camera (over the ROI's
    raw window, or the whole frame once the ROI moves out of it), weights once per target layout."""

    def __init__(self, camera: BrownCamera | None, targets: TargetsSpec, classifier: Classifier,
                 roi: np.ndarray | None = None, threshold_delta: float = 5.0, area_mode: str = "subpixel",
                 levels: tuple[float, float] | None = None, background: np.ndarray | None = None,
                 even_light: bool = True, calibration_conditions: dict | None = None):
        if area_mode not in AREA_MODES:
            raise ClassifyError(f"area mode must be one of {', '.join(AREA_MODES)}, got {area_mode!r}")
        self.area_mode = area_mode
        self.given_levels = check_levels(levels)
        if self.given_levels is not None:  # reversed levels turned Af inside out (+906 %)
            object_level, background_level = self.given_levels
            if (object_level > background_level) != (classifier.object != "dark"):
                raise ClassifyError(f"levels {object_level:g},{background_level:g} are reversed for a "
                                    f"{classifier.object} object: its level must lie "
                                    f"{'below' if classifier.object == 'dark' else 'above'} the background's "
                                    "(give OBJECT,BACKGROUND)")
        self.calibration_conditions = calibration_conditions  # the calibration file's medium and distance
        # sub-pixel shares under uneven light: the band evened by the background's surface (a frame of the empty
        # scene, else fitted per frame); not for the excess-green index, which is no brightness
        self.even_light = even_light and area_mode == "subpixel" and classifier.object != "green"
        if background is not None and not self.even_light:
            raise ClassifyError("a background frame evens the light for sub-pixel shares of a dark or bright "
                                "object; it does not apply to " + ("count mode" if area_mode != "subpixel"
                                                                   else "the excess-green index"))
        if background is not None and camera is not None:
            check_background_frame(background, (camera.image_size[1], camera.image_size[0]))
        self.background_band = None if background is None else classifier.index_image(background)
        self.camera = camera
        self.idealizer = Idealizer(camera) if camera is not None else None
        self.targets = targets
        self.classifier = classifier
        # refused now, not at every frame: without a calibration the image size is known only from frames
        self.roi_polygon = (None if roi is None else check_polygon(roi) if camera is None
                            else check_roi_in_image(roi, *camera.image_size))
        self.threshold_delta = threshold_delta
        self._hand_pixels = self._idealize_points(np.array([p for p, _ in targets.points]).reshape(-1, 2))
        self._markers: dict[int, DetectedMarker] = {}  # raw-frame markers of the previous frame
        self.skip_unmoved_markers = True  # markers whose windows did not move keep their corners (markers.unmoved)
        self._geometry: _Geometry | None = None  # over the ROI's raw window, or the whole frame
        self._weights: _Weights | None = None
        self._last_scale: PlaneScale | None = None  # the last frame's fit: where a hidden marker should be
        # the last frame's markers (the same objects when none moved) and what they located: kept, not refitted
        self._last_located: tuple[list[DetectedMarker], _Located] | None = None
        self._carried: tuple[PlaneScale, tuple[_Weights, float, float]] | None = None  # the last fit's weights
        self.rebuilds = 0  # how often the weights were (re)built: once for a steady camera
        self.light_fits = 0  # how often the flat field and levels were found: every LIGHT_REFRESH_FRAMES, or a drift
        self._light: _Light | None = None  # the light and levels found and carried (sub-pixel mode)
        self._pure: tuple[Levels, float | None, Levels | None] | None = None  # carried levels as `_levels` gives them

    def start_segment(self) -> None:
        """Forget what is carried from frame to frame (tracked markers, weights, light): the next frame is
        measured as a first frame. A long input measured in segments gives the same rows whether its segments
        run one after another or on different workers."""
        self._markers, self._weights, self._last_scale, self._light = {}, None, None, None
        self._last_located = self._carried = None

    def _idealize_points(self, raw_pixels: np.ndarray) -> np.ndarray:
        """Raw-frame pixels -> the idealized image."""
        if self.camera is None or len(raw_pixels) == 0:
            return raw_pixels
        return self.idealizer.ideal.normalized_to_pixels(self.camera.pixels_to_normalized(raw_pixels))

    def _ideal_to_raw(self, ideal_pixels: np.ndarray) -> np.ndarray:
        """Idealized-image pixels -> the raw frame (the inverse of `_idealize_points`)."""
        if self.camera is None or len(ideal_pixels) == 0:
            return ideal_pixels
        return self.camera.normalized_to_pixels(self.idealizer.ideal.pixels_to_normalized(ideal_pixels))

    def _hidden_marker_guesses(self) -> dict[int, tuple[np.ndarray, float]]:
        """Where the listed markers the last frame missed should be (raw centre, half a search box of three
        marker sides), from that frame's fit of the others; none when that fit has no orientation."""
        scale = self._last_scale
        hidden = [marker_id for marker_id in self.targets.markers if marker_id not in self._markers]
        if not hidden or not self._markers or scale is None or scale.kind == "distance":
            return {}
        centres = self._ideal_to_raw(scale.plane_to_pixels(np.array([self.targets.markers[i] for i in hidden])))
        side = np.mean([np.ptp(marker.corners, axis=0).max() for marker in self._markers.values()])
        return {marker_id: (centre, 1.5 * side) for marker_id, centre in zip(hidden, centres, strict=True)}

    def _check_size(self, frame: np.ndarray) -> None:
        if self.idealizer is not None:
            self.idealizer.check(frame)

    def _locate(self, frame: np.ndarray) -> _Located:
        """Markers found in the raw frame (all of it: idealization pushes the periphery of a barrel-distorted
        frame out of view), their corners mapped into the idealized image and the centre intersected there;
        hand-picked points; the scale fit."""
        located = _Located(None, [], [], [], [], [])
        if self.targets.markers:
            self._markers = track_markers(frame, self.targets.dictionary, self._markers, set(self.targets.markers),
                                          self._hidden_marker_guesses(), skip_unmoved=self.skip_unmoved_markers)
            found = [marker_id for marker_id in self.targets.markers if marker_id in self._markers]
            tracked = [self._markers[marker_id] for marker_id in found]
            if self._last_located is not None and len(tracked) == len(self._last_located[0]) and all(
                    now is before for now, before in zip(tracked, self._last_located[0], strict=True)):
                return self._last_located[1]  # no marker moved: the same corners give the same fit
            located.missing = [marker_id for marker_id in self.targets.markers if marker_id not in self._markers]
            raw_corners = np.array([self._markers[marker_id].corners for marker_id in found]).reshape(-1, 2)
            for marker_id, corners in zip(found, self._idealize_points(raw_corners).reshape(-1, 4, 2), strict=True):
                centre = marker_centre(corners)
                located.pixels.append(centre)
                located.labels.append(f"marker {marker_id}")
                located.offsets.append(corners - centre)
                located.holes.append(centre + MARKER_EXCLUSION * located.offsets[-1])
        planes = [self.targets.markers[int(label.split()[1])] for label in located.labels]
        for k, ((_, plane), pixel) in enumerate(zip(self.targets.points, self._hand_pixels, strict=True)):
            located.pixels.append(pixel)
            located.labels.append(f"point {k}")
            planes.append(plane)
        if len(located.pixels) < 2:
            raise TargetsError(f"only {len(located.pixels)} target(s) found in the frame; "
                               f"missing marker ids {located.missing}")
        offset = self.targets.object_plane_offset_m
        if offset is not None and self.camera is None:
            raise TargetsError(NO_CALIBRATION_FOR_OFFSET)
        located.scale = PlaneScale.fit(np.array(located.pixels), np.array(planes), self.targets.distance_std_m,
                                       self.targets.pixel_std, offset,
                                       self.idealizer.ideal.camera_matrix if offset is not None else None)
        self._last_scale = located.scale
        if self.targets.markers:
            self._last_located = tracked, located
        return located

    def _roi_polygon(self, located: _Located) -> tuple[np.ndarray, list[np.ndarray]]:
        """The ROI polygon and holes in the idealized image: the user's, or by default the frame of ALL listed
        targets (a missing one placed by the others' fit, for the ROI only) without the marker squares."""
        if self.roi_polygon is not None:
            return self.roi_polygon, []
        scale = located.scale
        if scale.kind == "distance":
            raise ClassifyError("two targets do not enclose a region; give the region of interest (--roi)")
        holes = list(located.holes)
        for marker_id in located.missing:
            centre = scale.plane_to_pixels(self.targets.markers[marker_id][None])[0]
            holes.append(centre + MARKER_EXCLUSION * np.mean(located.offsets, axis=0))
        hull = cv2.convexHull(scale.plane_to_pixels(self.targets.all_planes()).astype(np.float32)).reshape(-1, 2)
        return hull.astype(float), holes

    def _roi_ideal(self, shape: tuple[int, ...], located: _Located) -> tuple[np.ndarray, np.ndarray]:
        polygon, holes = self._roi_polygon(located)
        if self.roi_polygon is not None:  # the user's: said to lie outside the frame, not found empty
            check_roi_in_image(polygon, shape[1], shape[0])
        roi = polygon_roi(shape, polygon, holes)
        if self.idealizer is not None:
            roi &= self.idealizer.valid_mask()  # never count the black border the remap leaves
        return roi, polygon

    def _pixel_geometry(self, height: int, width: int, roi_ideal: np.ndarray) -> _Geometry:
        """The raw pixels' positions in the idealized image and the areas they cover, over a window holding
        the raw pixels of this ROI (`_raw_window`; the first ROI's window with a margin, the whole frame once
        a later ROI leaves it), in row blocks to bound the memory of a 10-megapixel frame."""
        geometry = self._geometry
        if geometry is not None and geometry.frame_shape != (height, width):  # frames of another size (no camera)
            geometry = self._geometry = None
        if geometry is not None and geometry.full:
            return geometry
        window = self._raw_window(height, width, roi_ideal)
        if geometry is not None and geometry.covers(*window):
            return geometry
        # the first ROI's window; a second one (the ROI moves): the whole frame, once for all
        self._geometry = _Geometry.build(self.camera, height, width, window if geometry is None else None)
        return self._geometry

    def _raw_window(self, height: int, width: int, roi_ideal: np.ndarray) -> tuple[int, int, int, int]:
        """Rows and columns (top, bottom, left, right; ends excluded) of the raw frame whose pixels can land in
        the ROI: the raw image of the ROI's bounding box (widened by a pixel for the nearest-pixel lookup,
        its edges taken every half pixel) with GEOMETRY_MARGIN_PX around it, within the frame. The lens maps
        the box's inside inside its edges' image; `_build_weights` checks that the ROI did not reach the
        window's edge."""
        x, y, w, h = cv2.boundingRect(roi_ideal)
        if w == 0 or h == 0 or self.camera is None:
            return 0, height, 0, width
        x0, y0, x1, y1 = x - 1.0, y - 1.0, x + w + 0.0, y + h + 0.0
        across = np.linspace(x0, x1, int(2 * (x1 - x0)) + 2)
        down = np.linspace(y0, y1, int(2 * (y1 - y0)) + 2)
        edges = np.vstack([np.column_stack([across, np.full_like(across, y0)]),
                           np.column_stack([across, np.full_like(across, y1)]),
                           np.column_stack([np.full_like(down, x0), down]),
                           np.column_stack([np.full_like(down, x1), down])])
        raw = self._ideal_to_raw(edges)
        if not np.all(np.isfinite(raw)):
            return 0, height, 0, width
        (u0, v0), (u1, v1) = raw.min(axis=0), raw.max(axis=0)
        margin = GEOMETRY_MARGIN_PX
        return (int(np.clip(np.floor(v0) - margin, 0, height)), int(np.clip(np.ceil(v1) + margin + 1, 0, height)),
                int(np.clip(np.floor(u0) - margin, 0, width)), int(np.clip(np.ceil(u1) + margin + 1, 0, width)))

    def _check_layout(self, located: _Located, roi_polygon: np.ndarray) -> None:
        """TargetsError when the targets file cannot describe the detected markers (`marker_layout_problem`)."""
        corners = {int(label.split()[1]): pixel + offset
                   for label, pixel, offset in zip(located.labels, located.pixels, located.offsets, strict=False)
                   if label.startswith("marker ")}
        problem = marker_layout_problem(located.scale, corners, self.targets.marker_side_m, roi_polygon)
        if problem:
            raise TargetsError(problem)

    def _build_weights(self, frame: np.ndarray, located: _Located) -> _Weights:
        height, width = frame.shape[:2]
        roi_ideal, polygon = self._roi_ideal(frame.shape, located)
        self._check_layout(located, polygon)
        geometry = self._pixel_geometry(height, width, roi_ideal)
        roi_raw, (x, y, w, h) = geometry.roi(roi_ideal)
        if w > 0 and h > 0 and geometry.reaches_inner_edge(x, y, w, h):  # the window was too small: never here
            self._geometry = geometry = _Geometry.build(self.camera, height, width)
            roi_raw, (x, y, w, h) = geometry.roi(roi_ideal)
        if w == 0 or h == 0:
            raise ClassifyError("the region of interest is empty")
        local = (slice(y, y + h), slice(x, x + w))  # in the geometry's window
        window = (slice(y + geometry.top, y + geometry.top + h), slice(x + geometry.left, x + geometry.left + w))
        roi = np.ascontiguousarray(roi_raw[local])
        inside = roi > 0
        uv = np.column_stack([geometry.ideal_u[local][inside], geometry.ideal_v[local][inside]])
        exact = geometry.area[local][inside] * located.scale.pixel_area(uv)
        low, high = exact.min(), exact.max()
        step = (high - low) / (WEIGHT_LEVELS - 1) if high > low else 1.0
        level = np.rint((exact - low) / step).astype(np.uint8)
        counts = np.bincount(level, minlength=WEIGHT_LEVELS)
        level_area = np.bincount(level, exact, WEIGHT_LEVELS) / np.maximum(counts, 1)
        levels = np.zeros(roi.shape, np.uint8)
        levels[inside] = level
        centre = _centroid(roi_ideal)
        self.rebuilds += 1
        offset_std = 0.0
        if self.targets.object_plane_offset_m is not None:
            offset_std = (located.scale.relative_area_change_per_metre_at(centre)
                          * self.targets.object_plane_offset_std_m)
        return _Weights(window, roi, levels, level_area, float(np.max(np.abs(level_area[level] - exact) / exact)),
                        roi_ideal, located.scale, list(located.labels), np.array(located.pixels), polygon, centre,
                        located.scale.relative_area_std_at(centre), offset_std)

    def _weights_for(self, frame: np.ndarray, located: _Located) -> tuple[_Weights, float, float]:
        """The weights for this frame's targets, the factor that carries them to this frame's scale and the
        relative error bound of that factor; rebuilt when the target layout changed, the targets moved, or
        the scale changed unevenly over the ROI by more than matters: 2e-4, or up to Af's relative scale std
        (the targets' localisation, 0.1 px by default), which the fit's own jitter under sensor noise reaches
        (4 DN: up to 8e-4 at 640x480; 3 DN in an MJPG video: 1.4e-3; a rebuild at most frames before). Weights
        built afresh carry that same frame's fit error, so carrying is no worse in kind; the carried error
        enters the scale std (in quadrature) and the bound."""
        weights = self._weights
        if self._carried is not None and self._carried[0] is located.scale and self._carried[1][0] is weights:
            return self._carried[1]  # the same fit as the last frame's (no marker moved)
        if (weights is not None and weights.labels == located.labels
                and np.max(np.abs(weights.pixels - np.array(located.pixels))) <= ROI_TOLERANCE_PX):
            # a scale change is a ratio of two linear-fractional functions: extreme at the ROI's corners
            points = np.vstack([weights.centre, weights.corners])
            ratio = located.scale.pixel_area(points) / weights.scale.pixel_area(points)
            uneven = float(np.max(np.abs(ratio / ratio[0] - 1)))
            if uneven <= max(SCALE_TOLERANCE, CARRY_SHARE * weights.relative_scale_std):
                self._carried = located.scale, (weights, float(ratio[0]), uneven)
                return self._carried[1]
        self._weights = self._build_weights(frame, located)
        self._carried = located.scale, (self._weights, 1.0, 0.0)
        return self._carried[1]

    def _levels(self, estimator: LevelEstimator, threshold: float) -> Levels | None:
        """The object/background levels at this threshold: estimated from the ROI's band histogram, or the
        user's with the spreads the histogram shows around them."""
        light = self._light
        unevenness = None if light is None else light.unevenness

        def with_light(levels: Levels) -> Levels:
            # without a surface the light may vary: a level may be off by up to its spread
            return (replace(levels, object_error=None, background_error=None) if unevenness is None
                    else levels.with_unevenness(unevenness))

        if light is not None and light.levels is not None and self.given_levels is None:
            # the carried levels at every threshold of the sweep: made once for these levels and this light
            if self._pure is None or self._pure[0] is not light.levels or self._pure[1] != unevenness:
                pure = with_light(light.levels)
                self._pure = light.levels, unevenness, pure if pure.resolvable() else None
            return self._pure[2]
        estimated = estimator.at(threshold)
        if estimated is not None:
            estimated = with_light(estimated)
        if self.given_levels is None:
            return estimated if estimated is not None and estimated.resolvable() else None
        object_level, background_level = self.given_levels
        spreads = ((estimated.object_spread, estimated.background_spread) if estimated is not None
                   else (MIN_SPREAD_DN, MIN_SPREAD_DN))
        given = Levels(object_level, background_level, *spreads, estimated=False)
        return given if given.resolvable() else None

    def measure(self, frame: np.ndarray, keep_images: bool = False, grey: np.ndarray | None = None) -> AreaResult:
        """Af of one raw frame. `keep_images` also returns the idealized frame, its ROI and the object mask
        in it (for overlays and the node's image topics; costs a remap). `grey`: a colour frame's grey
        conversion (cv2.COLOR_BGR2GRAY) where it was made already, beside the decoding: the markers and a grey
        band are read from it, with the same result."""
        self._check_size(frame)
        if grey is not None and grey.shape != frame.shape[:2]:
            raise ValueError(f"the grey frame is {grey.shape}, the frame {frame.shape[:2]}")
        if self.background_band is not None:
            check_background_frame(self.background_band, frame.shape)
        looked_at = frame if grey is None else grey  # what the markers are found in
        located = self._locate(looked_at)
        weights, factor, carried = self._weights_for(frame, located)
        raw_band = self.classifier.index_image(frame[weights.window], None if grey is None else grey[weights.window])
        object_is_high = self.classifier.object != "dark"
        band, threshold, light, histogram = self._evened(raw_band, weights, fresh=False)
        roi_count = histogram.sum(axis=1)
        estimator = LevelEstimator(roi_count, object_is_high)
        if self._light_drifted(estimator, threshold):  # the light changed since it was fitted
            band, threshold, light, histogram = self._evened(raw_band, weights, fresh=True)
            roi_count = histogram.sum(axis=1)
            estimator = LevelEstimator(roi_count, object_is_high)
            self._light_drifted(estimator, threshold)  # found in this frame: what the next frames are held to
        # area (m²) and number of the ROI's pixels at every band value, from one 2-D histogram
        roi_area = histogram @ weights.level_area * factor
        morphology = self.classifier.open_px or self.classifier.close_px
        subpixel = self.area_mode == "subpixel"
        cumulative_area, cumulative_count = np.cumsum(roi_area), np.cumsum(roi_count)
        outcomes: dict[float, tuple[float, float, int, Levels | None]] = {}

        def measured(level: float) -> tuple[float, float, int, Levels | None]:
            """(Af in this mode, Af counted, pixels counted, levels) at a threshold, once per threshold."""
            if level not in outcomes:
                outcomes[level] = outcome(level)
            return outcomes[level]

        def outcome(level: float) -> tuple[float, float, int, Levels | None]:
            if not morphology:
                index = int(np.floor(level))
                if self.classifier.object == "dark":  # band <= level
                    counted, count = float(cumulative_area[index]), int(cumulative_count[index])
                else:
                    counted = float(cumulative_area[-1] - cumulative_area[index])
                    count = int(cumulative_count[-1] - cumulative_count[index])
                if not subpixel:  # levels only for the uncertainty, at the chosen threshold
                    return counted, counted, count, None
                levels = self._levels(estimator, level)
                area = float(roi_area @ levels.fractions()) if levels is not None else counted
                return area, counted, count, levels
            levels = self._levels(estimator, level)
            mask = self.classifier.mask(band, weights.roi, level)
            counted, count = self._mask_area(mask, weights, factor)
            if not subpixel or levels is None:
                return counted, counted, count, levels
            # the cleaned mask counts whole inside; its one-pixel rings inside and outside count their fraction
            kernel = np.ones((3, 3), np.uint8)
            inner = cv2.subtract(mask, cv2.erode(mask, kernel))
            outer = cv2.subtract(cv2.dilate(mask, kernel), mask) & weights.roi
            fractions = levels.fractions()
            area = (counted - self._ring_area(band, inner, weights, factor) @ (1 - fractions)
                    + self._ring_area(band, outer, weights, factor) @ fractions)
            return float(area), counted, count, levels

        area, counted, count, levels = measured(threshold)
        if levels is None:
            levels = self._levels(estimator, threshold)

        def edge_terms(fractional: bool) -> _EdgeTerms:
            return _edge_terms(roi_area, roi_count, levels, counted, count, fractional,
                               lambda lv: float(roi_area @ lv.fractions()))

        delta = self.threshold_delta

        def threshold_term(pick: int) -> float:  # pick 0: Af from the shares, 1: counted
            return abs(measured(min(threshold + delta, 255))[pick] - measured(max(threshold - delta, 0))[pick]) / 2

        applied = subpixel and levels is not None
        edge = edge_terms(applied)
        threshold_std = threshold_term(0 if applied else 1)
        if applied:  # shares less certain than whole pixels (uneven levels): the count is the better estimate
            counting, counting_threshold_std = edge_terms(False), threshold_term(1)
            if np.hypot(edge.levels, threshold_std) > np.hypot(counting.discretisation, counting_threshold_std):
                applied, edge, area, threshold_std = False, counting, counted, counting_threshold_std
        sweep = [(float(level), measured(level)[0 if applied else 1])
                 for level in threshold + delta * np.arange(-3, 4) if 0 <= level <= 255]
        scale_std = area * float(np.hypot(weights.relative_scale_std, carried))  # carrying errs like the scale
        offset_std = area * weights.relative_offset_std
        result = AreaResult(
            area_m2=area, area_std_m2=float(np.sqrt(scale_std**2 + threshold_std**2 + edge.discretisation**2
                                                    + edge.levels**2 + offset_std**2)),
            pixel_count=count, threshold=threshold, calibrated=self.camera is not None, scale=located.scale,
            scale_std_m2=scale_std, threshold_std_m2=threshold_std, missing_targets=list(located.missing), sweep=sweep,
            target_pixels=dict(zip(located.labels, located.pixels, strict=True)),
            weight_error_bound=weights.error_bound + carried, area_mode=self.area_mode, levels=levels,
            subpixel_applied=applied,
            discretisation_std_m2=edge.discretisation, levels_std_m2=edge.levels, plane_offset_std_m2=offset_std,
            edge_length_px=edge.length_px, count_area_m2=counted, flat_field=light)
        mask = self.classifier.mask(band, weights.roi, threshold)
        result.exposure = self._exposure(raw_band, mask, weights, factor)
        if result.exposure is not None and result.exposure["matters"]:
            # each edge pixel next to the clipping may be off by up to half a pixel, all the same way
            result.exposure_std_m2 = result.exposure["affected_area_m2"] * 0.5 / np.sqrt(3)
            result.area_std_m2 = float(np.hypot(result.area_std_m2, result.exposure_std_m2))
        result.edge_widths = self._edge_widths(looked_at, mask, roi_count, weights, levels)
        result.warnings = self._warnings(result, mask, weights, located)
        absent = estimator.no_object(threshold)
        if absent is not None:  # never a large number from the background's noise or texture
            mask = np.zeros_like(mask)
            result.area_m2 = result.count_area_m2 = result.area_std_m2 = 0.0
            result.pixel_count, result.subpixel_applied = 0, False
            result.warnings = [f"no object found: {absent}; Af is 0"] + [
                w for w in result.warnings if w.split(":", 1)[0] not in OBJECT_WARNINGS]
        if keep_images:
            raw_mask = np.zeros(frame.shape[:2], np.uint8)
            raw_mask[weights.window] = mask
            result.mask = self.idealizer(raw_mask, cv2.INTER_NEAREST) if self.idealizer is not None else raw_mask
            result.image = self.idealizer(frame) if self.idealizer is not None else frame
            result.roi = weights.roi_ideal
        return result

    def _exposure(self, raw_band: np.ndarray, mask: np.ndarray, weights: _Weights, factor: float) -> dict | None:
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
        object_is_bright = self.classifier.object != "dark"
        found = {"matters": False, "affected_area_m2": 0.0}
        for side, clipped in (("highlights", raw_band >= CLIP_HIGH), ("shadows", raw_band <= CLIP_LOW)):
            clipped = clipped.astype(np.uint8) * 255
            if not cv2.countNonZero(clipped & weights.roi):
                continue
            touched = edge & cv2.dilate(clipped, reach)
            share = cv2.countNonZero(touched) / edges
            # the class on the clipped side: the background for a dark object's highlights
            clipped_is_object = object_is_bright == (side == "highlights")
            members = mask if clipped_is_object else cv2.subtract(weights.roi, mask)
            pure = cv2.erode(members, interior)
            level_share = cv2.countNonZero(pure & clipped) / max(cv2.countNonZero(pure), 1)
            area = self._mask_area(touched, weights, factor)[0]
            matters = share >= CLIP_EDGE_SHARE
            found[side] = {"edge_share": share, "level_share": level_share, "affected_area_m2": area,
                           "clipped_class": "object" if clipped_is_object else "background",
                           "reads": "high" if clipped_is_object else "low", "matters": matters}
            if matters:
                found["matters"] = True
                found["affected_area_m2"] += area
        return found if len(found) > 2 else None

    def _warnings(self, result: AreaResult, mask: np.ndarray, weights: _Weights, located: _Located) -> list[str]:
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
        if self.area_mode == "subpixel" and not result.subpixel_applied:
            said.append("counted whole pixels: the object's and the background's levels could not be told apart "
                        "well enough for sub-pixel shares (uneven light or texture); the std is the count's")
        if located.missing:
            said.append(f"targets missing: marker(s) {located.missing} not found; the scale comes from the others "
                        "and the ROI places the missing ones by their fit")
        border = weights.border()
        touching = cv2.countNonZero(mask & border)
        if touching >= max(5, BORDER_TOUCH_SHARE * max(result.pixel_count, 1)):
            said.append(f"object touches the ROI's border: {touching} of its pixels lie on it, so Af is cut there "
                        "(widen the ROI, or move the targets)")
        if result.area_m2 > 0 and result.threshold_std_m2 / result.area_m2 > SWEEP_UNSETTLED:
            said.append(f"threshold sweep does not settle: Af changes by "
                        f"{100 * result.threshold_std_m2 / result.area_m2:.1f} % per {self.threshold_delta:g} grey "
                        "levels around the threshold (no clear edge there)")
        widths = result.edge_widths
        if widths and widths["object_px"] > BLUR_RATIO * widths["markers_px"] + 1.0:
            said.append(f"edges wider than the markers': the object's edges are {widths['object_px']:.1f} px wide, "
                        f"the printed markers' {widths['markers_px']:.1f} px (a plant moving in the current, or "
                        "out of focus): its edge shares are blurred together and Af is less certain")
        said.extend(self._condition_warnings(located))
        return said

    def _edge_widths(self, frame: np.ndarray, mask: np.ndarray, counts: np.ndarray, weights: _Weights,
                     levels: Levels | None) -> dict | None:
        """How wide (px) the object's edges are, against the printed markers' in the same frame, each as the
        pixels between the two levels' outer 15 % per pixel of outline. Blur of the water or the lens widens
        both alike; a plant moving in the current (or out of focus) widens only its own. The markers' width is
        found once per target layout."""
        if levels is None or not self._markers:
            return None
        low, high = sorted((levels.object, levels.background))
        if high - low < 20:
            return None
        inside = np.abs(BAND_VALUES - (low + high) / 2) < (0.5 - EDGE_ZONE) * (high - low)
        outline = _outline(mask)
        if outline == 0:
            return None
        if not weights.marker_edge_found:  # printed edges: once per target layout
            weights.marker_edge_px = _marker_edge_width(frame, self._markers.values())
            weights.marker_edge_found = True
        markers = weights.marker_edge_px
        if markers is None:
            return None
        return {"object_px": float(counts[inside].sum()) / outline, "markers_px": markers}

    def _condition_warnings(self, located: _Located) -> list[str]:
        """A calibration used outside its conditions (the calibration file's metadata): another distance of the
        targets' plane, or no medium recorded. A plumb_bob calibration absorbs refraction at one distance only."""
        conditions = self.calibration_conditions
        if not conditions or self.camera is None:
            return []
        said = []
        if conditions.get("medium") == "unspecified":
            said.append("calibration medium unspecified: a calibration holds only in the medium it was made in "
                        "(recalibrate with --medium air|water)")
        calibrated_at = conditions.get("calibration_distance_m")
        if calibrated_at and located.scale.kind != "distance":
            focal = float(self.idealizer.ideal.camera_matrix[0, 0])
            distance = located.scale.metres_per_pixel * focal
            if abs(distance / calibrated_at - 1) > DISTANCE_TOLERANCE:
                said.append(f"calibrated at {calibrated_at:g} m, measuring at about {distance:.2f} m"
                            f"{' in ' + conditions['medium'] if conditions.get('medium') == 'water' else ''}: "
                            "refraction is absorbed at the calibration's distance only (errors of a few percent); "
                            "calibrate at this distance or use the flat-port model")
        return said

    def _evened(self, raw_band: np.ndarray, weights: _Weights, fresh: bool
                ) -> tuple[np.ndarray, float, FlatField | None, np.ndarray]:
        """The band to read the shares from (evened where the light is uneven), its threshold, the flat field
        applied, and its 2-D histogram (band value x weight level) over the ROI. The flat field and the levels
        from the classes' interiors are found afresh every LIGHT_REFRESH_FRAMES frames, when the weights were
        rebuilt, or when `fresh` (the light drifted); in between they are carried, as a steady camera's light is."""
        threshold = self.classifier.resolve_threshold(raw_band, weights.roi)
        band, light = raw_band, self._light
        if self.even_light:
            if fresh or light is None or light.weights is not weights or light.age >= LIGHT_REFRESH_FRAMES:
                raw_threshold, reach, start = threshold, INTERIOR_PX, INTERIOR_PX
                self.light_fits += 1
                for _ in range(2):  # again, the background kept as far from the edges as they are wide
                    found = self._flat_field(raw_band, weights, raw_threshold, reach)
                    light = _Light(weights, None if found is None else found.unevenness,
                                   found if found is not None and found.needed else None)
                    band, threshold = raw_band, raw_threshold
                    if light.flat is not None:
                        band = light.flat.apply(raw_band)
                        threshold = self.classifier.resolve_threshold(band, weights.roi)
                    light.levels, settled, before = self._interior_levels(band, weights.roi, threshold, start)
                    if settled <= reach:
                        break
                    reach, start = settled, before  # the last step is taken again on the evened band
                self._light = light
            else:
                light.age += 1
                if light.flat is not None:
                    band = light.flat.apply(raw_band)
                    threshold = self.classifier.resolve_threshold(band, weights.roi)
        histogram = cv2.calcHist([band, weights.levels], [0, 1], weights.roi, [256, WEIGHT_LEVELS],
                                 [0, 256, 0, WEIGHT_LEVELS]).astype(np.float64)
        return band, threshold, light.flat if self.even_light else None, histogram

    def _light_drifted(self, estimator: LevelEstimator, threshold: float) -> bool:
        """Whether the carried flat field and levels no longer fit this frame: its background's level and spread
        as the histogram gives them (cheap) moved by more than 2 DN (or three level errors), or the spread grew
        by half (the light's shape changed), against the same figures of the frame they were found in."""
        light = self._light
        if light is None or light.levels is None:
            return False
        now = estimator.at(threshold)
        if light.age == 0:  # found in this very frame: what later frames are held to
            light.seen_levels = now
            return False
        then = light.seen_levels
        if now is None or then is None:
            return now is not then
        return (abs(now.background - then.background) > max(2.0, 3 * light.levels.error("background"))
                or now.background_spread > 1.5 * then.background_spread + 1.0)

    def _interior_levels(self, band: np.ndarray, roi: np.ndarray, threshold: float,
                         start: int = INTERIOR_PX) -> tuple[Levels | None, int, int]:
        """Both levels from the pixels at least `start` pixels inside their class (and the ROI), or deeper; the
        reach they were read at and the one before it. No edge pixel, blurred or not, pulls them towards each
        other, as it pulls a histogram's modes where an object is mostly edge (a bush's twigs under blur and
        noise: its level 2.4 DN off, Af +0.9 %). Where the edges are wider (turbid water, a DSLR's 7 px sd of
        blur) the levels still move as the interior shrinks (the bush's object level 57 DN at 3 px inside,
        40.2 at 18, truly 40): the reach grows by half until neither level moves away from the other class by
        more than twice its standard error. Where a class runs out of interior pixels (or the reach its
        limit) while a level still moved, the last move is added to that level's error: a deeper reading might
        have moved it as far again. None where a class has too small an interior even at `start` (twigs 1-3 px
        wide): the histogram's modes are used."""
        kind = self.classifier.object_side(band, threshold)
        inside = roi > 0
        classes = [(kind & inside).astype(np.uint8), (~kind & inside).astype(np.uint8)]
        levels = self._levels_inside(band, classes, start)
        reach = before = start
        if levels is None:
            return None, reach, before
        last_move = None
        while reach < MAX_INTERIOR_PX:
            deeper = min(MAX_INTERIOR_PX, int(np.ceil(reach * 1.5)))
            further = self._levels_inside(band, classes, deeper)
            if further is None:
                break
            if not _levels_moved(levels, further):
                last_move = None  # settled: a deeper reading agrees
                break
            last_move = (abs(further.object - levels.object), abs(further.background - levels.background))
            levels, before, reach = further, reach, deeper
        if last_move is not None:
            levels = replace(levels, object_error=math.hypot(levels.error("object"), last_move[0]),
                             background_error=math.hypot(levels.error("background"), last_move[1]))
        return levels, reach, before

    @staticmethod
    def _levels_inside(band: np.ndarray, classes: list[np.ndarray], reach: int) -> Levels | None:
        """The object's and the background's levels from their classes' pixels `reach` pixels inside."""
        kernel = cv2.getStructuringElement(cv2.MORPH_RECT if reach > INTERIOR_PX else cv2.MORPH_ELLIPSE,
                                           (2 * reach + 1, 2 * reach + 1))
        found = []
        for members in classes:
            interior = cv2.erode(members, kernel)
            found.append(pure_level(cv2.calcHist([band], [0], interior, [256], [0, 256]).ravel()))
        if found[0] is None or found[1] is None:
            return None
        (obj, obj_spread, obj_error), (bg, bg_spread, bg_error) = found
        return Levels(obj, bg, obj_spread, bg_spread, object_error=obj_error, background_error=bg_error)

    def _flat_field(self, band: np.ndarray, weights: _Weights, threshold: float,
                    reach: int = INTERIOR_PX) -> FlatField | None:
        """The flat field of this frame's window: from the background frame, or fitted to the background
        pixels at least `reach` - 1 pixels from any pixel of the object's class (blurred edges stay out)."""
        if self.background_band is not None:
            return flat_field(band, weights.roi, background_band=self.background_band[weights.window])
        background = ~self.classifier.object_side(band, threshold)
        size = 2 * (reach - 1) + 1
        background = cv2.erode(background.astype(np.uint8), np.ones((size, size), np.uint8)) > 0
        return flat_field(band, weights.roi, background)

    @staticmethod
    def _mask_area(mask: np.ndarray, weights: _Weights, factor: float) -> tuple[float, int]:
        counts = cv2.calcHist([weights.levels], [0], mask, [WEIGHT_LEVELS], [0, WEIGHT_LEVELS]).ravel()
        return float(counts @ weights.level_area * factor), int(counts.sum())

    @staticmethod
    def _ring_area(band: np.ndarray, ring: np.ndarray, weights: _Weights, factor: float) -> np.ndarray:
        """Area (m²) of a ring's pixels at every band value."""
        histogram = cv2.calcHist([band, weights.levels], [0, 1], ring, [256, WEIGHT_LEVELS],
                                 [0, 256, 0, WEIGHT_LEVELS]).astype(np.float64)
        return histogram @ weights.level_area * factor

    def measure_idealized(self, frame: np.ndarray) -> AreaResult:
        """The paper's path, kept as the reference: remap the frame to the ideal camera, classify there and
        count idealized pixels, each weighted by its metric area."""
        self._check_size(frame)
        located = self._locate(frame)
        image = self.idealizer(frame) if self.idealizer is not None else frame
        roi, polygon = self._roi_ideal(image.shape, located)
        self._check_layout(located, polygon)
        band = self.classifier.index_image(image)
        threshold = self.classifier.resolve_threshold(band, roi)

        def area_at(level: float) -> tuple[float, np.ndarray]:
            v, u = np.nonzero(self.classifier.mask(band, roi, level))
            return located.scale.area(np.column_stack([u, v])), u

        area, u = area_at(threshold)
        delta = self.threshold_delta
        threshold_std = abs(area_at(min(threshold + delta, 255))[0] - area_at(max(threshold - delta, 0))[0]) / 2
        scale_std = area * located.scale.relative_area_std_at(_centroid(roi))
        return AreaResult(
            area_m2=area, area_std_m2=float(np.hypot(scale_std, threshold_std)), pixel_count=len(u),
            threshold=threshold, calibrated=self.camera is not None, scale=located.scale, scale_std_m2=scale_std,
            threshold_std_m2=threshold_std, missing_targets=located.missing,
            mask=self.classifier.mask(band, roi, threshold), roi=roi, image=image,
            target_pixels=dict(zip(located.labels, located.pixels, strict=True)))


def _levels_moved(nearer: Levels, deeper: Levels) -> bool:
    """Whether either level moved, deeper inside its class, away from the other class by more than twice the two
    readings' error: a blurred edge only ever pulls a level towards the other class; a move the other way is
    the object's texture or the light (a dark leaf with a lighter midrib), which a deeper interior does not cure."""
    away = np.sign(nearer.background - nearer.object)  # the background's side of the object
    moves = {"object": (nearer.object - deeper.object) * away,
             "background": (deeper.background - nearer.background) * away}
    return any(moved > 2 * math.hypot(nearer.error(name), deeper.error(name)) for name, moved in moves.items())


@dataclass
class _EdgeTerms:
    discretisation: float = 0.0  # m², count mode
    levels: float = 0.0  # m², sub-pixel mode
    length_px: float = 0.0


def _edge_terms(roi_area: np.ndarray, roi_count: np.ndarray, levels: Levels | None, counted_area: float,
                counted_pixels: int, subpixel: bool, subpixel_area: Callable[[Levels], float]) -> _EdgeTerms:
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
            return _EdgeTerms()
        length = 2 * float(np.sqrt(np.pi * counted_pixels))  # a disc's perimeter, px
        return _EdgeTerms(discretisation=counted_area / counted_pixels * length / float(np.sqrt(24)),
                          length_px=length)
    eps_object, eps_background = levels.pure_zones()
    length = mixed_count / max(1.0 - eps_object - eps_background, 0.1)
    weight = float(roi_area[mixed].sum()) / mixed_count
    if not subpixel:
        systematic = abs(counted_area - subpixel_area(levels))
        return _EdgeTerms(discretisation=max(systematic, weight * float(np.sqrt(length / 12))), length_px=length)
    sensitivity = []
    for name in ("object", "background"):
        shift = levels.error(name)
        moved = [subpixel_area(Levels(**{**levels.to_dict(), name: getattr(levels, name) + sign * shift}))
                 for sign in (1, -1)]
        sensitivity.append((moved[0] - moved[1]) / 2)
    noise = weight * np.sqrt(mixed_count) * levels.background_spread / levels.contrast
    # the pure zones: an edge pixel within one is counted 0 or 1. Where the edge crosses the grid at random
    # phases the errors are independent; where it follows the grid they repeat along it, and what they add up
    # to shows as the change of Af when both zones are made twice as wide (an error growing with the zones'
    # width, linearly or faster, is bounded by that change)
    random_zones = weight * np.sqrt(length * (eps_object**3 + eps_background**3) / 3)
    wider = Levels(**{**levels.to_dict(), "object_spread": 2 * levels.object_spread,
                      "background_spread": 2 * levels.background_spread})
    zones = max(random_zones, abs(subpixel_area(wider) - subpixel_area(levels)))
    return _EdgeTerms(levels=float(np.sqrt(sensitivity[0] ** 2 + sensitivity[1] ** 2 + noise**2 + zones**2)),
                      length_px=length)


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
    mode = "sub-pixel" if result.subpixel_applied else "count"
    text = (f"Af = {result.area_m2 * 1e4:.2f} +/- {result.area_std_m2 * 1e4:.2f} cm2 ({mode}), "
            f"T = {result.threshold:g}, "
            f"{'calibrated' if result.calibrated else 'UNCALIBRATED'}")
    font_scale = max(0.4, canvas.shape[1] / 1400)
    thickness = max(1, round(font_scale * 1.5))
    (text_w, text_h), baseline = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font_scale, thickness)
    cv2.rectangle(canvas, (0, 0), (text_w + 2 * size, text_h + baseline + 2 * size), (0, 0, 0), cv2.FILLED)
    cv2.putText(canvas, text, (size, text_h + size), cv2.FONT_HERSHEY_SIMPLEX, font_scale, (255, 255, 255),
                thickness, cv2.LINE_AA)
    return canvas


class PortAreaMeasurer:
    """Af through a lens calibrated in air behind a flat port (`flat_port.FlatPortCamera`). The targets' plane
    pose comes from the markers through the exact refraction model; the object's plane (the targets' one, or
    `object_plane_offset_m` farther along the optical axis) and the targets' then get the plumb_bob camera that
    images them as the lens and port do (`flat_port.absorbed_camera`, fitted around the targets), and the
    measurement is the calibrated one of `AreaMeasurer` with that camera. The plane is found again when the
    targets move."""

    def __init__(self, camera: FlatPortCamera, targets: TargetsSpec, classifier: Classifier, **options):
        if len(targets.markers) + len(targets.points) < 4:
            raise TargetsError("a flat-port measurement needs 4 or more targets (the plane's pose through the port)")
        self.camera, self.targets, self.classifier, self.options = camera, targets, classifier, options
        self._inner: AreaMeasurer | None = None
        self._rebuilds_seen = 0
        self.absorbed_residual_px = float("nan")  # the plumb_bob stand-in's largest misfit around the targets
        self.plane_pose: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def rebuilds(self) -> int:
        return 0 if self._inner is None else self._inner.rebuilds

    def _plane_pose(self, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        markers = detect_markers(frame, self.targets.dictionary) if self.targets.markers else {}
        found = [i for i in self.targets.markers if i in markers]
        pixels = [markers[i].centre for i in found] + [pixel for pixel, _ in self.targets.points]
        planes = [self.targets.markers[i] for i in found] + [plane for _, plane in self.targets.points]
        if len(pixels) < 4:
            raise TargetsError(f"only {len(pixels)} target(s) found; the plane's pose through the port needs 4")
        try:
            return estimate_pose(self.camera, np.array(planes), np.array(pixels))
        except PortError as exc:
            raise TargetsError(str(exc)) from exc

    def _targets_box(self, rvec: np.ndarray, tvec: np.ndarray) -> tuple[float, float, float, float]:
        """The raw-image box of every listed target (seen or not), widened by 15 % of the image a side: where
        the default ROI and the targets are."""
        planes = self.targets.all_planes()
        pixels = self.camera.project_pose(np.column_stack([planes, np.zeros(len(planes))]), rvec, tvec)
        width, height = self.camera.image_size
        (u0, v0), (u1, v1) = pixels.min(axis=0), pixels.max(axis=0)
        return (max(0.0, u0 - 0.15 * width), max(0.0, v0 - 0.15 * height),
                min(width - 1.0, u1 + 0.15 * width), min(height - 1.0, v1 + 0.15 * height))

    def _build(self, frame: np.ndarray) -> None:
        rvec, tvec = self._plane_pose(frame)
        self.plane_pose = (rvec, tvec)
        offset = self.targets.object_plane_offset_m or 0.0
        object_tvec = np.asarray(tvec, float) + np.array([0.0, 0.0, offset])
        # one stand-in for both planes: the targets' (their centres make the scale) and the object's (its
        # pixels' footprints); through a port they are not one pinhole's, so each alone would bias the other
        absorbed, self.absorbed_residual_px = absorbed_camera(
            self.camera, rvec, object_tvec, box=self._targets_box(rvec, tvec),
            more_tvecs=(np.asarray(tvec, float),) if offset else ())
        self._inner = AreaMeasurer(absorbed, self.targets, self.classifier, **self.options)

    def start_segment(self) -> None:
        """As AreaMeasurer.start_segment; the plane's pose through the port is found anew too."""
        self._inner, self._rebuilds_seen = None, 0

    def measure(self, frame: np.ndarray, keep_images: bool = False, grey: np.ndarray | None = None) -> AreaResult:
        """As AreaMeasurer.measure (`grey` too: the markers found in it)."""
        looked_at = frame if grey is None else grey
        if self._inner is None:
            self._build(looked_at)
        result = self._inner.measure(frame, keep_images, grey)
        if self._inner.rebuilds > max(self._rebuilds_seen, 1):  # the targets moved: find their plane again
            self._build(looked_at)
            result = self._inner.measure(frame, keep_images, grey)
        self._rebuilds_seen = self._inner.rebuilds
        return result
