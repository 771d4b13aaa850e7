"""ArUco targets in a frame: detection, the projective centre of a marker, and re-tracking of known markers
near where they were in the previous frame (sub-pixel corners checked against the marker's code). No ROS here.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import cv2
import numpy as np


@dataclass(frozen=True)
class DetectedMarker:
    centre: np.ndarray  # (2,) px, the projective centre (intersection of the diagonals)
    corners: np.ndarray  # (4, 2) px
    # the marker's window as it looked in the frame where these corners were found: (grey patch, left, top,
    # and the patch's gradients and their inverse normal matrix), to tell cheaply whether it has moved since
    reference: tuple | None = field(default=None, compare=False, repr=False)


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
# a marker whose window shifted by less than this since it was tracked is where it was: re-tracking would only
# move its corners by their own noise (a one-step gradient estimate over the window; its noise at 4 DN: ~0.004 px)
STEADY_SHIFT_PX = 0.02
STEADY_MEAN_DN = 8.0  # a window whose grey levels changed more than this on average (occlusion) is re-tracked
STEADY_MARGIN_PX = 3


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


def _window(frame: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, int, int] | None:
    """The grey window around a marker's corners (float32), and its top-left; None at the frame's edge."""
    (x0, y0), (x1, y1) = corners.min(axis=0), corners.max(axis=0)
    left, top = int(x0) - STEADY_MARGIN_PX, int(y0) - STEADY_MARGIN_PX
    right, bottom = int(np.ceil(x1)) + STEADY_MARGIN_PX, int(np.ceil(y1)) + STEADY_MARGIN_PX
    if left < 1 or top < 1 or right > frame.shape[1] - 1 or bottom > frame.shape[0] - 1:
        return None
    patch = frame[top:bottom, left:right]
    grey = patch if patch.ndim == 2 else cv2.cvtColor(patch, cv2.COLOR_BGR2GRAY)
    return grey.astype(np.float32), left, top


def with_reference(frame: np.ndarray, marker: DetectedMarker) -> DetectedMarker:
    """The marker with its window in this frame kept as the reference a later frame is compared with."""
    window = _window(frame, marker.corners)
    if window is None:
        return marker
    grey, left, top = window
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3) / 8
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3) / 8
    normal = np.array([[float((gx * gx).sum()), float((gx * gy).sum())],
                       [float((gx * gy).sum()), float((gy * gy).sum())]])
    if np.linalg.det(normal) <= 1e-6 * max(np.trace(normal), 1e-12) ** 2:
        return marker  # no texture to tell a shift by
    mean, std = cv2.meanStdDev(grey)
    return replace(marker, reference=(grey, left, top, gx.ravel(), gy.ravel(), np.linalg.inv(normal),
                                      float(mean[0, 0]), float(std[0, 0])))


def unmoved(frame: np.ndarray, marker: DetectedMarker) -> bool:
    """Whether the marker's window is where it was when its corners were found: its shift, one Lucas-Kanade
    step over the window against the reference, under STEADY_SHIFT_PX, and its grey levels, the light's gain
    and offset over the window taken out, changed no more than STEADY_MEAN_DN on average (something in front
    of it changes them)."""
    if marker.reference is None:
        return False
    grey, left, top, gx, gy, inverse, ref_mean, ref_std = marker.reference
    bottom, right = top + grey.shape[0], left + grey.shape[1]
    if bottom > frame.shape[0] or right > frame.shape[1]:
        return False
    patch = frame[top:bottom, left:right]
    now = patch if patch.ndim == 2 else cv2.cvtColor(patch, cv2.COLOR_BGR2GRAY)
    # the light's change over the window (gain and offset) taken out: a brighter frame has not moved a marker
    now_mean, now_std = cv2.meanStdDev(now)
    if now_std[0, 0] < 1e-6:
        return False
    gain = ref_std / now_std[0, 0]
    diff = cv2.addWeighted(now, gain, grey, -1.0, ref_mean - gain * now_mean[0, 0], dtype=cv2.CV_32F)
    if cv2.norm(diff, cv2.NORM_L1) / diff.size > STEADY_MEAN_DN:
        return False
    diff = diff.ravel()
    shift = -inverse @ np.array([float(diff @ gx), float(diff @ gy)])
    return bool(np.hypot(*shift) < STEADY_SHIFT_PX)


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
                  guesses: dict[int, tuple[np.ndarray, float]] | None = None,
                  skip_unmoved: bool = True) -> dict[int, DetectedMarker]:
    """As `_track_markers`; with `skip_unmoved`, a marker whose window has not moved since it was tracked
    (`unmoved`) keeps its corners without re-tracking (a steady camera: most frames), and every marker found
    anew keeps its window as the reference for the next frames."""
    if skip_unmoved and previous and (wanted is None or set(wanted) <= set(previous)) \
            and all(unmoved(frame, marker) for marker in previous.values()):
        return {marker_id: marker for marker_id, marker in previous.items() if wanted is None or marker_id in wanted}
    found = _track_markers(frame, dictionary, previous, wanted, guesses)
    if not skip_unmoved:
        return found
    return {marker_id: with_reference(frame, marker) for marker_id, marker in found.items()}


def _track_markers(frame: np.ndarray, dictionary: str, previous: dict[int, DetectedMarker],
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
