"""What a series of measured frames (one input: a video, a bag, a folder) says as a whole: its mean Af with the
uncertainty of that mean, beside the frame-to-frame spread, and what was not measured and why. It exists apart
from the CLI because the batch summary, a single input's last line and the cluster client all report it.

The uncertainty of the mean: the terms of each frame's std that the frames share (the scale from the same
targets, the object plane's offset, the threshold's and the levels' reading, clipping, the edge pixels of a
plant that does not move) are not averaged down and are counted once, at their mean over the frames; what does
differ from frame to frame is measured by the frames themselves, their spread's standard error. The two add
in quadrature.

No ROS here.
"""

from __future__ import annotations

import math
import statistics

SHARED_TERMS = ("scale_std_m2", "plane_offset_std_m2", "threshold_std_m2", "levels_std_m2", "exposure_std_m2",
                "glare_std_m2", "edge_trend_std_m2", "discretisation_std_m2", "calibration_std_m2")


def _warnings(row: dict) -> list[str]:
    warnings = row.get("warnings", ())
    return warnings.split(" | ") if isinstance(warnings, str) and warnings else list(warnings or ())


def warning_counts(rows: list[dict]) -> str:
    """How many frames carried each kind of warning ('clipped highlights: 12 frames | ...')."""
    kinds: dict[str, int] = {}
    for row in rows:
        for kind in {w.split(":", 1)[0] for w in _warnings(row)}:
            kinds[kind] = kinds.get(kind, 0) + 1
    return " | ".join(f"{kind}: {count} frame{'s' if count > 1 else ''}" for kind, count in sorted(kinds.items()))


def not_measured_counts(rows: list[dict]) -> str:
    """How many frames were not measured, by reason ('no camera_info recorded before this frame: 3 frames')."""
    reasons: dict[str, int] = {}
    for row in rows:
        if row.get("error"):
            reason = str(row["error"])
            reasons[reason] = reasons.get(reason, 0) + 1
    return " | ".join(f"{reason}: {count} frame{'s' if count > 1 else ''}" for reason, count in sorted(reasons.items()))


def series_summary(rows: list[dict]) -> dict:
    """The series' mean Af (m²), the uncertainty of that mean (`mean_area_std_m2`), the frame-to-frame spread
    (`frame_spread_m2`, the standard deviation of the frames' Af: not an uncertainty of Af), the frames read and
    measured, the warnings and the frames not measured, each by kind."""
    areas = [row for row in rows if not row.get("error") and row.get("area_m2") not in (None, "")]
    summary = {"frames": len(rows), "measured": len(areas), "mean_area_m2": math.nan, "mean_area_std_m2": math.nan,
               "frame_spread_m2": math.nan, "warnings": warning_counts(rows),
               "not_measured": not_measured_counts(rows)}
    if not areas:
        return summary
    values = [float(row["area_m2"]) for row in areas]
    spread = statistics.stdev(values) if len(values) > 1 else 0.0
    shared = math.sqrt(sum(statistics.fmean(float(row.get(term) or 0.0) for row in areas) ** 2
                           for term in SHARED_TERMS))
    summary.update(mean_area_m2=statistics.fmean(values), frame_spread_m2=spread,
                   mean_area_std_m2=math.hypot(shared, spread / math.sqrt(len(values))))
    return summary


def summary_line(summary: dict) -> str:
    """The one line a single input ends with."""
    if not summary["measured"]:
        return f"Af: no frame measured of {summary['frames']}" + (
            f"; not measured: {summary['not_measured']}" if summary["not_measured"] else "")
    text = (f"Af = {summary['mean_area_m2']:.6g} ± {summary['mean_area_std_m2']:.2g} m² (mean of "
            f"{summary['measured']} of {summary['frames']} frames and its uncertainty; frame-to-frame sd "
            f"{summary['frame_spread_m2']:.2g} m²)")
    if summary["warnings"]:
        text += f"; warnings: {summary['warnings']}"
    if summary["not_measured"]:
        text += f"; not measured: {summary['not_measured']}"
    return text
