"""The overlay of a measured frame: the idealized frame with the object mask, the ROI, the targets and Af
written on it, as `--overlay` writes it and the area node publishes it.

No ROS here.
"""

from __future__ import annotations

import cv2
import numpy as np

from .area_result import AreaResult


def draw_overlay(result: AreaResult) -> np.ndarray:
    """The idealized frame with the object mask tinted red, the ROI outlined in yellow, the targets marked
    in green, where a folding lens model stops holding in orange, and Af written in the corner (BGR)."""
    image = result.image
    canvas = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    if result.mask is not None:
        tinted = canvas.copy()
        tinted[result.mask > 0] = (0, 0, 255)
        canvas = cv2.addWeighted(canvas, 0.55, tinted, 0.45, 0)
    if result.roi is not None:
        contours, _ = cv2.findContours(result.roi, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(canvas, contours, -1, (0, 255, 255), 1, cv2.LINE_AA)
    size = max(6, canvas.shape[1] // 80)
    if result.model_reach_px is not None:  # nothing is measured beyond it
        centre = (round((canvas.shape[1] - 1) / 2), round((canvas.shape[0] - 1) / 2))
        cv2.circle(canvas, centre, round(result.model_reach_px), (0, 140, 255), 2, cv2.LINE_AA)
        cv2.putText(canvas, "lens model holds inside", (centre[0] - 6 * size, centre[1] + round(result.model_reach_px)
                    - size), cv2.FONT_HERSHEY_SIMPLEX, size / 25, (0, 140, 255), 1, cv2.LINE_AA)
    for label, (u, v) in result.target_pixels.items():
        centre = (round(u), round(v))
        cv2.drawMarker(canvas, centre, (0, 255, 0), cv2.MARKER_CROSS, 2 * size, 1, cv2.LINE_AA)
        cv2.putText(canvas, label, (centre[0] + size, centre[1] - size), cv2.FONT_HERSHEY_SIMPLEX,
                    size / 25, (0, 255, 0), 1, cv2.LINE_AA)
    mode = "sub-pixel" if result.subpixel_applied else "count"
    text = (f"Af = {result.area_m2 * 1e4:.2f} +/- {result.area_std_m2 * 1e4:.2f} cm2 ({mode}), "
            f"T = {result.threshold:g}, "
            f"{'calibrated' if result.calibrated else 'UNCALIBRATED'}")
    font_scale = max(0.4, canvas.shape[1] / 1400)
    thickness = max(1, round(font_scale * 1.5))
    (text_w, text_h), baseline = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font_scale, thickness)
    cv2.rectangle(canvas, (0, 0), (text_w + 2 * size, text_h + baseline + 2 * size), (0, 0, 0), cv2.FILLED)
    cv2.putText(canvas, text, (size, text_h + size), cv2.FONT_HERSHEY_SIMPLEX, font_scale, (255, 255, 255),
                thickness, cv2.LINE_AA)
    return canvas
