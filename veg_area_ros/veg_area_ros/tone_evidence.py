"""Which tone curve a camera encodes light with, judged on its own calibration views. No ROS here.

A JPEG's grey levels are encoded light (most cameras: the sRGB curve). An edge blurred in light is not blurred
symmetrically in encoded levels, so read with the wrong curve every edge moves a fixed fraction of a pixel
towards one side, and the error in an area goes as one over the object's size in pixels. A chessboard seen at
several distances shows it: the black area inside the rectangle through its outer squares' centres is known
(the board's squares; on a ChArUco board the squares and the markers as the board's drawing has them, inside the
largest rectangle of corners the view found), so each view is a measurement with a known answer; under the
camera's curve the views
from afar read as the near ones, under another they drift with 1/(pixels per square). The curve whose drift is
clearly the smaller is taken; views too alike in distance cannot tell the curves apart, and the result says so.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from .area import AreaMeasurer
from .area_result import AreaResult
from .board import BoardSpec, Detection, to_grey
from .camera_model import BrownCamera
from .classify import AREA_MODES, TONE_CURVES
from .edge_trend import TrendChoice, ViewEdge, fit_edge_trend
from .reading_evidence import MIN_VIEWS as MIN_READING_VIEWS
from .reading_evidence import ReadingChoice, ViewReading, choose_reading
from .settings import MeasurementSettings
from .targets import TargetsSpec

MAX_VIEWS = 24  # views the tone curve is judged on, evenly over sizes: about 1.5 s each at 10 MP (both curves)
MAX_TREND_VIEWS = 48  # views measured for how the edges follow exposure (edge_trend): the bright few show a shoulder
MIN_VIEWS = 6  # a slope and its scatter need a few more views than its two parameters
MIN_SIZE_RATIO = 1.3  # nearest to farthest board (pixels per square): below it the views cannot tell curves apart
# what moves a board's area by more than the curves do (burnt-out whites: 1-5 % low; no object found: all of
# it); crushed blacks, common in action cameras' JPEGs, move every view alike and stay in
SPOILS_THE_EVIDENCE = ("clipped highlights", "the ROI reaches beyond the image", "no object found")
DECISIVE_SIGMA = 3.0  # one curve's drift smaller than the other's by this many combined standard errors
MAX_KEPT_BYTES = 256 * 2**20  # a live calibration's kept frames, PNG: a few hundred views of 10 MP
CASE_KINDS = ("chessboard", "charuco")  # boards whose dark area inside a rectangle of their corners is known
# a ChArUco marker's cells below this (px) lose their interiors: the levels go unread, the view is counted, and
# the count's threshold moves every one of the many cell edges alike (renders: -3 to -6 % at 2.6-4 px a cell,
# the shares within 0.2 % from 4.3 px where they apply)
MIN_CELL_PX = 5.5


@dataclass
class BoardCase:
    """One view of a chessboard as an Af measurement with a known answer."""

    name: str
    targets: TargetsSpec  # the rectangle's four corners (a chessboard's outer inner corners), in board metres
    roi: np.ndarray  # (4, 2) idealized px: the rectangle through the centres of the squares `inset` in
    square_px: float  # idealized pixels per square: the board's size in the image
    first_black_probe: np.ndarray  # (2, 2) raw px: the rectangle's corner square at the first corner, and its neighbour
    inset: int = 0  # 0: the rectangle through the outer squares' centres; 1: one square further in
    drawn: tuple[float, float] | None = None  # a ChArUco board's (dark area m², edges m) inside the rectangle

    def known_area_m2(self, board: BoardSpec, grey: np.ndarray) -> float:
        """The print's dark area inside the rectangle: drawn (ChArUco), or the chessboard's squares with the
        first one's colour read in the view's grey image."""
        return self.drawn[0] if self.drawn is not None else self.true_area_m2(board, self.first_black(grey))

    def known_edge_m(self, board: BoardSpec) -> float:
        """The dark area's edges inside the rectangle (m)."""
        return self.drawn[1] if self.drawn is not None else self.edge_length_m(board)

    def true_area_m2(self, board: BoardSpec, first_black: bool) -> float:
        """The black squares' area inside the rectangle: quarter squares at its corners, halves along its sides."""
        total = 0.0
        first, last_col, last_row = self.inset, board.cols - self.inset, board.rows - self.inset
        for i in range(first, last_col + 1):
            for j in range(first, last_row + 1):
                if ((i + j) % 2 == 0) == first_black:
                    total += (0.5 if i in (first, last_col) else 1.0) * (0.5 if j in (first, last_row) else 1.0)
        return total * board.square**2

    def edge_length_m(self, board: BoardSpec) -> float:
        """The black squares' edges inside the rectangle: every inner grid line within it, whole (m)."""
        return 2.0 * (board.cols - 2 * self.inset) * (board.rows - 2 * self.inset) * board.square

    def first_black(self, grey: np.ndarray) -> bool:
        """Whether the outer square at the first corner is the black one, read in the view's grey image."""
        values = [float(grey[round(v), round(u)]) for u, v in self.first_black_probe]
        return values[0] < values[1]


def board_case(name: str, detection: Detection, board: BoardSpec, camera: BrownCamera, inside_only: bool = True
               ) -> BoardCase | None:
    """The view as a measurement, or None where it cannot be one: not a full chessboard (a ChArUco board: no
    rectangle of corners found at its four corners), or (`inside_only`) the rectangle or the probe of the first
    square's colour reaching beyond the image. With `inside_only`, a chessboard whose outer squares reach the
    image's edge is measured one square further in, where the board has room (a board filling the frame is
    still evidence); a ChArUco board inside its largest rectangle of found corners that lies in the image."""
    if board.kind == "charuco":
        rectangles = corner_rectangles(board, detection.ids)
        if not rectangles or (placement := _Placement.of(detection, board, camera)) is None:
            return None
        return next((case for rectangle in rectangles
                     if (case := _board_case(name, placement, rectangle, 0, inside_only)) is not None), None)
    if not could_be_case(board, detection) or (placement := _Placement.of(detection, board, camera)) is None:
        return None
    cols, rows = board.corner_grid()
    whole = (0, 0, cols - 1, rows - 1)
    if not inside_only:
        return _board_case(name, placement, whole, 0, False)
    return next((case for inset in (0, 1) if min(board.cols, board.rows) > 2 * inset + 1
                 and (case := _board_case(name, placement, whole, inset, True)) is not None), None)


def corner_rectangles(board: BoardSpec, ids: Iterable[int]) -> list[tuple[int, int, int, int]]:
    """The rectangles of the board's corner grid (first column, first row, last column, last row) whose four
    corners are among `ids`, largest first (a ChArUco board is often found in part)."""
    cols, rows = board.corner_grid()
    found = {int(i) for i in np.ravel(list(ids))}
    rectangles = [(c0, r0, c1, r1) for c0, c1 in itertools.combinations(range(cols), 2)
                  for r0, r1 in itertools.combinations(range(rows), 2)
                  if {r0 * cols + c0, r0 * cols + c1, r1 * cols + c1, r1 * cols + c0} <= found]
    return sorted(rectangles, key=lambda r: (-(r[2] - r[0] + 1) * (r[3] - r[1] + 1), r))


@dataclass(frozen=True)
class _Placement:
    """A view's board points as the rectangles of its corners need them, computed once for all of them."""
    detection: Detection
    board: BoardSpec
    camera: BrownCamera
    ids: np.ndarray
    squares: np.ndarray  # board coordinates in squares
    raw: np.ndarray  # raw pixels
    homography: np.ndarray  # board squares -> idealized pixels

    @classmethod
    def of(cls, detection: Detection, board: BoardSpec, camera: BrownCamera) -> _Placement | None:
        squares = np.asarray(detection.object_points, float)[:, :2] / board.square
        raw = np.asarray(detection.image_points, float).reshape(-1, 2)
        idealized = camera.ideal().normalized_to_pixels(camera.pixels_to_normalized(raw))
        homography, _ = cv2.findHomography(squares.astype(np.float32), idealized.astype(np.float32))
        if homography is None:
            return None
        return cls(detection, board, camera, np.asarray(detection.ids).ravel(), squares, raw, homography)


def _board_case(name: str, placement: _Placement, rectangle: tuple[int, int, int, int], inset: int,
                inside_only: bool) -> BoardCase | None:
    """The view measured inside the rectangle through the centres of the squares around `rectangle`'s corners
    (`inset` squares further in)."""
    board, camera, homography = placement.board, placement.camera, placement.homography
    ideal = camera.ideal()
    cols = board.corner_grid()[0]
    c0, r0, c1, r1 = rectangle
    points, inside = [], []
    for corner in (r0 * cols + c0, r0 * cols + c1, r1 * cols + c1, r1 * cols + c0):
        k = int(np.flatnonzero(placement.ids == corner)[0])
        points.append({"pixel": placement.raw[k].tolist(), "plane": (placement.squares[k] * board.square).tolist()})
        inside.append(placement.squares[k])
    targets = TargetsSpec.from_dict({"points": points, "pixel_std": 0.1})
    (x0, y0), (x1, y1) = np.min(inside, axis=0) - 0.5 + inset, np.max(inside, axis=0) + 0.5 - inset

    def placed(board_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Board points in idealized and in raw pixels."""
        image = cv2.perspectiveTransform(np.float32(board_points).reshape(-1, 1, 2), homography).reshape(-1, 2)
        return image, camera.normalized_to_pixels(ideal.pixels_to_normalized(image.astype(float)))

    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    roi, _ = placed(corners)
    sx, sy = inside[0]
    _, probe = placed(np.array([[sx - 0.5 + inset, sy - 0.5 + inset], [sx + 0.5 + inset, sy - 0.5 + inset]]))
    # the rectangle's outline, sampled, must lie inside the idealized image (a wide lens's is cropped) and
    # have raw pixels behind it (the lens bends its sides outwards), the probe too
    t = np.linspace(0, 1, 16, endpoint=False)[:, None]
    outline = np.concatenate([a + t * (b - a) for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True)])
    idealized_outline, raw_outline = placed(outline)
    if inside_only and not (_within(idealized_outline, camera, 0)
                            and _within(np.concatenate([raw_outline, probe]), camera, 2)):
        return None
    square_px = math.sqrt(cv2.contourArea(np.float32(roi)) / ((x1 - x0) * (y1 - y0)))
    if board.kind == "charuco" and inside_only and square_px * board.marker_cell() / board.square < MIN_CELL_PX:
        return None
    drawn = (_drawn_dark(board, (float(x0), float(y0), float(x1), float(y1)), placement.detection.inverted)
             if board.kind == "charuco" else None)
    return BoardCase(name, targets, roi, square_px, probe, inset, drawn)


@functools.lru_cache(maxsize=4)
def _dark_cells(board: BoardSpec) -> np.ndarray:
    """The board's dark rectangles (BoardSpec.dark_cells) in squares, to a millionth (OpenCV places the markers
    in single precision: a side meant on a rectangle's side would otherwise lie a hair beside it)."""
    return np.round(board.dark_cells() / board.square, 6)


@functools.lru_cache(maxsize=256)  # a calibration's views share a few rectangles, most the whole board
def _drawn_dark(board: BoardSpec, rectangle: tuple[float, float, float, float], inverted: bool
                ) -> tuple[float, float]:
    """(dark area m², its edges' length m) of a ChArUco board's print inside `rectangle` (board squares),
    exact: on the grid of every cell's and the rectangle's sides, each grid cell is dark or light, each side
    between two unlike ones an edge. A print found inverted (white on black) is dark where the drawing is
    light, the board's own margin too."""
    cells = _dark_cells(board)
    x0, y0, x1, y1 = rectangle

    def grid(low: float, high: float, sides: np.ndarray) -> np.ndarray:
        inside = sides[(sides > low) & (sides < high)]
        return np.unique(np.round(np.concatenate([[low, high], inside]), 9))

    xs, ys = grid(x0, x1, cells[:, [0, 2]].ravel()), grid(y0, y1, cells[:, [1, 3]].ravel())
    dark = np.zeros((len(ys) - 1, len(xs) - 1), bool)
    centres_x, centres_y = (xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2
    for cx0, cy0, cx1, cy1 in cells:
        dark[np.ix_((centres_y > cy0) & (centres_y < cy1), (centres_x > cx0) & (centres_x < cx1))] = True
    dark ^= inverted
    widths, heights = np.diff(xs), np.diff(ys)
    area = float(heights @ dark @ widths)
    edges = float(np.sum((dark[:, 1:] != dark[:, :-1]) * heights[:, None])
                  + np.sum((dark[1:] != dark[:-1]) * widths[None, :]))
    return area * board.square**2, edges * board.square


def could_be_case(board: BoardSpec, detection: Detection) -> bool:
    """Whether a view's board can be a measurement in some camera (board_case without the image's bounds)."""
    if board.kind == "charuco":
        return bool(corner_rectangles(board, detection.ids))
    return board.kind == "chessboard" and len(detection) == math.prod(board.corner_grid())


def _within(points: np.ndarray, camera: BrownCamera, margin: float) -> bool:
    """Whether every point lies in the camera's image, `margin` px inside its outer pixels' centres."""
    return bool(np.all(np.isfinite(points)) and points.min() >= margin
                and np.all(points[:, 0] <= camera.width - 1 - margin)
                and np.all(points[:, 1] <= camera.height - 1 - margin))


@dataclass
class ToneChoice:
    """The curve taken, why, and the evidence: per curve, the slope of the views' relative error against
    1/(pixels per square) and its standard error."""

    curve: str  # one of TONE_CURVES
    decided: bool  # False: the views could not tell the curves apart; `curve` is then the linear default
    reason: str
    views: int = 0
    square_px: tuple[float, float] = (math.nan, math.nan)
    slopes: dict[str, dict[str, float]] = field(default_factory=dict)
    left_out: dict[str, str] = field(default_factory=dict)  # view name -> why it was not measured
    sizes: list[float] = field(default_factory=list)  # each measured view's px per square
    errors: dict[str, list[float]] = field(default_factory=dict)  # per curve, each view's relative error
    edges: dict[str, list[ViewEdge]] = field(default_factory=dict)  # per curve, the views whose shares were used
    edge_trend: TrendChoice | None = None  # how the edges follow exposure under the curve taken (edge_trend)
    readings: dict[str, list[ViewReading]] = field(default_factory=dict)  # per curve, each view read both ways
    reading: ReadingChoice | None = None  # the shares or the count, judged under the curve taken (reading_evidence)

    def metadata(self) -> dict:
        """What a calibration file records of this judgement: the curve where decided (what measuring with
        tone curve auto, the default, reads frames with), the edges' trend with exposure where learned, the
        reading (shares or count) area mode auto takes, and why."""
        recorded: dict = {"tone_curve_evidence": self.reason}
        if self.decided:
            recorded["tone_curve"] = self.curve
        if self.edge_trend is not None:
            recorded["edge_trend_evidence"] = self.edge_trend.reason
            if self.edge_trend.trend is not None:
                recorded["edge_trend"] = self.edge_trend.trend.as_dict()
        if self.reading is not None:
            recorded.update(self.reading.metadata())
        return recorded

    def as_dict(self) -> dict:
        return {"curve": self.curve, "decided": self.decided, "reason": self.reason, "views": self.views,
                "square_px": [round(float(s), 1) for s in self.square_px],
                "slopes": {c: {k: round(float(v), 4) for k, v in s.items()} for c, s in self.slopes.items()},
                "left_out": len(self.left_out),
                "edge_trend": (None if self.edge_trend is None else
                               {"learned": self.edge_trend.trend is not None and self.edge_trend.trend.learned,
                                "reason": self.edge_trend.reason}),
                "reading": None if self.reading is None else self.reading.as_dict()}


def spread_by_size(cases: list[BoardCase], count: int = MAX_VIEWS) -> list[BoardCase]:
    """At most `count` of the cases, evenly over their board sizes (nearest and farthest always kept)."""
    ordered = sorted(cases, key=lambda case: case.square_px)
    if len(ordered) <= count:
        return ordered
    return [ordered[round(k)] for k in np.linspace(0, len(ordered) - 1, count)]


def chosen_cases(views: Iterable, board: BoardSpec, camera: BrownCamera) -> list[BoardCase]:
    """The views (calibration.View) that can be measurements, at most MAX_TREND_VIEWS evenly over their sizes."""
    return spread_by_size([case for view in views
                           if (case := board_case(view.name, view.detection, board, camera)) is not None],
                          MAX_TREND_VIEWS)


def judged_first(cases: list[BoardCase]) -> tuple[list[BoardCase], set[str]]:
    """(the cases with those the tone curve is judged on first, their names): at most MAX_VIEWS evenly over the
    sizes. Read in this order, the others are read under the curve taken only (judged_tone_curve)."""
    judged = {case.name for case in spread_by_size(cases)}
    return sorted(cases, key=lambda case: case.name not in judged), judged


@dataclass
class KeptFrames:
    """The grey frames of the views a live calibration keeps (the calibration node; `veg-area calibrate` reads
    its files again instead), PNG-encoded (lossless) until its fit judges the tone curve on them. Frames whose
    board cannot be a measurement (not a whole chessboard; a ChArUco board without a rectangle of found corners)
    are not kept; past MAX_KEPT_BYTES none are, and the judgement says so."""

    board: BoardSpec
    frames: dict[str, bytes] = field(default_factory=dict)
    size: int = 0
    over_budget: int = 0

    def offer(self, name: str, detection: Detection, image: np.ndarray) -> None:
        if not could_be_case(self.board, detection):
            return
        if self.size >= MAX_KEPT_BYTES:
            self.over_budget += 1
            return
        encoded, png = cv2.imencode(".png", to_grey(image), [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if encoded:
            self.frames[name] = png.tobytes()
            self.size += len(self.frames[name])

    def judge(self, views: Iterable, camera: BrownCamera) -> ToneChoice:
        """The tone curve judged on the kept frames of `views` (calibration.View)."""
        cases, judged = judged_first(chosen_cases([view for view in views if view.name in self.frames],
                                                  self.board, camera))
        pairs = ((case, cv2.imdecode(np.frombuffer(self.frames[case.name], np.uint8), cv2.IMREAD_GRAYSCALE))
                 for case in cases)
        choice = choose_tone_curve(pairs if len(cases) >= MIN_READING_VIEWS else iter(()), self.board, camera,
                                   judged)
        if self.over_budget:
            choice.reason += f" ({self.over_budget} views past the first {len(self.frames)} kept no frame)"
        return choice


def _slope(errors: np.ndarray, inverse_size: np.ndarray) -> tuple[float, float]:
    """Least-squares slope of errors against 1/size (with an intercept: the ink's gain), and its standard error."""
    design = np.column_stack([np.ones_like(inverse_size), inverse_size])
    coef, *_ = np.linalg.lstsq(design, errors, rcond=None)
    residual = errors - design @ coef
    variance = float(residual @ residual) / max(len(errors) - 2, 1)
    return float(coef[1]), math.sqrt(variance * float(np.linalg.inv(design.T @ design)[1, 1]))


def choose_tone_curve(cases: Iterable[tuple[BoardCase, np.ndarray]], board: BoardSpec, camera: BrownCamera,
                      judged: set[str] | None = None) -> ToneChoice:
    """The tone curve judged on the views (`judged_tone_curve`; on those named in `judged`, or all), how the
    edges follow exposure under it (edge_trend) and which reading reads them better (reading_evidence), on all of
    them: each view's error over the board's edge length inside the rectangle is how far it moved its edges."""
    choice = judged_tone_curve(cases, board, camera, judged)
    if board.kind in CASE_KINDS:
        edges = choice.edges.get(choice.curve, [])
        choice.edge_trend = fit_edge_trend([e.offset_px for e in edges], [e.white_dn for e in edges], choice.curve,
                                           [e.std_px for e in edges], [e.scale_px_per_m for e in edges])
        choice.reading = choose_reading(choice.readings.get(choice.curve, []), choice.curve)
    return choice


def judged_tone_curve(cases: Iterable[tuple[BoardCase, np.ndarray]], board: BoardSpec, camera: BrownCamera,
                      judged: set[str] | None = None) -> ToneChoice:
    """Measure each (case, grey image) under every tone curve (taken one at a time: a reader's generator keeps
    one frame in memory), in the default sub-pixel mode at Otsu's threshold (what frames are measured with; the
    count in light scatters more on some webcams' photos: 1.3 % against 0.5 %), and take the curve under which
    the error does not drift with the board's size, where the other's clearly does. Views with clipped
    highlights, no object found or the ROI beyond the image are left out. With `judged`, only the views it
    names judge the curve (MAX_VIEWS of them); the others are evidence of the edges only, read under the curve
    taken once every judged view has been read (so under both curves only where they come before)."""
    if board.kind not in CASE_KINDS:
        return ToneChoice("linear", False, f"not judged: the tone curve is read from a chessboard's or a ChArUco "
                                           f"board's squares, the views show a {board.kind} board")
    errors: dict[str, list[float]] = {curve: [] for curve in TONE_CURVES}
    edges: dict[str, list[ViewEdge]] = {curve: [] for curve in TONE_CURVES}
    readings: dict[str, list[ViewReading]] = {curve: [] for curve in TONE_CURVES}
    sizes: list[float] = []
    left_out: dict[str, str] = {}
    choice = ToneChoice("linear", False, "", left_out=left_out, sizes=sizes, errors=errors, edges=edges,
                        readings=readings)
    waiting = None if judged is None else set(judged)  # judged views not read yet
    decided = False
    shared = _SharedCameraWork(camera)
    for case, grey in cases:
        judging = judged is None or case.name in judged
        curves = TONE_CURVES if judging or not decided else (choice.curve,)
        measured = _measured(case, grey, board, shared, curves, left_out)
        if measured is not None:
            for curve, reading in measured.items():
                readings[curve].append(reading)
                if reading.edge is not None:
                    edges[curve].append(reading.edge)
            if judging:
                for curve, reading in measured.items():
                    errors[curve].append(reading.default_error)
                sizes.append(case.square_px)
        if waiting is not None:
            waiting.discard(case.name)
            if not waiting and not decided:
                _decide(choice)
                decided = True
    if not decided:
        _decide(choice)
    return choice


@dataclass
class _SharedCameraWork:
    """The views' measurers, each taking over the camera's own work from the one before (its idealizing maps and
    pixel geometry: MeasurementSettings.measurer's `previous`), built once instead of for every measurement; the
    measurers of one view (both curves, both readings: the same targets and ROI) also share its pixel weights,
    which neither the curve nor the reading changes (half the judgement's time went on building them again)."""
    camera: BrownCamera
    last: AreaMeasurer | None = None

    def measure(self, grey: np.ndarray, targets: TargetsSpec, curve: str, roi: np.ndarray, mode: str) -> AreaResult:
        settings = MeasurementSettings(threshold="otsu", roi=tuple(np.ravel(roi)), area_mode=mode, tone_curve=curve)
        previous = self.last
        self.last = settings.measurer(self.camera, targets, previous=previous)
        if (isinstance(previous, AreaMeasurer) and previous.targets is targets
                and np.array_equal(previous.region.user_polygon, self.last.region.user_polygon)):
            self.last.carried.weights = previous.carried.weights  # the same view
        return self.last.measure(grey)


def _measured(case: BoardCase, grey: np.ndarray, board: BoardSpec, shared: _SharedCameraWork,
              curves: Iterable[str], left_out: dict[str, str]) -> dict[str, ViewReading] | None:
    """Per curve, the view read both ways: its relative error in the default mode and its edge (where the shares
    were applied), and counted; None where the view is no case (said in `left_out`)."""
    truth = case.known_area_m2(board, grey)
    # the error over the edges' length is how far they moved (m), in the view's idealized px
    px_per_m2 = case.square_px / board.square / case.known_edge_m(board)
    # the board's squares exact, as the calibration takes them: an error of the print's scale is every view's
    # alike, so it is no part of a view's own std, against which the views' scatter is judged
    targets = replace(case.targets, distance_std_m=0.0)
    measured = {}
    for curve in curves:
        try:
            result, counted = (shared.measure(grey, targets, curve, case.roi, mode) for mode in AREA_MODES)
        except ValueError as exc:  # targets, light, a frame the measurement refuses: the view is no case
            left_out[case.name] = f"{curve}: {exc}"
            return None
        spoiled = [w for w in result.warnings if w.startswith(SPOILS_THE_EVIDENCE)]
        if spoiled:
            left_out[case.name] = f"{curve}: {spoiled[0]}"
            return None
        levels = result.levels
        # the views whose shares were applied, with their white level: the trend is applied to such frames
        edge = (None if levels is None or not result.subpixel_applied else
                ViewEdge(case.name, (result.area_m2 - truth) * px_per_m2, max(levels.object, levels.background),
                         result.area_std_m2 * px_per_m2, case.square_px / board.square))
        measured[curve] = ViewReading(case.name, result.area_m2 / truth - 1, counted.area_m2 / truth - 1, edge,
                                      px_per_m2 * truth)
    return measured


def _decide(choice: ToneChoice) -> None:
    """The curve taken on the judged views' errors against their sizes, and why, into `choice`."""
    sizes, errors = choice.sizes, choice.errors
    n = choice.views = len(sizes)
    span = choice.square_px = (min(sizes), max(sizes)) if sizes else (math.nan, math.nan)
    if n < MIN_VIEWS:
        choice.reason = (f"not judged: {MIN_VIEWS} or more views of the whole chessboard inside the image (all "
                         "but its outer squares will do; of a ChArUco board, a rectangle of its corners, its "
                         f"markers' cells {MIN_CELL_PX:g} px or more), "
                         f"whites not clipped, near and far, tell the curves apart; {n} could be measured")
        return
    inverse = 1.0 / np.array(sizes)
    for curve in TONE_CURVES:
        slope, error = _slope(np.array(errors[curve]), inverse)
        choice.slopes[curve] = {"slope": slope, "std": error, "spread": float(np.std(errors[curve], ddof=1))}
    if span[1] / span[0] < MIN_SIZE_RATIO:
        choice.reason = (f"not judged: the boards span {span[0]:.0f}-{span[1]:.0f} px per square, too alike in "
                         "distance to tell the curves apart (photograph the board near and far)")
        return
    best, other = sorted(TONE_CURVES, key=lambda c: abs(choice.slopes[c]["slope"]))[:2]
    gap = abs(choice.slopes[other]["slope"]) - abs(choice.slopes[best]["slope"])
    combined = math.hypot(choice.slopes[best]["std"], choice.slopes[other]["std"])
    reach = 1 / span[0] - 1 / span[1]  # the farthest view against the nearest, in 1/(px per square)
    described = "; ".join(f"{c} {100 * s['slope'] * reach:+.2f} +/- {100 * s['std'] * reach:.2f} %" for c, s in
                          choice.slopes.items())
    if gap <= DECISIVE_SIGMA * combined:
        choice.reason = (f"not told apart: the farthest of {n} views ({span[0]:.0f} px per square) reads against the "
                         f"nearest ({span[1]:.0f} px) about alike under both curves ({described}); linear kept")
        return
    choice.curve, choice.decided = best, True
    choice.reason = (f"the board's black area in the farthest of {n} views ({span[0]:.0f} px per square) reads "
                     f"against the nearest ({span[1]:.0f} px): {described}; {best} drifts the least")
