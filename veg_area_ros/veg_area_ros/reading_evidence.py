"""Which reading a camera's frames are measured with by default, judged on its calibration views. No ROS here.

Two readings of an edge: each edge pixel's share of the object (sub-pixel), or whole pixels counted (the
paper's method). On a render the shares are exact at any edge phase; real photos' edges carry what a render
has not (JPEG blocks, ink bleeding, a print's sheen), and on some cameras the shares scatter more between
photos than a count does (halves of OpenCV's webcam photos, Udacity's camera), on others less (a GoPro, a
machine-vision camera behind a dome). A chessboard's views are measurements with a known answer, so a camera's
own views say which reads it better: each view is measured both ways, the shares with the edge trend learned
from the other views alone (as a frame measured with the file is), and the reading whose errors spread the
less over the views is recorded. Counting is the reference the default must never be worse than, so it is
taken wherever the shares do not read the views better; with fewer than MIN_VIEWS views nothing is recorded
(frames are read with the shares, exact on renders).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .edge_trend import ViewEdge, fit_edge_trend

MIN_VIEWS = 3  # a spread over two views is one difference: no evidence of a camera's reading
SHARES, COUNT = "subpixel", "count"


@dataclass(frozen=True)
class ViewReading:
    """One view measured both ways: its relative error in the default mode (the shares where they were
    applied) and counted, and, where the shares were applied, its edge (edge_trend) with how many px of edge
    offset make one unit of relative error."""

    name: str
    default_error: float
    count_error: float
    edge: ViewEdge | None = None
    offset_px_per_error: float = 0.0


@dataclass
class ReadingChoice:
    """The reading taken, why, and the evidence: per reading, the views' errors' spread (relative)."""

    mode: str
    decided: bool  # False: too few views; `mode` is then the shares, the default without evidence
    reason: str
    views: int = 0
    spreads: dict[str, float] = field(default_factory=dict)
    errors: dict[str, list[float]] = field(default_factory=dict)  # per reading, each view's error as judged
    names: list[str] = field(default_factory=list)

    def metadata(self) -> dict:
        """What a calibration file records: the reading where decided (what measuring with area mode auto, the
        default, reads frames with) and why."""
        recorded: dict = {"area_mode_evidence": self.reason}
        if self.decided:
            recorded["area_mode"] = self.mode
        return recorded

    def as_dict(self) -> dict:
        return {"mode": self.mode, "decided": self.decided, "reason": self.reason, "views": self.views,
                "spread_percent": {mode: round(100 * s, 3) for mode, s in self.spreads.items()}}


def trend_corrected(readings: list[ViewReading], tone_curve: str) -> np.ndarray:
    """Each view's error in the default mode with its edges moved back by the trend the other views alone
    show (where its shares were applied and a trend, or its neighbours' residuals, moves a frame)."""
    errors = np.array([r.default_error for r in readings], float)
    for i, reading in enumerate(readings):
        if reading.edge is None or reading.offset_px_per_error <= 0:
            continue
        others = [r.edge for j, r in enumerate(readings) if j != i and r.edge is not None]
        trend = fit_edge_trend([e.offset_px for e in others], [e.white_dn for e in others], tone_curve,
                               [e.std_px for e in others], [e.scale_px_per_m for e in others]).trend
        if trend is not None:
            errors[i] -= trend.offset_px(reading.edge.white_dn)[0] / reading.offset_px_per_error
    return errors


def choose_reading(readings: list[ViewReading], tone_curve: str) -> ReadingChoice:
    """The reading whose errors spread the less over the views (the count where the shares do not do
    better), measured as module's docstring says."""
    n = len(readings)
    if n < MIN_VIEWS:
        return ReadingChoice(SHARES, False, f"not judged: {MIN_VIEWS} or more views of the whole chessboard (or "
                                            f"a ChArUco board's rectangle of corners), whites not clipped, tell "
                                            f"the readings apart; {n} could be measured",
                             n)
    errors = {SHARES: trend_corrected(readings, tone_curve).tolist(), COUNT: [r.count_error for r in readings]}
    spreads = {mode: float(np.std(values, ddof=1)) for mode, values in errors.items()}
    mode = SHARES if spreads[SHARES] < spreads[COUNT] else COUNT
    described = (f"the board's black area in {n} views spreads {100 * spreads[SHARES]:.2f} % read with the shares "
                 f"(each with the edge trend of the other views) and {100 * spreads[COUNT]:.2f} % counted")
    reason = (f"{described}: the shares read this camera's photos better" if mode == SHARES else
              f"{described}: whole pixels are counted, as the shares do not read this camera's photos better")
    return ReadingChoice(mode, True, reason, n, spreads, errors, [r.name for r in readings])
