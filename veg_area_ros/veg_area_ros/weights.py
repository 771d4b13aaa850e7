"""Stage 2 of a frame's measurement, the pixel weights: each raw pixel's metric footprint on the object plane.

It exists because Af is a sum over the raw frame's pixels of their footprints, which depend on the camera (the
idealized-image area each raw pixel covers: `PixelGeometry`, once per camera over the ROI's raw window) and on
the targets (the metric area of an idealized pixel there), and both change far more rarely than frames do.
The footprints are quantized into WEIGHT_LEVELS levels (one uint8 image: one OpenCV 2-D histogram per frame)
and, while the targets stay put, carried to each frame's scale fit by its ratio at the ROI's centre. Takes a
`Located` and the ROI (`Region`), gives the `Weights`, the factor that carries them to this frame's fit and
that factor's relative error bound; carries a `WeightsMemory` from frame to frame.

No ROS here.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .camera_model import BrownCamera
from .camera_uncertainty import KEPT_WITHIN_PX, SAMPLE_PIXELS, AreaSensitivity, CalibrationSpread
from .classify import ClassifyError, polygon_roi
from .idealize import OUTSIDE_PX, IdealView
from .locate import Located
from .region import Region, beyond_image, centroid
from .scale import PlaneScale, relative_area_std
from .targets import TargetsSpec

WEIGHT_LEVELS = 256  # one uint8 level image, so one OpenCV 2-D histogram per frame
GEOMETRY_MARGIN_PX = 16  # raw px around the ROI's window: a small move of the ROI needs no new geometry
ROI_TOLERANCE_PX = 0.5  # targets moved further than this (idealized px) since the weights were built: rebuild
SCALE_TOLERANCE = 2e-4  # the scale changed unevenly by more than this (relative) over the ROI: rebuild...
CARRY_SHARE = 1.0  # ...unless that is within Af's relative scale std: sensor noise jitters the fit by about that


@dataclass
class PixelGeometry:
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
              window: tuple[int, int, int, int] | None = None) -> PixelGeometry:
        """Over `window` (top, bottom, left, right) of a height x width frame; None: the whole frame."""
        top, bottom, left, right = window if window is not None else (0, height, 0, width)
        ideal_u = np.empty((bottom - top, right - left), np.float32)
        ideal_v, area = np.empty_like(ideal_u), np.ones_like(ideal_u)
        u = np.arange(left, right, dtype=float)
        if camera is None:  # the raw frame is the idealized image
            ideal_u[:] = u
            ideal_v[:] = np.arange(top, bottom, dtype=np.float32)[:, None]
        else:
            for first in range(top, bottom, 256):  # row blocks bound the memory of a 10-megapixel frame
                rows = np.arange(first, min(first + 256, bottom), dtype=float)
                uv = np.column_stack([np.tile(u, len(rows)), np.repeat(rows, len(u))])
                ideal, block_area = camera.pixels_to_ideal(uv)
                beyond = ~camera.within_reach(uv)  # a folding model's pixels past its fold: outside any ROI
                ideal[beyond], block_area[beyond] = OUTSIDE_PX, 0.0
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

    def roi_of(self, polygon: np.ndarray, holes: list[np.ndarray]) -> tuple[np.ndarray, tuple[int, int, int, int]]:
        """As `roi`, for a polygon reaching past the idealized image's edges: drawn on its own canvas (as far
        as the window's raw pixels reach), so the raw pixels that idealize beyond those edges are kept."""
        reached = self.area > 0  # a folding model's pixels past its fold have no place
        if not reached.any():
            return np.zeros(self.ideal_u.shape, np.uint8), (0, 0, 0, 0)
        corners = np.asarray(polygon, float).reshape(-1, 2)
        low = np.floor(np.maximum(corners.min(axis=0), [self.ideal_u[reached].min(), self.ideal_v[reached].min()]))
        high = np.ceil(np.minimum(corners.max(axis=0), [self.ideal_u[reached].max(), self.ideal_v[reached].max()]))
        low -= 1
        shape = (int(high[1] - low[1]) + 2, int(high[0] - low[0]) + 2)
        canvas = polygon_roi(shape, corners - low, [np.asarray(h, float).reshape(-1, 2) - low for h in holes])
        roi_raw = cv2.remap(canvas, self.ideal_u - np.float32(low[0]), self.ideal_v - np.float32(low[1]),
                            cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        return roi_raw, cv2.boundingRect(roi_raw)

    def reaches_inner_edge(self, x: int, y: int, w: int, h: int) -> bool:
        """Whether a box (in the window) touches an edge of the window that is not an edge of the frame: the
        ROI may go on beyond it."""
        height, width = self.ideal_u.shape
        return ((x == 0 and self.left > 0) or (y == 0 and self.top > 0)
                or (x + w == width and self.right < self.frame_shape[1])
                or (y + h == height and self.bottom < self.frame_shape[0]))


@dataclass
class Weights:
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
    # the targets' share of Af's relative variance (per target per px² of localisation, and the calliper's),
    # so that each frame's localisation stds scale it (scale.relative_area_std)
    scale_variances: tuple[np.ndarray, float]
    relative_offset_std: float  # relative std of Af from the object plane offset's uncertainty
    calibration: AreaSensitivity | None = None  # how the calibration's uncertainty moves the ROI's footprints
    _border: np.ndarray | None = None
    marker_edge_px: float | None = None  # the printed markers' edge width in this layout (px)
    marker_edge_found: bool = False
    roi_cut_share: float = 0.0  # of the ROI polygon where the idealized image has no raw pixel (Region.in_ideal)

    def border(self) -> np.ndarray:
        """The ROI's one-pixel border ring (its outline and the markers' holes), once per layout."""
        if self._border is None:
            inner = cv2.erode(self.roi, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0)
            self._border = cv2.subtract(self.roi, inner)  # the window's edge is the ROI's edge too
        return self._border

    def relative_calibration_std(self, mask: np.ndarray) -> float:
        """Af's relative std from the calibration's uncertainty over a mask's pixels (uint8 over the window):
        the object's, whose place in the image decides how a calibration's error moves its footprints."""
        if self.calibration is None:
            return 0.0
        u = self.calibration.raw_px[:, 0].astype(int) - self.window[1].start
        v = self.calibration.raw_px[:, 1].astype(int) - self.window[0].start
        within = (u >= 0) & (v >= 0) & (u < mask.shape[1]) & (v < mask.shape[0])
        inside = np.zeros(len(u), bool)
        inside[within] = mask[v[within], u[within]] > 0
        return self.calibration.relative_std(inside)

    def mask_area(self, mask: np.ndarray, factor: float) -> tuple[float, int]:
        """Af (m²) and number of a mask's pixels (uint8 over the window)."""
        counts = cv2.calcHist([self.levels], [0], mask, [WEIGHT_LEVELS], [0, WEIGHT_LEVELS]).ravel()
        return float(counts @ self.level_area * factor), int(counts.sum())

    def histogram(self, band: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """The 2-D histogram (band value x weight level) of a mask's pixels."""
        return cv2.calcHist([band, self.levels], [0, 1], mask, [256, WEIGHT_LEVELS],
                            [0, 256, 0, WEIGHT_LEVELS]).astype(np.float64)


@dataclass
class WeightsMemory:
    """What the weights stage carries from frame to frame: the pixel geometry (once per camera and frame size,
    kept across segments), the weights of the current target layout and the last frame's fit carried onto them."""
    geometry: PixelGeometry | None = None  # over the ROI's raw window, or the whole frame
    weights: Weights | None = None
    carried: tuple[PlaneScale, tuple[Weights, float, float]] | None = None  # the last fit's weights
    rebuilds: int = 0  # how often the weights were (re)built: once for a steady camera

    def forget_layout(self) -> None:
        self.weights = self.carried = None


class Weighting:
    """The weights of one camera's frames over the ROI (`Region`)."""

    def __init__(self, targets: TargetsSpec, view: IdealView, region: Region,
                 spread: CalibrationSpread | None = None):
        self.targets, self.view, self.region, self.spread = targets, view, region, spread

    def _pixel_geometry(self, height: int, width: int, box: tuple[int, int, int, int], memory: WeightsMemory
                        ) -> PixelGeometry:
        """The raw pixels' positions in the idealized image and the areas they cover, over a window holding
        the raw pixels of this ROI (`_raw_window`; the first ROI's window with a margin, the whole frame once
        a later ROI leaves it)."""
        geometry = memory.geometry
        if geometry is not None and geometry.frame_shape != (height, width):  # frames of another size (no camera)
            geometry = memory.geometry = None
        if geometry is not None and geometry.full:
            return geometry
        window = self._raw_window(height, width, box)
        if geometry is not None and geometry.covers(*window):
            return geometry
        # the first ROI's window; a second one (the ROI moves): the whole frame, once for all
        memory.geometry = PixelGeometry.build(self.view.camera, height, width, window if geometry is None else None)
        return memory.geometry

    def _raw_window(self, height: int, width: int, box: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
        """Rows and columns (top, bottom, left, right; ends excluded) of the raw frame whose pixels can land in
        the ROI: the raw image of the ROI's bounding box (widened by a pixel for the nearest-pixel lookup,
        its edges taken every half pixel) with GEOMETRY_MARGIN_PX around it, within the frame. The lens maps
        the box's inside inside its edges' image; `_build` checks that the ROI did not reach the window's edge."""
        x, y, w, h = box
        if w == 0 or h == 0 or self.view.camera is None:
            return 0, height, 0, width
        x0, y0, x1, y1 = x - 1.0, y - 1.0, x + w + 0.0, y + h + 0.0
        across = np.linspace(x0, x1, int(2 * (x1 - x0)) + 2)
        down = np.linspace(y0, y1, int(2 * (y1 - y0)) + 2)
        edges = np.vstack([np.column_stack([across, np.full_like(across, y0)]),
                           np.column_stack([across, np.full_like(across, y1)]),
                           np.column_stack([np.full_like(down, x0), down]),
                           np.column_stack([np.full_like(down, x1), down])])
        raw = self.view.to_raw(edges)
        if not np.all(np.isfinite(raw)):
            return 0, height, 0, width
        (u0, v0), (u1, v1) = raw.min(axis=0), raw.max(axis=0)
        margin = GEOMETRY_MARGIN_PX
        return (int(np.clip(np.floor(v0) - margin, 0, height)), int(np.clip(np.ceil(v1) + margin + 1, 0, height)),
                int(np.clip(np.floor(u0) - margin, 0, width)), int(np.clip(np.ceil(u1) + margin + 1, 0, width)))

    def _build(self, shape: tuple[int, ...], located: Located, memory: WeightsMemory) -> Weights:
        height, width = shape[:2]
        roi_ideal, polygon, holes, cut = self.region.in_ideal(shape, located)
        self.region.check_layout(located, polygon)
        corners = np.asarray(polygon, float).reshape(-1, 2)
        if beyond_image(corners, width, height) and self.view.camera is not None:
            (x0, y0), (x1, y1) = np.floor(corners.min(axis=0)), np.ceil(corners.max(axis=0))
            box, raw_roi = (int(x0), int(y0), int(x1 - x0) + 1, int(y1 - y0) + 1), lambda g: g.roi_of(polygon, holes)
        else:
            box, raw_roi = cv2.boundingRect(roi_ideal), lambda g: g.roi(roi_ideal)
        geometry = self._pixel_geometry(height, width, box, memory)
        roi_raw, (x, y, w, h) = raw_roi(geometry)
        if w > 0 and h > 0 and geometry.reaches_inner_edge(x, y, w, h):  # the window was too small: never here
            memory.geometry = geometry = PixelGeometry.build(self.view.camera, height, width)
            roi_raw, (x, y, w, h) = raw_roi(geometry)
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
        centre = centroid(roi_ideal)
        memory.rebuilds += 1
        offset_std = 0.0
        if self.targets.object_plane_offset_m is not None:
            offset_std = (located.scale.relative_area_change_per_metre_at(centre)
                          * self.targets.object_plane_offset_std_m)
        weights = Weights(window, roi, levels, level_area, float(np.max(np.abs(level_area[level] - exact) / exact)),
                          roi_ideal, located.scale, list(located.labels), np.array(located.pixels), polygon, centre,
                          located.scale.relative_area_variances_at(centre), offset_std, roi_cut_share=cut)
        last = memory.weights
        if (last is not None and last.labels == weights.labels and last.roi.shape == weights.roi.shape
                and np.max(np.abs(last.pixels - weights.pixels)) <= KEPT_WITHIN_PX):
            weights.calibration = last.calibration
        else:
            weights.calibration = self.calibration_sensitivity(weights)
        return weights

    def calibration_sensitivity(self, weights: Weights) -> AreaSensitivity | None:
        """How the calibration's uncertainty moves the footprints of the weights' ROI (None where it records
        none)."""
        if self.spread is None or self.view.camera is None:
            return None
        # a grid over the ROI: a 10 MP ROI's every pixel would cost 160 MB of coordinates for the same number
        stride = max(1, int(np.sqrt(cv2.countNonZero(weights.roi) / SAMPLE_PIXELS)))
        rows, cols = np.nonzero(weights.roi[::stride, ::stride])
        raw = np.column_stack([cols * stride + weights.window[1].start,
                               rows * stride + weights.window[0].start]).astype(float)
        return self.spread.sensitivity(self.view, raw, weights.scale)

    def weights_for(self, shape: tuple[int, ...], located: Located, memory: WeightsMemory
                    ) -> tuple[Weights, float, float]:
        """The weights for this frame's targets, the factor that carries them to this frame's scale and the
        relative error bound of that factor; rebuilt when the target layout changed, the targets moved, or
        the scale changed unevenly over the ROI by more than matters: 2e-4, or up to Af's relative scale std
        (the targets' localisation, 0.1 px by default), which the fit's own jitter under sensor noise reaches
        (4 DN: up to 8e-4 at 640x480; 3 DN in an MJPG video: 1.4e-3; a rebuild at most frames before). Weights
        built afresh carry that same frame's fit error, so carrying is no worse in kind; the carried error
        enters the scale std (in quadrature) and the bound."""
        weights = memory.weights
        if memory.carried is not None and memory.carried[0] is located.scale and memory.carried[1][0] is weights:
            return memory.carried[1]  # the same fit as the last frame's (no marker moved)
        if (weights is not None and weights.labels == located.labels
                and np.max(np.abs(weights.pixels - np.array(located.pixels))) <= ROI_TOLERANCE_PX):
            # a scale change is a ratio of two linear-fractional functions: extreme at the ROI's corners
            points = np.vstack([weights.centre, weights.corners])
            ratio = located.scale.pixel_area(points) / weights.scale.pixel_area(points)
            uneven = float(np.max(np.abs(ratio / ratio[0] - 1)))
            scale_std = relative_area_std(weights.scale_variances, located.scale.pixel_stds())
            if uneven <= max(SCALE_TOLERANCE, CARRY_SHARE * scale_std):
                memory.carried = located.scale, (weights, float(ratio[0]), uneven)
                return memory.carried[1]
        memory.weights = self._build(shape, located, memory)
        memory.carried = located.scale, (memory.weights, 1.0, 0.0)
        return memory.carried[1]
