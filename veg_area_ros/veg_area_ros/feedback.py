"""The calibration node's `~/feedback` image: what the person topside should see while a diver holds the board.
The live frame (at most 1280 px wide) with the detected points, the image cells the kept views cover, a bar per
kind of variety, views kept and rejected with their reasons, and one line saying what is still needed; once
fitted, the RMS, the std of c, xp and yp, the projection uncertainty over the image and the newest view's
residuals. Drawn with OpenCV primitives: a few milliseconds a frame.

No ROS here.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .camera_model import BrownCamera
from .guidance import GOALS, CalibrationGuide, Verdict

MAX_WIDTH = 1280
PANEL_WIDTH = 330
KEPT_COLOUR = (60, 200, 60)  # BGR
REJECTED_COLOUR = (40, 40, 230)
SIMILAR_COLOUR = (0, 200, 230)
COVERED_COLOUR = (80, 200, 80)
FONT = cv2.FONT_HERSHEY_SIMPLEX


@dataclass
class FitView:
    """What a fit shows on the feedback image."""

    rms_px: float
    std: dict[str, float]  # PARAM_NAMES -> 1 std
    projection: dict  # calibration.projection_std: grid points and their std in px
    newest_points: np.ndarray | None = None  # the newest kept view's points (raw pixels) ...
    newest_residuals: np.ndarray | None = None  # ... and its residuals (px)
    reach: tuple[float, float, float, float] | None = None  # a folding model holds inside: (cx, cy, rx, ry) raw px


def fit_reach(camera: BrownCamera) -> tuple[float, float, float, float] | None:
    """Where a fitted model that folds inside the frame holds, for `FitView.reach`; None where it holds over all."""
    if camera.holds_everywhere():
        return None
    radius = camera.reach[1]
    return camera.xp, camera.yp, radius * camera.fx, radius * camera.fy


def render_feedback(image: np.ndarray, guide: CalibrationGuide, points: np.ndarray | None = None,
                    verdict: Verdict | None = None, fit: FitView | None = None) -> np.ndarray:
    """The feedback image (BGR uint8) for the frame just judged: `points` its detected board points (raw
    pixels, None when no board was found) and `verdict` what became of it."""
    frame = image if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    scale = min(1.0, MAX_WIDTH / frame.shape[1])
    # a copy to draw on: the large camera's frame shrunk to at most MAX_WIDTH
    frame = (cv2.resize(frame, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1.0
             else frame.copy())
    height, width = frame.shape[:2]
    _draw_coverage(frame, guide.covered)
    if fit is not None and fit.projection.get("points"):
        _draw_uncertainty(frame, fit.projection, scale)
    if fit is not None and fit.reach is not None:  # where the fitted model stops holding: cover it, or change model
        cx, cy, rx, ry = (value * scale for value in fit.reach)
        cv2.ellipse(frame, (round(cx), round(cy)), (round(rx), round(ry)), 0, 0, 360, (0, 140, 255), 2, cv2.LINE_AA)
        _text(frame, "the model holds inside", (round(cx - rx / 3), round(cy + ry) - 8), (0, 140, 255), scale=0.45)
    if points is not None:
        colour = (KEPT_COLOUR if verdict is None or verdict.kept
                  else SIMILAR_COLOUR if verdict.kind == "similar" else REJECTED_COLOUR)
        radius = max(2, round(3 * max(1.0, width / 640)))
        for x, y in np.asarray(points).reshape(-1, 2) * scale:
            cv2.circle(frame, (round(float(x)), round(float(y))), radius, colour, 1, cv2.LINE_AA)
    if fit is not None and fit.newest_points is not None and fit.newest_residuals is not None:
        for (x, y), (dx, dy) in zip(fit.newest_points * scale, fit.newest_residuals * 50 * scale, strict=True):
            cv2.arrowedLine(frame, (round(float(x)), round(float(y))), (round(float(x + dx)), round(float(y + dy))),
                            (255, 0, 255), 1, cv2.LINE_AA, tipLength=0.3)
    needed = guide.still_needed()
    banner = (verdict.reason if verdict is not None and not verdict.kept and verdict.kind != "similar" else "")
    if fit is not None:
        _banner(frame, f"calibrated: RMS {fit.rms_px:.3f} px (~/calibrate collects more views and fits again)",
                (30, 110, 30))
    else:
        _banner(frame, needed or "enough variety: ready to calibrate", (40, 40, 40) if needed else (30, 110, 30))
    if banner:
        _text(frame, f"rejected: {banner}", (8, height - 40), REJECTED_COLOUR, scale=0.45)
    panel = _panel(guide, verdict, fit, height)
    return np.hstack([frame, panel])


def _draw_coverage(frame: np.ndarray, covered: np.ndarray) -> None:
    height, width = frame.shape[:2]
    overlay = frame.copy()
    rows, cols = covered.shape
    for row in range(rows):
        for col in range(cols):
            x0, x1 = round(col * width / cols), round((col + 1) * width / cols)
            y0, y1 = round(row * height / rows), round((row + 1) * height / rows)
            if covered[row, col]:
                cv2.rectangle(overlay, (x0, y0), (x1 - 1, y1 - 1), COVERED_COLOUR, -1)
            cv2.rectangle(frame, (x0, y0), (x1 - 1, y1 - 1), (90, 90, 90), 1)
    cv2.addWeighted(overlay, 0.25, frame, 0.75, 0, dst=frame)


def _draw_uncertainty(frame: np.ndarray, projection: dict, scale: float) -> None:
    """The projection uncertainty at its grid points: a filled circle from green (0.1 px or less) through
    orange to red (1 px or more), on a log scale the same for every fit."""
    values = np.asarray(projection["std_px"], float)
    for (x, y), value in zip(np.asarray(projection["points"], float) * scale, values, strict=True):
        share = float(np.clip(np.log10(max(value, 1e-9) / 0.1), 0.0, 1.0))
        cv2.circle(frame, (round(float(x)), round(float(y))), 4, (0, round(255 * (1 - share)), round(255 * share)),
                   -1, cv2.LINE_AA)


def _banner(frame: np.ndarray, text: str, colour: tuple[int, int, int]) -> None:
    cv2.rectangle(frame, (0, frame.shape[0] - 26), (frame.shape[1], frame.shape[0]), colour, -1)
    _text(frame, text, (8, frame.shape[0] - 8), (255, 255, 255), scale=0.5)


def _text(image: np.ndarray, text: str, origin: tuple[int, int], colour: tuple[int, int, int],
          scale: float = 0.45) -> None:
    cv2.putText(image, text, origin, FONT, scale, colour, 1, cv2.LINE_AA)


def bar_rows(guide: CalibrationGuide) -> list[tuple[str, float]]:
    """(label, fill 0..1) per bar, in the panel's order."""
    bars = guide.bars()
    return [(GOALS[name][0], bars[name]) for name in ("x", "y", "size", "tilt_h", "tilt_v", "roll", "coverage")]


def _panel(guide: CalibrationGuide, verdict: Verdict | None, fit: FitView | None, height: int) -> np.ndarray:
    panel = np.full((max(height, 420), PANEL_WIDTH, 3), 32, np.uint8)
    y = 22
    _text(panel, "variety of the kept views", (10, y), (230, 230, 230), 0.5)
    for label, fill in bar_rows(guide):
        y += 34
        _text(panel, label, (10, y - 8), (210, 210, 210))
        cv2.rectangle(panel, (10, y - 4), (PANEL_WIDTH - 10, y + 8), (70, 70, 70), -1)
        colour = (60, 200, 60) if fill >= 1 else (0, 180, 240)
        cv2.rectangle(panel, (10, y - 4), (10 + round((PANEL_WIDTH - 20) * fill), y + 8), colour, -1)
    y += 34
    _text(panel, f"views kept: {len(guide.kept)} of {guide.min_views}+", (10, y), (230, 230, 230), 0.5)
    for kind, count in sorted(guide.rejected.items()):
        y += 20
        _text(panel, f"rejected, {kind}: {count}", (10, y), (180, 180, 230))
    if fit is not None:
        y += 30
        _text(panel, f"fitted: RMS {fit.rms_px:.3f} px", (10, y), (140, 240, 140), 0.5)
        for name, label in (("fx", "c"), ("cx", "xp"), ("cy", "yp")):
            if name in fit.std:
                y += 20
                _text(panel, f"std {label}: {fit.std[name]:.2f} px", (10, y), (200, 230, 200))
        if fit.projection.get("std_px"):
            y += 20
            _text(panel, f"projection std: median {fit.projection['median']:.2f}, max {fit.projection['max']:.2f} px",
                  (10, y), (200, 230, 200), 0.4)
    return panel[:height] if panel.shape[0] > height else panel
