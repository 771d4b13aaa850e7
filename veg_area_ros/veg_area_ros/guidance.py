"""Guiding the operator of a calibration, as ROS's camera_calibration does, for a board held under water: each
view judged (kept, or rejected with its reason), the variety of the kept views as bars (where they cover the
image, how the board was placed, sized, tilted and rolled), and one line saying what is still needed. The
calibration node draws it on `~/feedback`; `veg-area calibrate` prints the lines and its report the bars.

No ROS here.
"""

from __future__ import annotations

import bisect
import math
from collections import Counter
from dataclasses import dataclass, field

import cv2
import numpy as np

from .board import BoardSpec, Detection, nearest_spacing
from .calibration import NEW_POSE_DISTANCE, coverage_grid, pose_signature

GRID = (16, 12)  # coverage cells over the image (columns, rows): fine enough to show a missed corner
CORNER_SHARE = 0.25  # an image corner: the outer quarter of the width and of the height
MIN_BOARD_SHARE = 0.5  # a view with fewer of the board's points shows only part of it
CLIP_LEVEL = 250
MAX_CLIPPED_SHARE = 0.05  # corner-window pixels at 250 or more: whites bloom into the blacks, corners move
BLUR_FACTOR = 1.6  # edges wider than this many times the kept views' median: motion blur
SQRT_HALF = math.sqrt(0.5)
MAX_EDGE_WIDTH_PX = 6.0  # before three views are kept, edges wider than this (at 640 px; scaled) are blurred
# what each bar counts and the span of the kept views that fills it
GOALS = {
    # span of the board's positions, each as a share of the room the board has to move in (0: touching the
    # left or top edge, 1: the right or bottom), as camera_calibration measures them
    "x": ("position X", 0.5),
    "y": ("position Y", 0.5),
    # span of the board's apparent size, share of the image width: modest, as the views are taken at about
    # the measuring distance (the method's rule); tilting and a little nearer and farther give it
    "size": ("size (distance)", 0.08),
    "tilt_h": ("tilt about the horizontal axis", 30.0),  # degrees between the most tilted views
    "tilt_v": ("tilt about the vertical axis", 30.0),
    "roll": ("roll (a 90° turn)", 70.0),  # degrees, folded modulo 180
    "coverage": ("coverage", 0.6),  # share of the grid's cells holding a kept view's point
}
ADVICE = {
    "tilt_h": "tilt the board about its horizontal axis (top towards the camera, then away)",
    "tilt_v": "tilt the board about its vertical axis (left side towards the camera, then away)",
    "roll": "roll the board by 90 degrees (turn it on its side)",
    "x": "move the board to the left and right edges of the image",
    "y": "move the board to the top and bottom edges of the image",
    "size": "hold the board nearer and farther (a little bigger and smaller in the image)",
    "coverage": "cover the image's empty cells (shown unfilled)",
}
ORDER = ("corners", "tilt_h", "tilt_v", "roll", "x", "y", "size", "coverage")


@dataclass
class ViewStats:
    """What one view shows about its pose and its quality."""

    position: tuple[float, float]  # board centre in the room it has to move in (0..1 across, 0..1 down)
    size: float  # sqrt of the board's hull area, share of the image width
    tilt_h: float  # degrees, the board's normal turned up/down (about the image's horizontal axis)
    tilt_v: float  # degrees, turned left/right
    roll: float  # degrees, the board's first axis in the image, modulo 180
    edge_width_px: float  # median width of the board's edges at its corners, in their least steep direction
    clipped_share: float  # share of the corner windows' pixels at CLIP_LEVEL or more
    points: int
    board_points: int


@dataclass
class Verdict:
    kept: bool
    reason: str  # why it was rejected ('' when kept)
    kind: str  # one word for counting: kept, similar, partial, blurred, clipped
    stats: ViewStats | None = None


@dataclass
class CalibrationGuide:
    """The views offered so far, judged; the variety of those kept; what is still needed."""

    board: BoardSpec
    image_size: tuple[int, int]
    min_views: int = 12
    kept: list[ViewStats] = field(default_factory=list)
    signatures: list[np.ndarray] = field(default_factory=list)
    rejected: Counter = field(default_factory=Counter)
    covered: np.ndarray | None = None
    # the kept views' edge widths, sorted (their median at hundreds of views); kept up to date by offer()
    kept_widths: list[float] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.covered is None:
            self.covered = np.zeros((GRID[1], GRID[0]), bool)
        self.kept_widths = sorted(s.edge_width_px for s in self.kept)

    def offer(self, detection: Detection, image: np.ndarray, keep: bool = False,
              stats: ViewStats | None = None) -> Verdict:
        """Judge a view: kept (it adds variety and is sharp and well exposed) or rejected with its reason.
        `keep`: count it among the kept views whatever the verdict (a set of photos chosen by hand: the
        verdict is then advice). `stats`: the view's `view_stats`, where they were computed already (beside
        the board's search, on another thread)."""
        if stats is None:
            stats = view_stats(detection, image, self.board, self.image_size)
        signature = pose_signature(detection.image_points, self.image_size)
        cells = coverage_grid([detection.image_points], *self.image_size, *GRID)
        verdict = self._judge(stats, signature, cells)
        if verdict.kept or keep:
            self.kept.append(stats)
            bisect.insort(self.kept_widths, stats.edge_width_px)
            self.signatures.append(signature)
            self.covered |= cells
        else:
            self.rejected[verdict.kind] += 1
        return verdict

    def _judge(self, stats: ViewStats, signature: np.ndarray, cells: np.ndarray) -> Verdict:
        if stats.points < MIN_BOARD_SHARE * stats.board_points:
            return Verdict(False, f"only part of the board ({stats.points} of {stats.board_points} points)",
                           "partial", stats)
        if stats.clipped_share > MAX_CLIPPED_SHARE:
            return Verdict(False, f"over-exposed board ({100 * stats.clipped_share:.0f} % of the corners' pixels "
                                  f"at {CLIP_LEVEL} or more): shorten the exposure or dim the light",
                           "clipped", stats)
        limit = self.blur_limit()
        if stats.edge_width_px > limit:
            return Verdict(False, f"motion blur (edges {stats.edge_width_px:.1f} px wide, the sharp views' "
                                  f"{limit / BLUR_FACTOR if len(self.kept) >= 3 else limit:.1f} px): hold the "
                                  "board still", "blurred", stats)
        nearest = (float(np.linalg.norm(np.asarray(self.signatures) - signature, axis=1).min())
                   if self.signatures else math.inf)
        if nearest < NEW_POSE_DISTANCE and not (cells & ~self.covered).any():
            return Verdict(False, "too similar to a kept view", "similar", stats)
        return Verdict(True, "", "kept", stats)

    def blur_limit(self) -> float:
        """The widest edges a kept view may have: BLUR_FACTOR times the kept views' median, or an absolute
        limit (scaled with the image width) until three views are kept."""
        if len(self.kept_widths) >= 3:
            middle = len(self.kept_widths) // 2
            median = (self.kept_widths[middle] if len(self.kept_widths) % 2
                      else (self.kept_widths[middle - 1] + self.kept_widths[middle]) / 2)
            return BLUR_FACTOR * float(median)
        return MAX_EDGE_WIDTH_PX * max(1.0, self.image_size[0] / 640)

    def spans(self) -> dict[str, float]:
        """The kept views' span of each kind of variety, in the units of GOALS."""
        if not self.kept:
            return {name: 0.0 for name in GOALS}
        def span(values: list[float]) -> float:
            return float(max(values) - min(values))
        rolls = np.array([s.roll for s in self.kept])
        apart = np.abs(rolls[:, None] - rolls[None, :]) % 180  # every pair, on the circle of directions mod 180
        roll_span = float(np.minimum(apart, 180 - apart).max())
        return {"x": span([s.position[0] for s in self.kept]), "y": span([s.position[1] for s in self.kept]),
                "size": span([s.size for s in self.kept]), "tilt_h": span([s.tilt_h for s in self.kept]),
                "tilt_v": span([s.tilt_v for s in self.kept]), "roll": float(roll_span),
                "coverage": float(self.covered.mean())}

    def bars(self) -> dict[str, float]:
        """Each variety as a share of its goal (0..1)."""
        return {name: min(value / GOALS[name][1], 1.0) for name, value in self.spans().items()}

    def missing_corners(self) -> list[str]:
        """The image corners no kept view reached."""
        cols, rows = max(1, round(CORNER_SHARE * GRID[0])), max(1, round(CORNER_SHARE * GRID[1]))
        regions = {"top-left": self.covered[:rows, :cols], "top-right": self.covered[:rows, -cols:],
                   "bottom-left": self.covered[-rows:, :cols], "bottom-right": self.covered[-rows:, -cols:]}
        return [name for name, cells in regions.items() if not cells.any()]

    def still_needed(self) -> str | None:
        """What the views still lack, most important first, as the operator should hear it; None when the
        variety suffices for a fit."""
        bars = self.bars()
        for need in ORDER:
            if need == "corners":
                corners = self.missing_corners()
                if corners:
                    return f"cover the {' and '.join(corners[:2])} corner{'s' if len(corners[:2]) > 1 else ''}"
            elif bars[need] < 1.0:
                return ADVICE[need]
        if len(self.kept) < self.min_views:
            return f"{self.min_views - len(self.kept)} more varied views (kept {len(self.kept)} of {self.min_views})"
        return None

    def enough(self) -> bool:
        return self.still_needed() is None

    def summary(self) -> dict:
        """Plain numbers for `~/progress` and the CLI's JSON."""
        return {"views_kept": len(self.kept), "rejected": dict(self.rejected),
                "bars": {name: round(value, 3) for name, value in self.bars().items()},
                "still_needed": self.still_needed(), "coverage_cells": int(self.covered.sum())}


def nominal_camera(image_size: tuple[int, int]) -> np.ndarray:
    """A pinhole without a calibration (focal length the image's longer side, centred): enough to tell how a
    board is turned, which is all the bars need."""
    width, height = image_size
    focal = float(max(width, height))
    return np.array([[focal, 0, (width - 1) / 2], [0, focal, (height - 1) / 2], [0, 0, 1]])


def view_stats(detection: Detection, image: np.ndarray, board: BoardSpec, image_size: tuple[int, int]) -> ViewStats:
    width, height = image_size
    points = detection.image_points.reshape(-1, 2)
    centre = points.mean(axis=0)
    hull = cv2.convexHull(points.astype(np.float32))
    size = math.sqrt(max(cv2.contourArea(hull), 0.0)) / width
    tilt_h = tilt_v = roll = 0.0
    if len(points) >= 4:
        ok, rvec, _ = cv2.solvePnP(detection.object_points.reshape(-1, 3).astype(np.float64),
                                   points.astype(np.float64), nominal_camera(image_size), None,
                                   flags=cv2.SOLVEPNP_IPPE)
        if ok:
            rotation = cv2.Rodrigues(rvec)[0]
            normal = rotation[:, 2] * (1 if rotation[2, 2] >= 0 else -1)
            tilt_h = math.degrees(math.atan2(normal[1], normal[2]))
            tilt_v = math.degrees(math.atan2(normal[0], normal[2]))
            roll = math.degrees(math.atan2(rotation[1, 0], rotation[0, 0])) % 180
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    width_px, clipped = _corner_quality(grey, points)
    extent = np.ptp(points, axis=0) / (width, height)  # the board's bounding box, share of the image
    position = tuple(float(np.clip((centre[k] / (width, height)[k] - extent[k] / 2) / max(1 - extent[k], 1e-6), 0, 1))
                     for k in range(2))
    return ViewStats(position, float(size), tilt_h, tilt_v, roll, width_px, clipped, len(points),
                     len(board.object_points()))


def _corner_quality(grey: np.ndarray, points: np.ndarray, samples: int = 24) -> tuple[float, float]:
    """(median edge width in px, share of clipped pixels) in windows around up to `samples` of the corners.
    An edge's width: the window's contrast over its steepest gradient in the direction where edges are least
    steep (both after a 3x3 mean), the width a linear ramp of that contrast would have (a sharp edge about
    2-3 px, a blurred one its blur)."""
    chosen = points[np.linspace(0, len(points) - 1, min(samples, len(points))).round().astype(int)]
    spacing = nearest_spacing(points) if len(points) > 1 else 20.0
    half = int(np.clip(0.35 * spacing, 3, 40))
    side = 2 * half + 1
    # every window at once, with a 2 px rim so that the mean and the gradients see real neighbours
    corners = np.round(chosen).astype(int) - half - 2
    inside = ((corners >= 0).all(axis=1) & (corners[:, 0] + side + 4 <= grey.shape[1])
              & (corners[:, 1] + side + 4 <= grey.shape[0]))
    if not inside.any():
        return math.inf, 0.0
    corners = corners[inside]
    rimmed = np.lib.stride_tricks.sliding_window_view(grey, (side + 4, side + 4))[corners[:, 1], corners[:, 0]]
    raw = rimmed[:, 2:-2, 2:-2]
    clipped = float(np.count_nonzero(raw >= CLIP_LEVEL)) / raw.size
    # lightly smoothed, so that the sensor's noise neither widens the contrast nor steepens an edge; the windows
    # filtered as one image stacked from them (a window's 2 px rim keeps its neighbours out of what is used)
    mosaic = cv2.blur(rimmed.reshape(-1, side + 4).astype(np.float32), (3, 3))
    inner = (slice(None), slice(2, -2), slice(2, -2))
    window = mosaic.reshape(rimmed.shape)[inner]
    contrast = window.max(axis=(1, 2)) - window.min(axis=(1, 2))
    gx = cv2.Sobel(mosaic, cv2.CV_32F, 1, 0, ksize=3).reshape(rimmed.shape)[inner] / 8
    gy = cv2.Sobel(mosaic, cv2.CV_32F, 0, 1, ksize=3).reshape(rimmed.shape)[inner] / 8
    # the steepest gradient along each of four directions: motion smears the edges across its direction
    # only, so the widest of the four sees it (a sharp board turned 45 degrees reads at most 1.4x)
    steepest = np.min([np.abs(g).max(axis=(1, 2)) for g in (gx, gy, (gx + gy) * SQRT_HALF, (gx - gy) * SQRT_HALF)],
                      axis=0)
    usable = (contrast > 20) & (steepest > 0)
    widths = contrast[usable] / steepest[usable]
    return (float(np.median(widths)) if len(widths) else math.inf), clipped
