"""The region of interest of a frame, in the idealized image: the user's polygon, or by default the frame of
all listed targets without the marker squares; and the check that the targets file can describe the markers
found. It exists apart from locating because the ROI is what the weights and the reference path measure
over, whoever found the targets. Takes a `Located`, gives the ROI (uint8 mask) and its polygon. Carries
nothing from frame to frame.

No ROS here.
"""

from __future__ import annotations

import cv2
import numpy as np

from .classify import ClassifyError, check_polygon, check_roi_in_image, polygon_area, polygon_roi, roi_area_inside
from .idealize import IdealView
from .locate import MARKER_EXCLUSION, Located
from .scale import marker_layout_problem
from .targets import TargetsError, TargetsSpec

UNCOVERED_SAMPLES = 4096  # points of a ROI reaching past the idealized image, to find the share no pixel covers
MAX_PLANE_DISTANCE_M = 20.0  # no flume or river measurement sees its targets from farther: a unit slip


class Region:
    """The ROI of one camera's frames: `polygon` (idealized px) or None for the default inside the targets."""

    def __init__(self, targets: TargetsSpec, view: IdealView, polygon: np.ndarray | None):
        self.targets, self.view = targets, view
        # refused now, not at every frame: without a calibration the image size is known only from frames
        self.user_polygon = (None if polygon is None else check_polygon(polygon) if view.camera is None
                             else check_roi_in_image(polygon, *view.camera.image_size))

    def polygon(self, located: Located) -> tuple[np.ndarray, list[np.ndarray]]:
        """The ROI polygon and holes in the idealized image: the user's, or by default the frame of ALL listed
        targets (a missing one placed by the others' fit, for the ROI only) without the marker squares."""
        if self.user_polygon is not None:
            return self.user_polygon, []
        scale = located.scale
        if scale.kind == "distance":
            raise ClassifyError("two targets do not enclose a region; give the region of interest (--roi)")
        holes = list(located.holes)
        for marker_id in located.missing:
            centre = scale.plane_to_pixels(self.targets.markers[marker_id][None])[0]
            holes.append(centre + MARKER_EXCLUSION * np.mean(located.offsets, axis=0))
        hull = cv2.convexHull(scale.plane_to_pixels(self.targets.all_planes()).astype(np.float32)).reshape(-1, 2)
        return hull.astype(float), holes

    def in_ideal(self, shape: tuple[int, ...], located: Located
                 ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], float]:
        """The ROI (uint8 mask over an idealized image of `shape`), its polygon and holes, and the share of the
        polygon that no raw pixel covers (beyond the frame, or past a lens model's fold). A polygon reaching
        past the idealized image's edges may still hold raw pixels there (a barrel lens's corners idealize
        beyond them): the weights take those from the polygon itself (`beyond_image`)."""
        polygon, holes = self.polygon(located)
        if self.user_polygon is not None:  # the user's: said to lie outside the frame, not found empty
            check_roi_in_image(polygon, shape[1], shape[0])
        roi = polygon_roi(shape, polygon, holes)
        corners = np.asarray(polygon, float).reshape(-1, 2)
        valid = self.view.valid_mask()
        if valid is not None:
            roi &= valid  # never count the black border the remap leaves
        if beyond_image(corners, shape[1], shape[0]) and self.view.camera is not None:
            return roi, polygon, holes, self._uncovered_share(corners, shape)
        area = polygon_area(corners)
        kept = min(roi_area_inside(corners, shape[1], shape[0]) / area, 1.0) if area > 0 else 1.0
        if valid is not None:
            whole = polygon_roi(shape[:2], corners)
            kept *= cv2.countNonZero(whole & valid) / max(cv2.countNonZero(whole), 1)
        return roi, polygon, holes, 1.0 - kept

    def _uncovered_share(self, corners: np.ndarray, shape: tuple[int, ...]) -> float:
        """The share of the polygon's area (idealized px) that no raw pixel of a frame of `shape` covers, from
        about UNCOVERED_SAMPLES points inside it: each taken back to the raw frame, which must hold it, within
        the lens model's reach, and take it back to where it was."""
        (x0, y0), (x1, y1) = corners.min(axis=0), corners.max(axis=0)
        step = max(np.sqrt((x1 - x0) * (y1 - y0) / UNCOVERED_SAMPLES), 0.25)
        xs, ys = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
        points = np.column_stack([xs.ravel(), ys.ravel()])
        points = points[inside_polygon(points, corners)]
        if not len(points):
            return 0.0
        raw = self.view.to_raw(points)
        height, width = shape[:2]
        with np.errstate(invalid="ignore"):
            covered = (np.all(np.isfinite(raw), axis=1) & (raw[:, 0] >= -0.5) & (raw[:, 1] >= -0.5)
                       & (raw[:, 0] <= width - 0.5) & (raw[:, 1] <= height - 0.5))
        covered[covered] &= self.view.camera.within_reach(raw[covered])
        covered[covered] &= np.hypot(*(self.view.to_ideal(raw[covered]) - points[covered]).T) < 0.5
        return float(1.0 - covered.mean())

    def check_layout(self, located: Located, roi_polygon: np.ndarray) -> None:
        """TargetsError when the targets file cannot describe the detected markers (`marker_layout_problem`)."""
        corners = {int(label.split()[1]): pixel + offset
                   for label, pixel, offset in zip(located.labels, located.pixels, located.offsets, strict=False)
                   if label.startswith("marker ")}
        problem = marker_layout_problem(located.scale, corners, self.targets.marker_side_m, roi_polygon)
        if problem:
            raise TargetsError(problem)
        if self.view.calibrated and located.scale.kind != "distance":  # the layout holds: its unit may not
            distance = located.scale.metres_per_pixel * float(self.view.ideal_matrix[0, 0])
            if not distance <= MAX_PLANE_DISTANCE_M:
                raise TargetsError(
                    f"the targets put their plane {distance:.1f} m from the camera "
                    f"({located.scale.metres_per_pixel:.4g} m per idealized pixel at a focal length of "
                    f"{self.view.ideal_matrix[0, 0]:.0f} px): are the targets file's coordinates in metres? "
                    "(centimetres read as metres give 100x the distance, inches 39x)")


def beyond_image(corners: np.ndarray, width: int, height: int) -> bool:
    """Whether a polygon (N, 2 px) reaches past the edges of a width x height image's pixels."""
    return bool(corners.min() < -0.5 or corners[:, 0].max() > width - 0.5 or corners[:, 1].max() > height - 0.5)


def inside_polygon(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Which points (N, 2) lie inside a simple polygon (M, 2): the even-odd rule, one ray along +x."""
    x, y = points[:, 0:1], points[:, 1:2]
    ax, ay = corners[:, 0], corners[:, 1]
    bx, by = np.roll(ax, -1), np.roll(ay, -1)
    straddles = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing = ax + (y - ay) * (bx - ax) / (by - ay)
    return np.count_nonzero(straddles & (x < crossing), axis=1) % 2 == 1


def centroid(mask: np.ndarray) -> np.ndarray:
    moments = cv2.moments(mask, binaryImage=True)
    return np.array([moments["m10"], moments["m01"]]) / moments["m00"]
