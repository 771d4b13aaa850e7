"""A marker's corners placed by its four sides, in the idealized image. No ROS here.

ArUco's corner refinement (OpenCV's cornerSubPix) finds where the grey-level gradients around a corner point
at it; on a sharp or lightly blurred L-shaped corner that point moves with the edge's phase in its pixel, by up
to 0.25 px at a marker's centre on 640x480 renders, which moved the plane's scale and Af by +-0.15 % as a cube
and its markers slid across one pixel. A side of a dark square on a light quiet zone is placed without that
bias: across the side, the integral of the "blackness" (the grey level's share between the quiet zone's white
and the border's black) over a window that reaches into both is the side's position, at any blur and phase,
because blur and pixel area keep that integral. Profiles across the middle of each side are sampled through the
camera's idealization, so a side is a straight line where it is fitted (distortion bends it in the raw frame);
the corners are the intersections of neighbouring sides.

Where a side's profiles disagree (the quiet zone is not clear: a plant over it, a dark print's margin, a
marker at the frame's edge), the marker keeps the corners the tracking refined, and the caller says so.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

SIDE_SPAN = (0.2, 0.8)  # the part of each side sampled: clear of the corners, where two sides' blur meets
SIDE_PROFILES = 24  # profiles across each side
PROFILE_STEP_PX = 0.25  # samples along a profile (idealized pixels)
REACH_CELLS = 0.5  # a profile reaches this far into the border cell and as far out into the quiet zone
MAX_REACH_PX = 8.0  # enough for a DSLR's blur; farther out the quiet zone may end
MIN_REACH_PX = 1.5  # a smaller marker's cells leave no room for the blur: its tracked corners are kept
LEVEL_SAMPLES = 2  # samples at each end of a profile that read the black and the white
MIN_CONTRAST_DN = 10.0  # black and white closer than this tell no side
OUTLIER_PX = 0.2  # a profile whose side lies farther than this from the others' line is not used, or farther
OUTLIER_SPREADS = 4.0  # than this many of their robust spreads where noise scatters them more
MIN_KEPT = 0.6  # share of a side's profiles that must agree with its line
MAX_MOVE_PX = 1.0  # corners placed by the sides must lie this close to the tracked ones
ROUNDS = 2  # the sides refitted along the sides found in the round before


def _side_line(grey: np.ndarray, start: np.ndarray, end: np.ndarray, outward: np.ndarray,
               to_raw: Callable[[np.ndarray], np.ndarray], reach: float) -> tuple[np.ndarray, np.ndarray] | None:
    """One side as a point and a unit direction in the idealized image, or None where it cannot be told."""
    along = end - start
    length = float(np.hypot(*along))
    direction = along / length
    across = np.arange(-reach, reach + PROFILE_STEP_PX / 2, PROFILE_STEP_PX)
    shares = np.linspace(*SIDE_SPAN, SIDE_PROFILES)
    ideal = (start + shares[:, None] * along)[:, None, :] + across[None, :, None] * outward
    raw = to_raw(ideal.reshape(-1, 2)).reshape(ideal.shape)
    height, width = grey.shape
    if (not np.all(np.isfinite(raw)) or raw[..., 0].min() < 0 or raw[..., 1].min() < 0
            or raw[..., 0].max() > width - 1 or raw[..., 1].max() > height - 1):
        return None
    profiles = cv2.remap(grey, raw[..., 0].astype(np.float32), raw[..., 1].astype(np.float32), cv2.INTER_LINEAR)
    black = float(np.median(profiles[:, :LEVEL_SAMPLES]))
    white = float(np.median(profiles[:, -LEVEL_SAMPLES:]))
    if white - black < MIN_CONTRAST_DN:
        return None
    blackness = (white - profiles) / (white - black)
    # black for offsets below the side: the integral from -reach to +reach is the side's offset plus reach
    offsets = np.trapezoid(blackness, across, axis=1) - reach
    positions = shares * length
    # a robust first line (Theil-Sen: the median of the pairs' slopes), then least squares on the profiles near it
    first, second = np.triu_indices(len(offsets), 1)
    slope = float(np.median((offsets[second] - offsets[first]) / (positions[second] - positions[first])))
    intercept = float(np.median(offsets - slope * positions))
    for _ in range(2):
        residuals = offsets - (intercept + slope * positions)
        # noise scatters the profiles (a dim, noisy frame by a few tenths of a pixel); a leaf moves them further
        spread = 1.4826 * float(np.median(np.abs(residuals - np.median(residuals))))
        kept = np.abs(residuals) <= max(OUTLIER_PX, OUTLIER_SPREADS * spread)
        if kept.sum() < MIN_KEPT * len(offsets):
            return None
        slope, intercept = np.polyfit(positions[kept], offsets[kept], 1)
    point = start + intercept * outward
    turned = direction + slope * outward
    return point, turned / np.hypot(*turned)


def _intersection(first: tuple[np.ndarray, np.ndarray], second: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    (p1, d1), (p2, d2) = first, second
    try:
        steps = np.linalg.solve(np.column_stack([d1, -d2]), p2 - p1)
    except np.linalg.LinAlgError:  # parallel sides: no corner
        return np.full(2, np.nan)
    return p1 + steps[0] * d1


def corners_by_sides(grey: np.ndarray, corners: np.ndarray, cells: int,
                     to_raw: Callable[[np.ndarray], np.ndarray]) -> np.ndarray | None:
    """The marker's four corners (idealized image, in the order given) as the intersections of its sides,
    each side placed by its profiles' blackness. `grey`: the raw frame (float32; in light for a camera with a
    tone curve), `corners`: the tracked corners in the idealized image, `cells`: the marker's cells across with
    its border, `to_raw`: idealized -> raw pixels. None where the sides cannot be told (see the module)."""
    corners = np.asarray(corners, float).reshape(4, 2)
    side = float(np.mean(np.hypot(*(corners - corners[[1, 2, 3, 0]]).T)))
    reach = min(REACH_CELLS * side / cells, MAX_REACH_PX)
    if reach < MIN_REACH_PX:
        return None
    centre = corners.mean(axis=0)
    placed = corners
    for _ in range(ROUNDS):
        lines = []
        for k in range(4):
            start, end = placed[k], placed[(k + 1) % 4]
            direction = (end - start) / np.hypot(*(end - start))
            outward = np.array([direction[1], -direction[0]])
            if outward @ ((start + end) / 2 - centre) < 0:
                outward = -outward
            line = _side_line(grey, start, end, outward, to_raw, reach)
            if line is None:
                return None
            lines.append(line)
        placed = np.array([_intersection(lines[k - 1], lines[k]) for k in range(4)])
        if not np.all(np.isfinite(placed)) or np.max(np.hypot(*(placed - corners).T)) > MAX_MOVE_PX:
            return None
    return placed
