"""How well a frame's markers were located, read from the markers themselves: each printed marker is a square
on the targets' plane, so its four corners, mapped onto the plane by the scale's fit of the targets, must form
a square there. What they miss it by is the corners' localisation error (blur, noise, a dim print, JPEG),
and a marker's centre, the intersection of its diagonals, errs by that over sqrt(2) per coordinate.

Measured per frame, it replaces the targets file's localisation std where it is larger: on a real webcam's
video of printed markers the centres erred 0.34 px (rms per coordinate) against the 0.1 px a targets file
assumes, and this read 0.29 px. It reads about 0.8 of the error (0.76-0.87 on renders and that video): a
shift of a marker's four corners alike leaves its square whole.

No ROS here.
"""

from __future__ import annotations

import cv2
import numpy as np

# a square's corners about its centre, as complex numbers in ArUco's order (clockwise in the image)
_UNIT_SQUARE = np.array([-1 - 1j, 1 - 1j, 1 + 1j, -1 + 1j]) / 2
_NORM = float(np.sum(np.abs(_UNIT_SQUARE) ** 2))
# each marker's 8 corner coordinates less its rotation and size on the plane (its centre is the fit's)
DEGREES_OF_FREEDOM_PER_MARKER = 6


def marker_centre_std(ideal_corners: np.ndarray, planes: np.ndarray, to_plane: np.ndarray) -> float | None:
    """The markers' centre localisation std per coordinate (idealized px), from how far each marker's corners
    (N, 4, 2; idealized image) are from a square about its plane position (N, 2; metres) once mapped onto the
    plane by `to_plane` (3x3, idealized px -> metres: the scale's fit of the targets' centres, affine or a
    homography). None without markers."""
    corners = np.asarray(ideal_corners, float).reshape(-1, 4, 2)
    planes = np.asarray(planes, float).reshape(-1, 2)
    if not len(corners):
        return None
    on_plane = cv2.perspectiveTransform(corners.reshape(-1, 1, 2), to_plane).reshape(-1, 4, 2) - planes[:, None]
    offsets = on_plane[..., 0] + 1j * on_plane[..., 1]  # (N, 4)
    # each square's size and rotation fitted; either handedness (the plane's y may point up or down)
    missed = np.min([np.sum(np.abs(offsets - (offsets @ unit.conj() / _NORM)[:, None] * unit) ** 2, axis=1)
                     for unit in (_UNIT_SQUARE, np.conj(_UNIT_SQUARE))], axis=0)
    squared_px = float(missed @ _pixels_per_square_metre(np.linalg.inv(to_plane), planes))
    corner_std = np.sqrt(squared_px / (DEGREES_OF_FREEDOM_PER_MARKER * len(corners)))
    return float(corner_std / np.sqrt(2))


def _pixels_per_square_metre(to_pixels: np.ndarray, planes: np.ndarray, step: float = 1e-4) -> np.ndarray:
    """The plane -> image map's area ratio at plane points (N, 2): px² per m²."""
    steps = np.array([[0.0, 0.0], [step, 0.0], [0.0, step]])
    points = (planes[:, None] + steps).reshape(-1, 1, 2)
    p0, p1, p2 = np.moveaxis(cv2.perspectiveTransform(points, to_pixels).reshape(-1, 3, 2), 1, 0)
    (ax, ay), (bx, by) = (p1 - p0).T, (p2 - p0).T
    return np.abs(ax * by - ay * bx) / step**2
