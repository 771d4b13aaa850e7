"""Whether a new calibration should replace the one a file (or a node) holds, judged on evidence a lower RMS
cannot fake: fewer views always fit with a lower RMS and know the lens worse. It exists apart from the fit
because it compares two calibrations, one of them known only by its file: the new fit's views, coverage and
projection uncertainty against the recorded ones, and how well the held camera predicts the new views.

No ROS here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .calibration import CalibrationResult, pose_residuals
from .camera_model import BrownCamera

LENS_CHANGED = 3.0  # the held camera predicts the new views this many times worse than the new fit: another lens
SAME_FIGURE = 1e-6  # relative: the same views fitted again differ by ~1e-10 (threaded sums): one figure
LENS_CHANGED_FLOOR_PX = 0.1  # ... and by at least this RMS (sensor noise moves corners by a few hundredths)


@dataclass(frozen=True)
class Judgement:
    replace: bool
    reason: str  # one line: what is better in which


def predicted_rms(camera: BrownCamera, result: CalibrationResult) -> float:
    """How well `camera` predicts the corners of the views `result` was fitted to, each view placed anew by
    it (RMS px, both coordinates): the held calibration tried on the new fit's views."""
    intrinsics = np.array(list(camera.parameters().values()))
    residuals = []
    for pose, points, inliers, view in zip(result.poses, result.image_points, result.inliers, result.object_points,
                                           strict=True):
        residuals.append(pose_residuals(intrinsics, pose, view[inliers], points[inliers], camera.model))
    joined = np.concatenate(residuals)
    return float(np.sqrt(np.mean(joined**2) * 2))


def judge(held: BrownCamera, held_metadata: dict, result: CalibrationResult) -> Judgement:
    """Replace the held calibration by `result`? Yes when the held one is for another image size, records no
    evidence (another tool's file), no longer predicts these views (the lens or port changed), or when the new
    fit's projection uncertainty (the parameters' std over the covered image: what fewer views or a narrower
    coverage cost) is no larger than the held one's. The reason names the figures of both."""
    new = result.camera
    if held.image_size != new.image_size:
        return Judgement(True, f"the held calibration is for {held.width}x{held.height} images, this one for "
                               f"{new.width}x{new.height}")
    held_std = (held_metadata.get("projection_std_px") or {}).get("median")
    new_std = result.projection_std_px.get("median", math.inf)
    held_views = held_metadata.get("views_used", "?")
    held_coverage = held_metadata.get("coverage")
    facts = (f"{result.views_used} views against {held_views}, coverage "
             f"{result.coverage:.0%} against {'?' if held_coverage is None else f'{held_coverage:.0%}'}")
    if not isinstance(held_std, int | float) or not math.isfinite(held_std):
        return Judgement(True, f"the held calibration records no projection uncertainty to judge it by ({facts})")
    prediction = predicted_rms(held, result)
    own = result.halves.get("held_out_rms_px") or result.rms_px
    if prediction > max(LENS_CHANGED * own, own + LENS_CHANGED_FLOOR_PX):
        return Judgement(True, f"the held calibration predicts these views to {prediction:.3f} px against this "
                               f"fit's {own:.3f} px: the lens, its focus or the port changed ({facts})")
    figures = (f"projection uncertainty {new_std:.3f} px (median) against the held {held_std:.3f} px; {facts}; "
               f"the held camera predicts these views to {prediction:.3f} px")
    if new_std <= held_std * (1 + SAME_FIGURE):
        return Judgement(True, f"this fit knows the lens as well or better: {figures}")
    return Judgement(False, f"the held calibration knows the lens better: {figures}")
