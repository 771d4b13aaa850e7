"""Scale from targets in the object's plane: metres per pixel (two targets, the paper's calliper distance),
an affine map (three) or a plane homography (four or more, exact for a plane not quite perpendicular to the
camera). Targets are ArUco markers (their centre) or points picked by hand, listed in a targets file:

    dictionary: DICT_4X4_50
    markers:            # marker id: centre [x, y] in the object plane, metres
      0: [-0.22, -0.16]
      1: [0.22, -0.16]
    points:             # optional hand-picked targets: raw-frame pixel and plane position
      - {pixel: [u, v], plane: [x, y]}
    distance_std_m: 0.0005      # calliper uncertainty of target distances (default 0.5 mm)
    pixel_std: 0.1              # localisation uncertainty of a target centre, px (default 0.1)
    object_plane_offset_m: 0.035     # optional: object's plane this far behind the targets' (+ = farther)
    object_plane_offset_std_m: 0.002 # its uncertainty (default 2 mm when an offset is given)

The offset is measured along the camera's viewing direction (the optical axis) and needs four or more
targets and a calibration: the targets' plane pose follows from them, Af is taken on the parallel plane.

No ROS here. All pixel coordinates handed to a PlaneScale are in the idealized image.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np
import yaml

from .strict_yaml import StrictYamlError, load_text, read_text


class TargetsError(ValueError):
    """A targets file or a frame's targets that cannot give a scale; the message says why."""


def _pair(value, what: str) -> np.ndarray:
    try:
        pair = np.array(value, dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise TargetsError(f"{what} must be two numbers, got {value!r}") from exc
    if pair.size != 2 or not np.all(np.isfinite(pair)):
        raise TargetsError(f"{what} must be two finite numbers, got {value!r}")
    return pair


@dataclass
class TargetsSpec:
    dictionary: str = ""
    markers: dict[int, np.ndarray] = field(default_factory=dict)  # id -> plane (x, y), metres
    points: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # (raw pixel, plane)
    distance_std_m: float = 0.0005
    pixel_std: float = 0.1
    object_plane_offset_m: float | None = None  # None: the object lies in the targets' plane (the paper's set-up)
    object_plane_offset_std_m: float = 0.002
    marker_side_m: float | None = None  # the black square's side: checks the layout's scale against each marker

    @classmethod
    def load(cls, path: str | Path) -> TargetsSpec:
        path = Path(path)
        try:
            content = load_text(read_text(path))
        except StrictYamlError as exc:
            raise TargetsError(f"{path}: {exc}") from exc
        except FileNotFoundError as exc:
            raise TargetsError(f"{path}: no such targets file") from exc
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise TargetsError(f"{path}: not a readable YAML targets file ({exc.__class__.__name__})") from exc
        try:
            return cls.from_dict(content)
        except TargetsError as exc:
            raise TargetsError(f"{path}: {exc}") from exc

    @classmethod
    def from_dict(cls, content) -> TargetsSpec:
        if not isinstance(content, dict):
            raise TargetsError("expected a mapping with 'markers' and/or 'points'")
        spec = cls(dictionary=str(content.get("dictionary", "")).upper())
        markers = content.get("markers") or {}
        if not isinstance(markers, dict):
            raise TargetsError("'markers' must map marker ids to [x, y]")
        for marker_id, plane in markers.items():
            if not isinstance(marker_id, int) or isinstance(marker_id, bool) or marker_id < 0:
                raise TargetsError(f"marker id {marker_id!r} is not a non-negative integer")
            spec.markers[marker_id] = _pair(plane, f"marker {marker_id}")
        if spec.markers and not (spec.dictionary.startswith("DICT_") and hasattr(cv2.aruco, spec.dictionary)):
            raise TargetsError(f"unknown or missing ArUco dictionary {content.get('dictionary')!r}")
        for k, entry in enumerate(content.get("points") or []):
            if not isinstance(entry, dict) or "pixel" not in entry or "plane" not in entry:
                raise TargetsError(f"point {k} needs 'pixel' and 'plane'")
            spec.points.append((_pair(entry["pixel"], f"point {k} pixel"), _pair(entry["plane"], f"point {k} plane")))
        if "marker_side_m" in content:
            side = content["marker_side_m"]
            if not _is_number(side) or not 0 < side <= 10:
                raise TargetsError(f"'marker_side_m' must be a side in metres, got {side!r}")
            spec.marker_side_m = float(side)
        for key in ("distance_std_m", "pixel_std", "object_plane_offset_std_m"):
            if key in content:
                value = content[key]
                if not _is_number(value) or value < 0:
                    raise TargetsError(f"'{key}' must be a non-negative number, got {value!r}")
                setattr(spec, key, float(value))
        planes = [tuple(p) for p in spec.markers.values()] + [tuple(p) for _, p in spec.points]
        if len(planes) < 2:
            raise TargetsError(f"{len(planes)} target(s) given; at least 2 are needed for a scale")
        if len(set(planes)) != len(planes):
            raise TargetsError("two targets share the same plane position")
        if "object_plane_offset_m" in content:
            offset = content["object_plane_offset_m"]
            if not _is_number(offset) or abs(offset) > 10:
                raise TargetsError(f"'object_plane_offset_m' must be a distance in metres, got {offset!r}")
            if len(planes) < 4:
                raise TargetsError(f"an object plane offset needs 4 or more targets (their plane's pose); this file "
                                   f"lists {len(planes)}: put the targets in the object's plane, or add targets")
            spec.object_plane_offset_m = float(offset)
        elif "object_plane_offset_std_m" in content:
            raise TargetsError("'object_plane_offset_std_m' given without 'object_plane_offset_m'")
        return spec

    def all_planes(self) -> np.ndarray:
        """Plane positions of every listed target, markers then points (N, 2)."""
        return np.array([*self.markers.values(), *(plane for _, plane in self.points)], float).reshape(-1, 2)


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and bool(np.isfinite(value))


@dataclass(frozen=True)
class DetectedMarker:
    centre: np.ndarray  # (2,) px, the projective centre (intersection of the diagonals)
    corners: np.ndarray  # (4, 2) px


def marker_centre(corners: np.ndarray) -> np.ndarray:
    """Intersection of the marker's diagonals: the image of its centre under any perspective."""
    p0, p1, p2, p3 = np.asarray(corners, float).reshape(4, 2)
    d1, d2 = p2 - p0, p3 - p1
    denom = d1[0] * d2[1] - d1[1] * d2[0]
    if abs(denom) < 1e-12:
        return (p0 + p1 + p2 + p3) / 4
    s = ((p1[0] - p0[0]) * d2[1] - (p1[1] - p0[1]) * d2[0]) / denom
    return p0 + s * d1


CORNER_ACCURACY_PX = 0.01  # corners refined until they move less than this (OpenCV's default stops at 0.1 px)
CORNER_ITERATIONS = 30  # OpenCV's default
CORNER_WINDOW_PX = 5  # largest refinement half-window, OpenCV's default (smaller for small markers: 0.3 cell)
RETRACK_STARTS_PX = [(0.5, 0.5), (0.5, -0.5), (-0.5, 0.5), (-0.5, -0.5)]  # shifts of every corner's start
RETRACK_AGREEMENT_PX = 0.05  # re-tracked corners from every start must agree this closely
CODE_CELL_PX = 8  # a marker's cells are sampled at this size to check its code
CODE_CONTRAST = 5.0  # grey levels that must separate every black cell from every white cell of a re-tracked marker


@lru_cache(maxsize=8)
def _dictionary(name: str) -> cv2.aruco.Dictionary:
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


@lru_cache(maxsize=8)
def _detector(dictionary: str) -> cv2.aruco.ArucoDetector:
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    # refined to a fixed point, so that re-tracking from last frame's corners lands where detection would
    parameters.cornerRefinementMinAccuracy = CORNER_ACCURACY_PX
    parameters.cornerRefinementMaxIterations = CORNER_ITERATIONS
    parameters.cornerRefinementWinSize = CORNER_WINDOW_PX
    return cv2.aruco.ArucoDetector(_dictionary(dictionary), parameters)


@lru_cache(maxsize=256)
def _code_cells(dictionary: str, marker_id: int) -> tuple[np.ndarray, np.ndarray]:
    """Which cells of the marker (with its one-cell black border) are black, and which white."""
    cells = _dictionary(dictionary).markerSize + 2
    image = cv2.aruco.generateImageMarker(_dictionary(dictionary), marker_id, cells)
    return image == 0, image == 255


def detect_markers(image: np.ndarray, dictionary: str, offset: tuple[int, int] = (0, 0)) -> dict[int, DetectedMarker]:
    """ArUco markers in an image (or a window of one: `offset` is the window's top-left in the frame)."""
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    corners, ids, _ = _detector(dictionary).detectMarkers(grey)
    found: dict[int, DetectedMarker] = {}
    if ids is None:
        return found
    for marker_corners, marker_id in zip(corners, ids.ravel(), strict=True):
        c = marker_corners.reshape(4, 2).astype(np.float64) + offset
        found[int(marker_id)] = DetectedMarker(marker_centre(c), c)
    return found


def _refinement_window(corners: np.ndarray, dictionary: str) -> int:
    """The half-size of the corner refinement window ArUco uses for this marker: 0.3 cell, 1 to 5 px."""
    sides = corners - corners[[1, 2, 3, 0]]
    cell = float(np.sqrt((sides * sides).sum(axis=1)).mean()) / (_dictionary(dictionary).markerSize + 2)
    return min(CORNER_WINDOW_PX, max(1, round(0.3 * cell)))


def retrack_marker(frame: np.ndarray, dictionary: str, marker_id: int,
                   previous: DetectedMarker) -> DetectedMarker | None:
    """The marker found again from where it was in the previous frame, without a detection: its corners refined
    to subpixel from their previous places as detection refines them (same window rule, same criteria), then
    accepted only if none moved further than the refinement window (a farther move could have caught another
    corner), refinements from four nearby starts agree, and the marker's code still reads between the new
    corners (an occluded or vanished marker's does not). None: detect it instead. ArUco sizes the window from
    the unrefined contour, this from the refined corners: at a size boundary the two windows can differ by a
    pixel, and the corners by a few tenths of one."""
    half = _refinement_window(previous.corners, dictionary)
    height, width = frame.shape[:2]
    margin = 2 * half + 2
    (x0, y0), (x1, y1) = previous.corners.min(axis=0), previous.corners.max(axis=0)
    left, top = int(x0) - margin, int(y0) - margin
    right, bottom = int(np.ceil(x1)) + margin, int(np.ceil(y1)) + margin
    if left < 0 or top < 0 or right > width or bottom > height:
        return None
    patch = frame[top:bottom, left:right]
    grey = patch if patch.ndim == 2 else cv2.cvtColor(patch, cv2.COLOR_BGR2GRAY)
    start = (previous.corners - (left, top)).astype(np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, CORNER_ITERATIONS, CORNER_ACCURACY_PX)
    # refined from last frame's corners and from four starts around them: where they do not all meet, the corner
    # is ill-conditioned (blur, noise) and the result would depend on the start; detection decides then
    starts = start[None] + np.vstack([[[0.0, 0.0]], RETRACK_STARTS_PX])[:, None].astype(np.float32)
    refined = cv2.cornerSubPix(grey, starts.reshape(-1, 1, 2), (half, half), (-1, -1), criteria).reshape(-1, 4, 2)
    corners = refined[0]
    if (not np.all(np.isfinite(refined)) or np.max(np.abs(corners - start)) > half
            or np.max(np.abs(refined[1:] - corners)) > RETRACK_AGREEMENT_PX):
        return None
    black, white = _code_cells(dictionary, marker_id)
    cells = len(black)
    side = cells * CODE_CELL_PX
    square = np.array([[0, 0], [side, 0], [side, side], [0, side]], np.float32)
    canonical = cv2.warpPerspective(grey, cv2.getPerspectiveTransform(corners, square), (side, side),
                                    flags=cv2.INTER_LINEAR)
    inner = slice(CODE_CELL_PX // 4, CODE_CELL_PX - CODE_CELL_PX // 4)  # cell centres: edges blur into neighbours
    means = canonical.reshape(cells, CODE_CELL_PX, cells, CODE_CELL_PX)[:, inner, :, inner].mean(axis=(1, 3))
    if means[white].min() - means[black].max() < CODE_CONTRAST:
        return None
    corners = corners.astype(np.float64) + np.array([left, top])
    return DetectedMarker(marker_centre(corners), corners)


def _detect_in_box(frame: np.ndarray, dictionary: str, marker_id: int,
                   box: tuple[float, float, float, float]) -> DetectedMarker | None:
    """One marker detected inside a box (x0, y0, x1, y1) of the frame, clipped to it."""
    height, width = frame.shape[:2]
    left, top = max(int(box[0]), 0), max(int(box[1]), 0)
    right, bottom = min(int(np.ceil(box[2])), width), min(int(np.ceil(box[3])), height)
    if right - left < 8 or bottom - top < 8:
        return None
    return detect_markers(frame[top:bottom, left:right], dictionary, (left, top)).get(marker_id)


def track_markers(frame: np.ndarray, dictionary: str, previous: dict[int, DetectedMarker],
                  wanted: set[int] | None = None,
                  guesses: dict[int, tuple[np.ndarray, float]] | None = None) -> dict[int, DetectedMarker]:
    """Markers of a video frame. Each one found in the previous frame is first re-tracked (`retrack_marker`);
    if that fails, detected in a window around its last place (a wider window if the detector needs more
    context). Lost there while all the others were re-tracked in place, it is covered and missing from this
    frame. A `wanted` id missing from the previous frame is looked for in a window around its guessed place
    (`guesses`: raw centre and half-size in px, from the other targets), so that an uncovered marker comes
    back without a search of the whole frame. The whole frame is searched when there is nothing to track,
    when a marker is lost while others moved (the camera moved), or when a missing wanted id has no guess.
    Only wanted ids are kept."""
    keep = None if wanted is None else set(wanted)
    follow = [marker_id for marker_id in sorted(previous) if keep is None or marker_id in keep]
    hidden = sorted(set() if keep is None else keep - set(previous))
    guesses = guesses or {}
    if follow and all(marker_id in guesses for marker_id in hidden):
        found, moved = {}, False
        for marker_id in follow:
            marker = previous[marker_id]
            again = retrack_marker(frame, dictionary, marker_id, marker)
            if again is None:
                (x0, y0), (x1, y1) = marker.corners.min(axis=0), marker.corners.max(axis=0)
                side = max(x1 - x0, y1 - y0)
                for margin in (max(0.5 * side, 8.0), 1.5 * side):  # wider when the detector needs context
                    again = _detect_in_box(frame, dictionary, marker_id,
                                           (x0 - margin, y0 - margin, x1 + margin, y1 + margin))
                    if again is not None:
                        moved = True
                        break
            if again is not None:
                found[marker_id] = again
        # a marker lost while every other one stayed put is covered: seek it later where the others place it;
        # lost while others moved, the camera moved: search the whole frame now
        if found and (len(found) == len(follow) or not moved):
            for marker_id in hidden:
                (u, v), half = guesses[marker_id]
                again = _detect_in_box(frame, dictionary, marker_id, (u - half, v - half, u + half, v + half))
                if again is not None:
                    found[marker_id] = again
            return found
    everything = detect_markers(frame, dictionary)
    return {marker_id: marker for marker_id, marker in everything.items() if keep is None or marker_id in keep}


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
    pixel_std: float = 0.1
    plane_offset_m: float | None = None  # None: the object lies in the targets' plane, no pose needed
    camera_matrix: np.ndarray | None = None  # the idealized image's pinhole K (needed for an offset)
    area_matrix: np.ndarray | None = None  # 3x3 pixel -> object's plane, when it is not the targets' plane

    @classmethod
    def fit(cls, pixels: np.ndarray, planes: np.ndarray, distance_std_m: float = 0.0005,
            pixel_std: float = 0.1, plane_offset_m: float | None = None,
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

    def relative_area_std_at(self, uv: np.ndarray) -> float:
        """Relative standard deviation of the metric area of a pixel at `uv` (idealized image) from the targets'
        localisation (pixel_std per coordinate) and the calliper (distance_std_m / sqrt(2) per plane
        coordinate), propagated to first order through the fit by central differences."""
        uv = np.asarray(uv, float).reshape(1, 2)
        base = self.pixel_area(uv)[0]
        variance = 0.0
        for name, sigma, step in (("pixels", self.pixel_std, 1e-3), ("planes", self.distance_std_m / np.sqrt(2), 1e-6)):
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
                variance += ((shifted[0] - shifted[1]) / (2 * step) * sigma) ** 2
        return float(np.sqrt(variance) / base)

    def relative_area_change_per_metre_at(self, uv: np.ndarray) -> float:
        """d ln(pixel area)/d(plane offset) at `uv`, 1/m: how an error in the object's plane offset moves Af
        (about 2 / distance)."""
        if self.plane_offset_m is None:
            return 0.0
        step = 1e-4
        areas = [PlaneScale.fit(self.pixels, self.planes, plane_offset_m=self.plane_offset_m + sign * step,
                                camera_matrix=self.camera_matrix).pixel_area(uv)[0] for sign in (1, -1)]
        return float(abs(np.log(areas[0] / areas[1])) / (2 * step))


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
                    f"targets file do not match the board (permuted or mistyped?)")
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
