"""Calibration boards: specification, detection with sub-pixel refinement, and a printable texture.

No ROS here. A board spec is a string a user types:

    chessboard:COLSxROWS:SQUARE_M            inner corners, square side in metres
    charuco:SXxSY:SQUARE_M:MARKER_M:DICT     squares, square and marker side, ArUco dictionary
    charuco:SXxSY:SQUARE_M:MARKER_M:DICT:legacy   a board laid out as OpenCV before 4.6 (and calib.io) lay
                                             out those with an even number of rows
    circles:COLSxROWS:SPACING_M              asymmetric circle grid; circle (i, j) sits at
                                             ((2j + i mod 2)·s, i·s), OpenCV's convention
    circles:COLSxROWS:SPACING_M:symmetric    symmetric circle grid; circle (i, j) at (j·s, i·s)
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .targets import MAX_TARGET_SPAN_M, MIN_TARGET_SPAN_M

KINDS = ("chessboard", "charuco", "circles")
SECTOR_DETECTOR_SEED = 0x5EED  # findChessboardCornersSB's random numbers, the same for every frame


class BoardSpecError(ValueError):
    """A board specification that cannot be understood."""


@dataclass(frozen=True)
class Detection:
    """Board points found in one image: pixels (N, 2) and board coordinates in metres (N, 3)."""

    image_points: np.ndarray
    object_points: np.ndarray
    ids: np.ndarray  # index of each point in the full board, so partial views stay comparable
    inverted: bool = False  # found only after inverting the image (white-on-black boards)

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class BoardSpec:
    kind: str
    cols: int
    rows: int
    square: float  # square side (chessboard, charuco) or grid spacing (circles), metres
    marker: float = 0.0
    dictionary: str = ""
    symmetric: bool = False  # circles: a symmetric grid (else OpenCV's asymmetric one)
    legacy: bool = False  # charuco: the layout before OpenCV 4.6 (differs where the rows are even)

    @classmethod
    def parse(cls, text: str) -> BoardSpec:
        parts = text.strip().split(":")
        kind = parts[0].lower()
        usage = {
            "chessboard": "chessboard:COLSxROWS:SQUARE_M",
            "charuco": "charuco:SXxSY:SQUARE_M:MARKER_M:DICT",
            "circles": "circles:COLSxROWS:SPACING_M",
        }
        if kind not in usage:
            raise BoardSpecError(f"unknown board kind {parts[0]!r} in {text!r}; use one of {', '.join(KINDS)}")
        expected = usage[kind].count(":") + 1
        symmetric = kind == "circles" and len(parts) == expected + 1 and parts[-1].lower() == "symmetric"
        legacy = kind == "charuco" and len(parts) == expected + 1 and parts[-1].lower() == "legacy"
        if symmetric or legacy:
            parts = parts[:-1]
        if len(parts) != expected:
            hint = {"circles": " (or circles:COLSxROWS:SPACING_M:symmetric)",
                    "charuco": " (or charuco:SXxSY:SQUARE_M:MARKER_M:DICT:legacy)"}.get(kind, "")
            raise BoardSpecError(f"board spec {text!r} should look like {usage[kind]}{hint}")
        try:
            cols, rows = (int(n) for n in parts[1].lower().split("x"))
            square = float(parts[2])
            marker = float(parts[3]) if kind == "charuco" else 0.0
        except ValueError as exc:
            raise BoardSpecError(f"board spec {text!r} should look like {usage[kind]}") from exc
        if not (np.isfinite(square) and square > 0) or not np.isfinite(marker):
            raise BoardSpecError(f"square size must be a positive number of metres in {text!r}")
        if cols < 2 or rows < 2:
            raise BoardSpecError(f"a board needs at least 2x2 points, got {cols}x{rows} in {text!r}")
        dictionary = ""
        if kind == "charuco":
            dictionary = parts[4].upper()
            if not hasattr(cv2.aruco, dictionary) or not dictionary.startswith("DICT_"):
                raise BoardSpecError(f"unknown ArUco dictionary {parts[4]!r} in {text!r}")
            if not 0 < marker < square:
                raise BoardSpecError(f"the marker must be smaller than the square in {text!r}")
        spec = cls(kind, cols, rows, square, marker, dictionary, symmetric, legacy)
        span = float(np.max(np.ptp(spec.object_points()[:, :2], axis=0)))
        if not MIN_TARGET_SPAN_M <= span <= MAX_TARGET_SPAN_M:  # the same range as targets: the board scales them
            raise BoardSpecError(
                f"board {text!r} spans {span:.3g} m; sizes are in metres ({MIN_TARGET_SPAN_M * 1000:g} mm to "
                f"{MAX_TARGET_SPAN_M:g} m): " + ("millimetres given as metres?" if span > MAX_TARGET_SPAN_M
                                                 else "smaller than a board a camera resolves"))
        return spec

    def __str__(self) -> str:
        if self.kind == "charuco":
            return (f"charuco:{self.cols}x{self.rows}:{self.square:g}:{self.marker:g}:{self.dictionary}"
                    + (":legacy" if self.legacy else ""))
        return f"{self.kind}:{self.cols}x{self.rows}:{self.square:g}" + (":symmetric" if self.symmetric else "")

    # --- geometry -----------------------------------------------------------------------------------
    def object_points(self) -> np.ndarray:
        """All board points (N, 3) in metres, z = 0, in detection order."""
        if self.kind == "charuco":
            return np.asarray(self._charuco_board().getChessboardCorners(), dtype=np.float64).reshape(-1, 3)
        i, j = np.meshgrid(np.arange(self.rows), np.arange(self.cols), indexing="ij")
        if self.kind == "chessboard" or self.symmetric:
            xy = np.column_stack([j.ravel(), i.ravel()]) * self.square
        else:
            xy = np.column_stack([(2 * j + i % 2).ravel(), i.ravel()]) * self.square
        return np.column_stack([xy, np.zeros(len(xy))]).astype(np.float64)

    def corner_grid(self) -> tuple[int, int]:
        """(columns, rows) of the board's points: a chessboard's inner corners, a ChArUco board's chessboard
        corners (one fewer than its squares each way; id = row * columns + column), a circle grid's circles."""
        return (self.cols - 1, self.rows - 1) if self.kind == "charuco" else (self.cols, self.rows)

    def extent(self) -> tuple[float, float, float, float]:
        """Printed area (x0, y0, x1, y1) in board metres, quiet margin included."""
        s = self.square
        if self.kind == "chessboard":
            return (-1.5 * s, -1.5 * s, (self.cols + 0.5) * s, (self.rows + 0.5) * s)
        if self.kind == "charuco":
            return (-0.5 * s, -0.5 * s, (self.cols + 0.5) * s, (self.rows + 0.5) * s)
        columns = self.cols if self.symmetric else 2 * self.cols
        return (-1.5 * s, -1.5 * s, (columns + 0.5) * s, (self.rows + 0.5) * s)

    def dark_cells(self) -> np.ndarray:
        """A ChArUco board's dark print as disjoint rectangles (N, 4: x0, y0, x1, y1 in board metres, as its
        points): the black squares and each marker's black cells, placed as OpenCV draws the board."""
        if self.kind != "charuco":
            raise ValueError(f"dark_cells: a charuco board's, not a {self.kind} board's")
        board = self._charuco_board()
        dictionary = board.getDictionary()
        side = dictionary.markerSize + 2  # the bits and a black border of one cell
        cell = self.marker_cell()
        cells, holding = [], set()
        for marker_id, corners in zip(np.ravel(board.getIds()), board.getObjPoints(), strict=True):
            x0, y0 = np.asarray(corners, np.float64)[0, :2]
            holding.add((int(x0 // self.square), int(y0 // self.square)))
            bits = dictionary.generateImageMarker(int(marker_id), side, borderBits=1)
            for row, col in zip(*np.nonzero(bits < 128), strict=True):
                cells.append((x0 + col * cell, y0 + row * cell, x0 + (col + 1) * cell, y0 + (row + 1) * cell))
        s = self.square
        cells += [(c * s, r * s, (c + 1) * s, (r + 1) * s) for r in range(self.rows) for c in range(self.cols)
                  if (c, r) not in holding]
        return np.array(cells, np.float64)

    def marker_cell(self) -> float:
        """A ChArUco board's markers' cell side (m): the marker over its bits and its border of one cell."""
        return self.marker / (self._charuco_board().getDictionary().markerSize + 2)

    def _charuco_board(self) -> cv2.aruco.CharucoBoard:
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker, dictionary)
        board.setLegacyPattern(self.legacy)
        return board

    def texture(self, pixels_per_metre: float) -> np.ndarray:
        """The printed board as a grey image covering extent(); pixel (0, 0) is at (x0, y0)."""
        x0, y0, x1, y1 = self.extent()
        width = round((x1 - x0) * pixels_per_metre)
        height = round((y1 - y0) * pixels_per_metre)
        s = self.square * pixels_per_metre
        if self.kind == "charuco":
            board = self._charuco_board().generateImage(
                (round(self.cols * s), round(self.rows * s)), marginSize=0, borderBits=1)
            margin = round(0.5 * s)
            return cv2.copyMakeBorder(board, margin, margin, margin, margin, cv2.BORDER_CONSTANT, value=255)
        image = np.full((height, width), 255, np.uint8)
        ox, oy = -x0 * pixels_per_metre, -y0 * pixels_per_metre
        if self.kind == "chessboard":
            for r in range(self.rows + 1):
                for c in range(self.cols + 1):
                    if (r + c) % 2 == 0:
                        top, left = oy + (r - 1) * s, ox + (c - 1) * s
                        cv2.rectangle(image, (round(left), round(top)),
                                      (round(left + s) - 1, round(top + s) - 1), 0, thickness=-1)
        else:
            shift = 4  # sub-pixel circle centres
            for x, y, _ in self.object_points():
                # pixel centres sit half a texel inside the printed edge (see synthetic.render_plane)
                centre = (round((ox + x * pixels_per_metre - 0.5) * 2**shift),
                          round((oy + y * pixels_per_metre - 0.5) * 2**shift))
                cv2.circle(image, centre, round(0.35 * s * 2**shift), 0, -1, cv2.LINE_AA, shift)
        return image

    # --- detection ----------------------------------------------------------------------------------
    def detect(self, image: np.ndarray) -> Detection | None:
        """Find the board in a grey or BGR image; None where it is not found."""
        grey = to_grey(image)
        if self.kind == "chessboard":
            return self._detect_chessboard(grey)
        if self.kind == "circles":
            return self._detect_circles(grey)
        found = self._detect_charuco(grey)
        if found is None:  # white-on-black prints are only found inverted
            found = self._detect_charuco(255 - grey)
            if found is not None:
                found = Detection(found.image_points, found.object_points, found.ids, inverted=True)
        return found

    def _detection(self, corners: np.ndarray, ids: np.ndarray) -> Detection:
        corners = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
        ids = np.asarray(ids, dtype=np.int64).ravel()
        return Detection(corners, self.object_points()[ids], ids)

    def _detect_chessboard(self, grey: np.ndarray) -> Detection | None:
        size = (self.cols, self.rows)
        # both detectors cost seconds on a large frame without a board: only where OpenCV's quick check sees one
        if not board_in_view(grey, size):
            return None
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        found, corners = cv2.findChessboardCorners(grey, size, flags=flags)
        if not found:
            # the sector-based detector copes better with strong distortion and a board cut by the frame's edge;
            # its accuracy mode costs 4x the time and was no closer to the truth than the saddle refinement
            # below (renders of a distorted lens and under moderate blur; real frames' residuals)
            # it draws on the calling thread's random numbers, whose state depends on what that thread did
            # before: seeded here, a frame gives one answer in any thread (else a run's views varied with load)
            cv2.setRNGSeed(SECTOR_DETECTOR_SEED)
            found, corners = cv2.findChessboardCornersSB(grey, size)
            if not found:
                return None
        corners = refine_corners(grey, corners.reshape(-1, 2), nearest_spacing(corners.reshape(-1, 2)))
        return self._detection(corners, np.arange(self.cols * self.rows))

    def _detect_circles(self, grey: np.ndarray) -> Detection | None:
        grid = cv2.CALIB_CB_SYMMETRIC_GRID if self.symmetric else cv2.CALIB_CB_ASYMMETRIC_GRID
        found, centres = cv2.findCirclesGrid(grey, (self.cols, self.rows), flags=grid)
        if not found:
            return None
        return self._detection(centres, np.arange(self.cols * self.rows))

    def _detect_charuco(self, grey: np.ndarray) -> Detection | None:
        detector = cv2.aruco.CharucoDetector(self._charuco_board())
        corners, ids, _, _ = detector.detectBoard(grey)
        if ids is None or len(ids) < 6:  # fewer points cannot constrain a pose and the intrinsics
            return None
        # CharucoDetector refines corners itself; a second cornerSubPix would reach into the markers
        return self._detection(corners, ids)


def board_in_view(grey: np.ndarray, size: tuple[int, int]) -> bool:
    """OpenCV's quick check for a chessboard of `size` inner corners, on a quarter-size copy, then a half-size
    one, then the frame itself, until one sees a board: a reduced copy costs a fraction of the full check (which
    on a 1280x720 frame cost more than the detection itself), and the full-size check misses printed boards
    whose black squares stop short of the grid: their white squares touch across the corners by bridges a few
    pixels wide, which its one-pixel erosion does not cut (82 of 454 frames of a real phone video that the
    detector finds; 5 at a quarter size, where the bridges are under a pixel)."""
    for factor in (4, 2):
        if min(grey.shape[:2]) // factor >= MIN_CHECK_SIDE:
            reduced = cv2.resize(grey, (grey.shape[1] // factor, grey.shape[0] // factor), interpolation=cv2.INTER_AREA)
            if cv2.checkChessboard(reduced, size):
                return True
    return bool(cv2.checkChessboard(grey, size))


MIN_CHECK_SIDE = 180  # a reduced copy smaller than this is not checked (a board's squares would be a few pixels)


def to_grey(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim != 2:
        raise ValueError(f"expected a grey or BGR image, got shape {image.shape}")
    return image


def nearest_spacing(points: np.ndarray) -> float:
    """Smallest distance between two detected points, pixels."""
    diff = points[:, None, :] - points[None, :, :]
    dist = np.hypot(diff[..., 0], diff[..., 1])
    np.fill_diagonal(dist, np.inf)
    return float(dist.min())


def refine_corners(grey: np.ndarray, corners: np.ndarray, spacing: float) -> np.ndarray:
    """Sub-pixel saddle refinement with a window that stays inside one square."""
    half = int(np.clip(0.4 * spacing, 2, 11))  # 11 is OpenCV's usual choice at 640x480
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    refined = cv2.cornerSubPix(grey, corners.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), criteria)
    return refined.reshape(-1, 2).astype(np.float64)


DETECT_MAX_SIDE = 1600  # larger frames are searched at a reduced size, the points refined at full size


def detect_scaled(board: BoardSpec, image: np.ndarray, max_side: int = DETECT_MAX_SIDE) -> Detection | None:
    """`board.detect` on a copy reduced to at most `max_side` pixels (a 3872x2592 frame: 1/3), the points
    then refined on the full frame: the live node looks at a 10-megapixel frame in a fraction of the time
    (the search dominates; the refinement is local). Frames that fit are searched as they are."""
    factor = int(np.ceil(max(image.shape[:2]) / max_side))
    if factor <= 1:
        return board.detect(image)
    grey = to_grey(image)
    small = cv2.resize(grey, (grey.shape[1] // factor, grey.shape[0] // factor), interpolation=cv2.INTER_AREA)
    found = board.detect(small)
    if found is None:
        return None
    points = (found.image_points + 0.5) * factor - 0.5  # pixel centres of the reduced image, in full pixels
    if board.kind != "circles":  # saddle points: refined within a window that stays inside one square
        points = refine_corners(grey, points, nearest_spacing(points) * (0.5 if board.kind == "charuco" else 1.0))
    return Detection(points, found.object_points, found.ids, found.inverted)
