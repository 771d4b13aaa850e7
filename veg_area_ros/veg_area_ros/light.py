"""Uneven light: the background's brightness over the image and the flat field that evens it. No ROS here.

A flume is not lit evenly: a gradient across the channel, vignetting, a brighter patch. Light multiplies what
the object and the background reflect, so dividing the band by the background's surface B(x) (times its
median, to stay in grey levels) leaves the object's and the background's levels the same everywhere, and an
edge pixel's share where it was: (B_obj - v) / (B_obj - B_bg) does not change when all three are scaled alike.
B comes from a frame of the empty scene (`--background`, the empty flume filmed before the plant goes in), or
is fitted to the frame's own background pixels: a smooth polynomial surface in the image, from the cells of a
coarse grid that hold background only (away from the object's edges, where the shares are read).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

CELL_PX = 12  # the coarse grid's cell: background only cells are fitted, averaged over CELL_PX² pixels
SURFACE_DEGREE = 4  # gradient, vignetting (r², r⁴) and their products: smooth light, not texture
EVEN_SHARE = 0.01  # a surface within 1 % of its median over the region: the light is even, nothing to correct
MIN_CELLS = 40  # fewer background cells than this cannot pin a degree-4 surface: no flat field
BACKGROUND_BLUR_PX = 2.0  # a background frame's noise smoothed away (light varies over tens of pixels)


class LightError(ValueError):
    """A background frame that cannot flat-field these frames."""


@dataclass(frozen=True)
class FlatField:
    """The gain that evens one frame's light: band * gain has the background at `reference` everywhere."""

    gain: np.ndarray  # float32, the window's shape
    reference: float  # the background's median level (grey levels) the band is evened to
    variation: float  # (max - min) / median of the surface over the region: how uneven the light was
    source: str  # "background frame" or "fitted"
    misfit: float  # relative RMS misfit of the fitted surface on its background cells (0 for a background frame)

    @property
    def needed(self) -> bool:
        """Whether the light is uneven enough to be evened (else the band is left as it is)."""
        return self.variation >= EVEN_SHARE

    @property
    def unevenness(self) -> float:
        """The light's relative unevenness left after evening (its misfit), or left in place (half its range)."""
        return self.misfit if self.needed else max(self.misfit, self.variation / 2)

    def apply(self, band: np.ndarray) -> np.ndarray:
        """The evened band, uint8 (rounded, saturated)."""
        return cv2.convertScaleAbs(cv2.multiply(band, self.gain, dtype=cv2.CV_32F))


@functools.lru_cache(maxsize=8)
def _grid_terms(height: int, width: int, cell: int, degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For a window and its coarse grid: every cell's polynomial terms (rows*cols, terms), and the powers of x
    over the columns and of y over the rows that evaluate the surface at every pixel; once per window size."""
    scale = max(width, height)
    rows, cols = height // cell, width // cell
    v, u = np.mgrid[0:rows, 0:cols].reshape(2, -1)
    x = ((u + 0.5) * cell - 0.5 - width / 2) / scale
    y = ((v + 0.5) * cell - 0.5 - height / 2) / scale
    terms = np.column_stack([x ** (total - j) * y ** j for total in range(degree + 1) for j in range(total + 1)])
    x_powers = np.vander((np.arange(width) - width / 2) / scale, degree + 1, increasing=True)
    y_powers = np.vander((np.arange(height) - height / 2) / scale, degree + 1, increasing=True)
    for array in (terms, x_powers, y_powers):
        array.setflags(write=False)
    return terms, x_powers, y_powers


def _surface(coefficients: np.ndarray, shape: tuple[int, int], degree: int, cell: int) -> np.ndarray:
    """The polynomial surface over a window of `shape`: (rows' powers) @ (per-power row polynomials), one
    matrix product instead of a pass per term."""
    _, x_powers, y_powers = _grid_terms(*shape, cell, degree)
    table = np.zeros((degree + 1, degree + 1))  # table[j, i]: coefficient of x^i y^j
    k = 0
    for total in range(degree + 1):
        for j in range(total + 1):
            table[j, total - j] = coefficients[k]
            k += 1
    return (y_powers @ (table @ x_powers.T)).astype(np.float32)


def fit_background_surface(band: np.ndarray, background: np.ndarray, degree: int = SURFACE_DEGREE,
                           cell: int = CELL_PX) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The background's brightness over the window (float32), fitted to the cells of a coarse grid that hold
    only background pixels (`background`: bool, the window's shape), the relative RMS misfit on those cells,
    and the fitted surface's values at them; None when too few cells are background to pin the surface."""
    height, width = band.shape
    marks = background.astype(np.uint8) * np.uint8(255)
    needed = MIN_CELLS * cell**2  # background pixels in whole cells that pin the surface
    for size in (cell, cell // 2):  # halved where the background's patches hold too few whole cells
        cell = size
        rows, cols = height // cell, width // cell
        if rows < 2 or cols < 2 or cell < 2:
            return None
        crop = (slice(0, rows * cell), slice(0, cols * cell))
        # a cell is background when every one of its pixels is (255 on average: one pixel short makes it 253);
        # a chessboard's white squares of 38 px, eroded off the edges, hold one or two 12 px cells each (32 in
        # all on a real photo, too few: its 25 % shading was left in the shares, +5.9 %) and about ten 6 px ones
        full = (cv2.resize(marks[crop], (cols, rows), interpolation=cv2.INTER_AREA) == 255).ravel()
        if int(full.sum()) * cell**2 >= needed:
            break
    else:
        return None
    values = cv2.resize(band[crop], (cols, rows), interpolation=cv2.INTER_AREA).astype(float).ravel()
    terms, target = _grid_terms(height, width, cell, degree)[0][full], values[full]
    keep = np.ones(len(target), bool)
    for _ in range(2):  # once more without the cells the first fit calls outliers (a leaf, a bubble)
        used = terms[keep]
        coefficients = np.linalg.solve(used.T @ used + 1e-9 * np.eye(used.shape[1]), used.T @ target[keep])
        fitted = terms @ coefficients
        residual = target - fitted
        spread = 1.4826 * float(np.median(np.abs(residual[keep]))) + 1e-6
        keep = np.abs(residual) <= 4 * spread
        if int(keep.sum()) * cell**2 < needed:
            return None
    surface = _surface(coefficients, (height, width), degree, cell)
    misfit = float(np.sqrt(np.mean(residual[keep] ** 2))) / max(float(np.median(target[keep])), 1.0)
    return surface, misfit, fitted[keep]


def flat_field(band: np.ndarray, region: np.ndarray, background: np.ndarray | None = None,
               background_band: np.ndarray | None = None) -> FlatField | None:
    """The flat field of one window of the band: from a background frame's band (`background_band`, the same
    window of the empty scene), or fitted to the frame's background pixels (`background`, bool); None when
    it cannot be had. `needed` says whether the light varies by EVEN_SHARE or more over the region (uint8)."""
    if background_band is not None:
        surface = cv2.GaussianBlur(background_band.astype(np.float32), (0, 0), BACKGROUND_BLUR_PX)
        values = surface[region > 0]
        source, misfit = "background frame", 0.0
        reference, low, high = float(np.median(values)), float(values.min()), float(values.max())
    else:
        fitted = fit_background_surface(band, background & (region > 0))
        if fitted is None:
            return None
        surface, misfit, at_cells = fitted
        source = "fitted"
        low, high, _, _ = cv2.minMaxLoc(surface, region)
        reference = float(np.median(at_cells))
    if reference < 8 or low <= 1:
        return None  # a black or unlit background holds no light to even
    gain = cv2.divide(reference, np.maximum(surface, np.float32(1.0)))
    return FlatField(gain.astype(np.float32, copy=False), reference, (high - low) / reference, source, misfit)


def check_background_frame(background: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """A background frame usable for frames of `shape`: same size, lit (its median above 8 grey levels)."""
    if background.shape[:2] != tuple(shape[:2]):
        raise LightError(f"the background frame is {background.shape[1]}x{background.shape[0]}, the frames "
                         f"{shape[1]}x{shape[0]}: film the empty scene with the same camera and settings")
    if float(np.median(background)) < 8:
        raise LightError("the background frame is black (median under 8 grey levels): film the empty scene lit")
    return background
