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

    def in_ideal(self, shape: tuple[int, ...], located: Located) -> tuple[np.ndarray, np.ndarray, float]:
        """The ROI (uint8 mask over an idealized image of `shape`), its polygon, and the share of the polygon
        that lies where the idealized image has no raw pixel (beyond the frame, or past a lens model's fold)."""
        polygon, holes = self.polygon(located)
        if self.user_polygon is not None:  # the user's: said to lie outside the frame, not found empty
            check_roi_in_image(polygon, shape[1], shape[0])
        roi = polygon_roi(shape, polygon, holes)
        corners = np.asarray(polygon, float).reshape(-1, 2)
        area = polygon_area(corners)
        kept = min(roi_area_inside(corners, shape[1], shape[0]) / area, 1.0) if area > 0 else 1.0
        valid = self.view.valid_mask()
        if valid is not None:
            whole = polygon_roi(shape[:2], corners)
            roi &= valid  # never count the black border the remap leaves
            kept *= cv2.countNonZero(whole & valid) / max(cv2.countNonZero(whole), 1)
        return roi, polygon, 1.0 - kept

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


def centroid(mask: np.ndarray) -> np.ndarray:
    moments = cv2.moments(mask, binaryImage=True)
    return np.array([moments["m10"], moments["m01"]]) / moments["m00"]
