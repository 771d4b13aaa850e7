"""Scale from targets in the object's plane: metres per pixel (two targets, the paper's calliper distance),
an affine map (three) or a plane homography (four or more, exact for a plane not quite perpendicular to the
camera), and the check that a targets file describes the markers detected.

The object plane offset is measured along the camera's viewing direction (the optical axis) and needs four or
more targets and a calibration: the targets' plane pose follows from them, Af is taken on the parallel plane.

No ROS here. All pixel coordinates handed to a PlaneScale are in the idealized image.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .targets import TargetsError


@dataclass
class PlaneScale:
    """Pixel (idealized image) -> targets' plane (metres), and the metric area of every pixel on the object's
    plane: the targets' plane itself, or the parallel plane `plane_offset_m` farther along the optical axis."""

    kind: str  # "distance", "affine" or "homography"
    pixels: np.ndarray  # (N, 2) the targets used
    planes: np.ndarray  # (N, 2)
    matrix: np.ndarray  # 3x3 pixel -> targets' plane (similarity, affine or homography)
    metres_per_pixel: float  # at the centre of the targets, on the object's plane
    distance_std_m: float = 0.0005
    pixel_std: float | np.ndarray = 0.1  # targets' localisation std per coordinate, px: one for all, or one each
    plane_offset_m: float | None = None  # None: the object lies in the targets' plane, no pose needed
    camera_matrix: np.ndarray | None = None  # the idealized image's pinhole K (needed for an offset)
    area_matrix: np.ndarray | None = None  # 3x3 pixel -> object's plane, when it is not the targets' plane

    @classmethod
    def fit(cls, pixels: np.ndarray, planes: np.ndarray, distance_std_m: float = 0.0005,
            pixel_std: float | np.ndarray = 0.1, plane_offset_m: float | None = None,
            camera_matrix: np.ndarray | None = None) -> PlaneScale:
        pixels = np.asarray(pixels, float).reshape(-1, 2)
        planes = np.asarray(planes, float).reshape(-1, 2)
        n = len(pixels)
        if n < 2:
            raise TargetsError(f"{n} target(s) found; at least 2 are needed for a scale")
        if n == 2:
            pixel_length = np.linalg.norm(pixels[1] - pixels[0])
            plane_length = np.linalg.norm(planes[1] - planes[0])
            if pixel_length < 1.0:
                raise TargetsError("the two targets are less than a pixel apart")
            s = plane_length / pixel_length
            matrix = np.array([[s, 0, 0], [0, s, 0], [0, 0, 1.0]])  # area only: orientation does not matter
            kind = "distance"
        elif n == 3:
            matrix = np.vstack([cv2.getAffineTransform(pixels.astype(np.float32), planes.astype(np.float32)),
                                [0, 0, 1]]).astype(float)
            kind = "affine"
        else:
            matrix, _ = cv2.findHomography(pixels, planes, 0)
            if matrix is None:
                raise TargetsError("the targets are degenerate (collinear?); no homography")
            kind = "homography"
        if kind != "distance" and abs(np.linalg.det(matrix[:2, :2])) < 1e-18:
            raise TargetsError("the targets are collinear; they do not span the plane")
        scale = cls(kind, pixels, planes, matrix, 0.0, distance_std_m, pixel_std, plane_offset_m, camera_matrix)
        if plane_offset_m is not None:
            scale.area_matrix = _offset_plane_matrix(matrix, kind, camera_matrix, plane_offset_m)
        scale.metres_per_pixel = float(np.sqrt(scale.pixel_area(pixels.mean(axis=0, keepdims=True))[0]))
        return scale

    def pixel_area(self, uv: np.ndarray) -> np.ndarray:
        """Metric area (m²) of the unit pixel at each (u, v): |det| of the map's Jacobian there."""
        uv = np.asarray(uv, float).reshape(-1, 2)
        H = self.matrix if self.area_matrix is None else self.area_matrix
        w = H[2, 0] * uv[:, 0] + H[2, 1] * uv[:, 1] + H[2, 2]
        return np.abs(np.linalg.det(H)) / np.abs(w) ** 3

    def plane_to_pixels(self, planes: np.ndarray) -> np.ndarray:
        """Plane (x, y) metres -> idealized-image pixels (not for the 'distance' kind: it has no orientation)."""
        planes = np.asarray(planes, float).reshape(-1, 1, 2)
        return cv2.perspectiveTransform(planes, np.linalg.inv(self.matrix)).reshape(-1, 2)

    def area(self, uv: np.ndarray) -> float:
        """Σ of the metric areas of the given pixel centres."""
        return float(self.pixel_area(uv).sum()) if len(uv) else 0.0

    def pixel_stds(self) -> np.ndarray:
        """Each target's localisation std per coordinate (N,), px."""
        return np.broadcast_to(np.asarray(self.pixel_std, float), (len(self.pixels),)).copy()

    def relative_area_variances_at(self, uv: np.ndarray) -> tuple[np.ndarray, float]:
        """What the targets give the relative variance of the metric area of a pixel at `uv` (idealized image),
        propagated to first order through the fit by central differences: each target's share per px² of its
        localisation variance (N,), and the calliper's (distance_std_m / sqrt(2) per plane coordinate)."""
        uv = np.asarray(uv, float).reshape(1, 2)
        base = self.pixel_area(uv)[0]
        per_target = np.zeros(len(self.pixels))
        calliper = 0.0
        for name, sigma, step in (("pixels", 1.0, 1e-3), ("planes", self.distance_std_m / np.sqrt(2), 1e-6)):
            if sigma == 0:
                continue
            values = getattr(self, name)
            for index in np.ndindex(values.shape):
                shifted = []
                for sign in (1, -1):
                    moved = values.copy()
                    moved[index] += sign * step
                    pixels, planes = (moved, self.planes) if name == "pixels" else (self.pixels, moved)
                    shifted.append(PlaneScale.fit(pixels, planes, plane_offset_m=self.plane_offset_m,
                                                  camera_matrix=self.camera_matrix).pixel_area(uv)[0])
                share = ((shifted[0] - shifted[1]) / (2 * step) * sigma / base) ** 2
                if name == "pixels":
                    per_target[index[0]] += share
                else:
                    calliper += share
        return per_target, float(calliper)

    def relative_area_std_at(self, uv: np.ndarray) -> float:
        """Relative standard deviation of the metric area of a pixel at `uv` (idealized image) from the targets'
        localisation (`pixel_std` per coordinate) and the calliper."""
        return relative_area_std(self.relative_area_variances_at(uv), self.pixel_stds())

    def relative_area_change_per_metre_at(self, uv: np.ndarray) -> float:
        """d ln(pixel area)/d(plane offset) at `uv`, 1/m: how an error in the object's plane offset moves Af
        (about 2 / distance)."""
        if self.plane_offset_m is None:
            return 0.0
        step = 1e-4
        areas = [PlaneScale.fit(self.pixels, self.planes, plane_offset_m=self.plane_offset_m + sign * step,
                                camera_matrix=self.camera_matrix).pixel_area(uv)[0] for sign in (1, -1)]
        return float(abs(np.log(areas[0] / areas[1])) / (2 * step))


def relative_area_std(variances: tuple[np.ndarray, float], pixel_stds: np.ndarray) -> float:
    """Af's relative std from the targets, given `PlaneScale.relative_area_variances_at` and each target's
    localisation std."""
    per_target, calliper = variances
    return float(np.sqrt(per_target @ np.square(pixel_stds) + calliper))


SQUARE_TOLERANCE = 0.08  # a marker's sides and diagonals on the plane may differ this much (relative) from a square
SIDE_TOLERANCE = 0.05  # each marker's side on the plane against `marker_side_m`
CORNER_STD_PX = 0.25  # ArUco corners on real frames: what the tolerances must allow on a small marker


def marker_layout_problem(scale: PlaneScale, corners: dict[int, np.ndarray], marker_side_m: float | None,
                          roi_pixels: np.ndarray | None = None) -> str | None:
    """Why the targets file cannot describe what was detected, or None. The scale's map must send every
    marker's own four corners (idealized px) to a square of one handedness (the side `marker_side_m` when it
    is given) and keep the targets and the ROI on one side of its line at infinity. Permuted marker ids or a
    mistyped coordinate fold or stretch the map (Af off by orders of magnitude) and fail this."""
    if scale.kind == "distance" or not corners:
        return None
    H = scale.matrix
    pixels = np.vstack([scale.pixels, *corners.values(), *([] if roi_pixels is None else [roi_pixels])])
    w = H[2, 0] * pixels[:, 0] + H[2, 1] * pixels[:, 1] + H[2, 2]
    if not (np.all(w > 0) or np.all(w < 0)):
        return ("the targets' positions fold the plane (its horizon crosses the targets): marker ids or "
                "coordinates in the targets file do not match the board (permuted or mistyped?)")
    handedness = []
    for marker_id, marker in corners.items():
        marker = np.asarray(marker, float).reshape(4, 2)
        plane = cv2.perspectiveTransform(marker.reshape(-1, 1, 2), H).reshape(4, 2)
        edges = plane[[1, 2, 3, 0]] - plane
        lengths = np.hypot(*edges.T)
        diagonals = np.hypot(*(plane[2:] - plane[:2]).T) / np.sqrt(2)
        mean = lengths.mean()
        side_px = float(np.hypot(*(marker[[1, 2, 3, 0]] - marker).T).mean())
        allowed = max(SQUARE_TOLERANCE, 6 * CORNER_STD_PX / max(side_px, 1.0))
        spread = float(np.max(np.abs(np.concatenate([lengths, diagonals]) / mean - 1)))
        if spread > allowed:
            return (f"marker {marker_id} maps to a {lengths.min() * 1000:.3g}–{lengths.max() * 1000:.3g} mm "
                    f"quadrilateral, not a square (off by {spread:.0%}): marker ids or coordinates in the "
                    f"targets file do not match the board (permuted or mistyped?)"
                    + (", or the plane is tilted more than three targets' affine scale can follow (a fourth "
                       "target gives a homography)" if scale.kind == "affine" else ""))
        handedness.append(np.sign(edges[0, 0] * edges[1, 1] - edges[0, 1] * edges[1, 0]))
        allowed = max(SIDE_TOLERANCE, 4 * CORNER_STD_PX / max(side_px, 1.0))
        if marker_side_m is not None and abs(mean / marker_side_m - 1) > allowed:
            return (f"marker {marker_id} measures {mean * 1000:.4g} mm a side on the targets' plane where the "
                    f"targets file gives marker_side_m = {marker_side_m * 1000:.4g} mm: a coordinate or the "
                    f"side is mistyped")
    if len(set(handedness)) > 1:
        return ("the markers map mirrored against each other: marker ids or coordinates in the targets file do "
                "not match the board (permuted?)")
    return None


def _offset_plane_matrix(matrix: np.ndarray, kind: str, camera_matrix: np.ndarray | None,
                         offset: float) -> np.ndarray:
    """Pixel -> object plane for the plane parallel to the targets' one, `offset` metres farther along the
    optical axis. The targets' homography G = H^-1 (plane -> pixel) is K [r1 r2 t] / lambda; the object's
    plane has the same axes and origin t + offset * e_z, so its G' adds offset * lambda^-1 * e_z to K^-1 G's
    third column."""
    if kind != "homography":
        raise TargetsError(f"an object plane offset needs 4 or more targets found (their plane's pose); "
                           f"this frame's scale is {kind}")
    if camera_matrix is None:
        raise TargetsError("an object plane offset needs a calibration (the camera's pinhole)")
    columns = np.linalg.inv(camera_matrix) @ np.linalg.inv(matrix)  # [r1 r2 t] / lambda
    norm = np.sqrt(np.linalg.norm(columns[:, 0]) * np.linalg.norm(columns[:, 1]))  # 1 / lambda
    if columns[2, 2] < 0:  # the plane in front of the camera: t_z > 0
        columns = -columns
    shifted = columns.copy()
    shifted[2, 2] += offset * norm
    if shifted[2, 2] <= 0:
        raise TargetsError(f"the object plane offset {offset:g} m puts the object behind the camera")
    return np.linalg.inv(camera_matrix @ shifted)
