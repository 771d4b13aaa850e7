"""Calibration report figures: residual vectors, per-view residuals and image coverage (PNG, matplotlib).

No ROS here.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .calibration import CORNER_GRID, COVERAGE_CELLS, CalibrationResult, coverage_grid, radial_residuals
from .files import save_figure

if TYPE_CHECKING:
    from types import ModuleType

    from .guidance import CalibrationGuide
    from .reading_evidence import ReadingChoice
    from .tone_evidence import ToneChoice


def _pyplot() -> ModuleType:
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    return plt



def write_calibration_report(result: CalibrationResult, folder: str | Path, guide: CalibrationGuide | None = None,
                             tone: ToneChoice | None = None) -> list[Path]:
    """Write residuals.png, per_view.png, coverage.png, radial.png, uncertainty.png and calibration.json into
    `folder`; with `guide` (guidance.CalibrationGuide over the views) also variety.png, the bars; with `tone`
    (tone_evidence.ToneChoice) that measured views, tone_curve.png, and where it judged the reading, area_mode.png."""
    plt = _pyplot()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    width, height = result.camera.image_size
    points = np.concatenate(result.image_points)
    residuals = np.concatenate(result.residuals)
    inliers = np.concatenate(result.inliers)
    written = []

    norms = np.hypot(residuals[:, 0], residuals[:, 1])
    scale = 0.05 * width / max(np.percentile(norms, 95), 1e-9)  # the longest usual arrow ~5 % of the width
    fig, ax = plt.subplots(figsize=(8, 6.5))
    arrows = ax.quiver(points[inliers, 0], points[inliers, 1], residuals[inliers, 0] * scale,
                       residuals[inliers, 1] * scale, norms[inliers], angles="xy", scale_units="xy", scale=1,
                       cmap="viridis", width=0.002)
    fig.colorbar(arrows, ax=ax, shrink=0.8, label="residual length [px]")
    if (~inliers).any():
        ax.scatter(points[~inliers, 0], points[~inliers, 1], marker="x", color="red", label="rejected outliers")
        ax.legend(loc="upper right")
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    ax.set_aspect("equal")
    ax.set_title(f"Residual vectors x{scale:.0f} (RMS {result.rms_px:.3f} px, max {result.max_residual_px:.3f} px)")
    ax.set_xlabel("u [px]")
    ax.set_ylabel("v [px]")
    written.append(folder / "residuals.png")
    save_figure(fig, written[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(max(6, 0.35 * len(result.views)), 4))
    names = [v.name for v in result.views]
    ax.bar(range(len(names)), [v.rms_px for v in result.views], label="RMS")
    ax.plot(range(len(names)), [v.max_px for v in result.views], "r_", markersize=12, label="max")
    ax.set_xticks(range(len(names)), names, rotation=70, fontsize=7)
    ax.set_ylabel("residual [px]")
    ax.set_title("Residuals per view")
    ax.legend()
    written.append(folder / "per_view.png")
    save_figure(fig, written[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 6.5))
    columns, rows = COVERAGE_CELLS
    inlying = [points[kept] for points, kept in zip(result.image_points, result.inliers, strict=True)]
    held = coverage_grid(inlying, width, height, columns, rows)  # as the fit's coverage counts them
    empty = np.ma.masked_where(held, np.ones(held.shape))  # the cells no view reached, shaded
    ax.imshow(empty, extent=(0, width, height, 0), cmap="Reds", vmin=0, vmax=4, alpha=0.6, interpolation="nearest")
    for pts in result.image_points:
        ax.plot(pts[:, 0], pts[:, 1], ".", markersize=3)
    for k in range(1, columns):
        ax.axvline(k * width / columns, color="grey", lw=0.5)
    for k in range(1, rows):
        ax.axhline(k * height / rows, color="grey", lw=0.5)
    for k in range(1, CORNER_GRID):  # the cells whose corner ones the calibration's warning checks for points
        ax.axvline(k * width / CORNER_GRID, color="black", lw=1.0, ls="--",
                   label="thirds (corners warned)" if k == 1 else None)
        ax.axhline(k * height / CORNER_GRID, color="black", lw=1.0, ls="--")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.06), fontsize=8, frameon=False)
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    ax.set_aspect("equal")
    ax.set_title(f"Board points of all views: {held.sum()} of {held.size} cells reached "
                 f"(coverage {100 * result.coverage:.0f} %; empty cells shaded)")
    written.append(folder / "coverage.png")
    save_figure(fig, written[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)

    # the lens beyond the model: residuals that lean outwards or inwards depending on the distance from the centre
    where, radial = radial_residuals(result.camera, points[inliers], residuals[inliers])
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(where, radial, ".", markersize=2, alpha=0.3, color="tab:blue", label="points")
    rings = result.radial_profile
    ax.errorbar([(r["from"] + min(r["to"], where.max())) / 2 for r in rings], [r["mean_radial_px"] for r in rings],
                yerr=[2 * r["standard_error_px"] for r in rings], fmt="o", color="tab:red", capsize=4,
                label="ring mean ± 2 standard errors")
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_xlabel("distance from the principal point / half-diagonal")
    ax.set_ylabel("radial residual [px]")
    ax.set_title("Radial residuals (a lens the model follows: every ring mean at zero)")
    ax.legend(loc="best")
    written.append(folder / "radial.png")
    save_figure(fig, written[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)

    # how well the calibration pins each viewing direction's pixel, and the std of each parameter two ways
    projection = result.projection_std_px
    if projection.get("points"):
        grid, std = np.array(projection["points"]), np.array(projection["std_px"])
        fig, (left, right) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1.4, 1]})
        shown = left.scatter(grid[:, 0], grid[:, 1], c=std, s=120, cmap="magma_r", marker="s")
        fig.colorbar(shown, ax=left, label="projection std [px]")
        left.set_xlim(0, width)
        left.set_ylim(height, 0)
        left.set_aspect("equal")
        left.set_title(f"Projection uncertainty (median {projection['median']:.2f} px, max {projection['max']:.2f} px)")
        names = ["fx", "fy", "cx", "cy"]
        spots = np.arange(len(names))
        right.bar(spots - 0.2, [result.std_covariance.get(n, 0) for n in names], 0.4, label="covariance")
        right.bar(spots + 0.2, [result.std_views.get(n, 0) for n in names], 0.4, label="resampling views")
        right.set_xticks(spots, names)
        right.set_ylabel("std [px]")
        halves = result.halves
        right.set_title("Parameter std" + (f"; halves differ by up to {halves['max_z']:.1f} std" if halves else ""))
        right.legend()
        written.append(folder / "uncertainty.png")
        save_figure(fig, written[-1], dpi=110, bbox_inches="tight")
        plt.close(fig)

    if guide is not None:
        written.append(plot_variety(guide, folder / "variety.png", result.views_used))
    if tone is not None and tone.sizes:
        written.append(plot_tone_evidence(tone, folder / "tone_curve.png"))
    if tone is not None and len(tone.edges.get(tone.curve, [])) >= 2:
        written.append(plot_edge_trend(tone, folder / "edge_trend.png"))
    if tone is not None and tone.reading is not None and tone.reading.decided:
        written.append(plot_reading_evidence(tone.reading, folder / "area_mode.png"))
    written.append(folder / "calibration.json")
    written[-1].write_text(json.dumps(result.summary(), indent=2))
    return written


def plot_variety(guide: CalibrationGuide, path: str | Path, distinct: int | None = None) -> Path:
    """The variety bars of the views (as the calibration node's feedback shows them) and what is still needed."""
    from .feedback import bar_rows

    plt = _pyplot()
    rows = bar_rows(guide)
    fig, ax = plt.subplots(figsize=(8, 3.8))
    fills = [fill for _, fill in rows]
    ax.barh(range(len(rows)), fills, color=["tab:green" if f >= 1 else "tab:orange" for f in fills])
    ax.set_yticks(range(len(rows)), [label for label, _ in rows])
    ax.invert_yaxis()
    ax.set_xlim(0, 1)
    ax.set_xlabel("share of the variety each parameter needs")
    needed = guide.still_needed()
    views = (f"{len(guide.kept)} views" if distinct is None or distinct == len(guide.kept)
             else f"{distinct} distinct views ({len(guide.kept)} looked at, the others repeats)")
    ax.set_title(f"{views}; " + (f"still needed: {needed}" if needed else "variety enough"),
                 fontsize=10)
    path = Path(path)
    save_figure(fig, path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_tone_evidence(tone: ToneChoice, path: str | Path) -> Path:
    """Each measured view's error in the board's black area against its size, under each tone curve, with the
    fitted drift (error = a + slope / px per square): the camera's curve is the flat one."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    sizes = np.asarray(tone.sizes)
    line = np.linspace(sizes.min(), sizes.max(), 100)
    for (curve, errors), colour in zip(tone.errors.items(), ("tab:blue", "tab:orange"), strict=False):
        errors = 100 * np.asarray(errors)
        ax.plot(sizes, errors, "o", color=colour, label=f"{curve}")
        slope = tone.slopes.get(curve, {}).get("slope")
        if slope is not None:
            offset = np.mean(errors) - 100 * slope * np.mean(1 / sizes)
            ax.plot(line, offset + 100 * slope / line, "-", color=colour, lw=1)
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())
    low, high = ax.get_xlim()
    ax.set_xticks([t for t in (10, 15, 20, 30, 50, 70, 100, 150, 200, 300, 500) if low <= t <= high]
                  or [round(line[0]), round(line[-1])])
    ax.set_xlabel("board size in the view [px per square]")
    ax.set_ylabel("black area: error against the print [%]")
    verdict = f"{tone.curve} taken" if tone.decided else "not told apart: linear kept"
    ax.set_title(f"Tone curve from {len(sizes)} views: {verdict}", fontsize=10)
    ax.legend(title="read as")
    ax.grid(alpha=0.3)
    path = Path(path)
    save_figure(fig, path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_reading_evidence(reading: ReadingChoice, path: str | Path) -> Path:
    """Each measured view's error in the board's black area from the views' mean, read with the shares (each
    with the edge trend of the other views) and counted: the reading whose points lie closer to zero is taken."""
    plt = _pyplot()
    order = np.argsort(reading.names, kind="stable")
    fig, ax = plt.subplots(figsize=(max(6.0, 0.25 * len(order) + 2), 4.2))
    for offset, (mode, colour, label) in zip((-0.12, 0.12), (("subpixel", "tab:blue", "shares"),
                                                             ("count", "tab:grey", "counted")), strict=True):
        errors = 100 * np.asarray(reading.errors[mode])[order]
        ax.plot(np.arange(len(order)) + offset, errors - errors.mean(), "o", color=colour,
                label=f"{label}: sd {100 * reading.spreads[mode]:.2f} %")
    ax.axhline(0, color="black", lw=0.8)
    # a photo by its stem, a video's or bag's frame (NAME#N) by its number too
    labels = [Path(name).name if "#" in name else Path(name).stem for name in (reading.names[k] for k in order)]
    ax.set_xticks(np.arange(len(order)), labels, rotation=90, fontsize=6)
    ax.set_ylabel("black area: error from the views' mean [%]")
    taken = "the shares" if reading.mode == "subpixel" else "whole pixels counted"
    ax.set_title(f"Reading from {reading.views} views: {taken}", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    path = Path(path)
    save_figure(fig, path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_edge_trend(tone: ToneChoice, path: str | Path) -> Path:
    """Each measured view's edge offset (its black area's error over the board's edge length, px) against its
    white level, under the curve taken, with the trend the calibration records (or the line it did not take).
    Where the print's gain was fitted beside the trend, the views are drawn with it taken out."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    edges = tone.edges[tone.curve]
    choice = tone.edge_trend
    gain = np.array(choice.gain_px if choice is not None and choice.gain_px else [0.0] * len(edges))
    whites, offsets = np.array([e.white_dn for e in edges]), np.array([e.offset_px for e in edges]) - gain
    ax.plot(whites, offsets, "o", color="tab:blue",
            label="views, the print's gain with their scale taken out" if gain.any() else "views")
    for edge, offset in zip(edges, offsets, strict=True):
        ax.annotate(Path(edge.name).stem, (edge.white_dn, offset), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
    if choice is not None and choice.trend is not None:
        trend = choice.trend
        line = np.linspace(*trend.range_dn, 50)
        moved = np.array([trend.offset_px(float(white)) for white in line])  # a frame at each level: move, std
        middle, spread = float(np.mean(offsets)) + moved[:, 0], moved[:, 1]
        label = ("trend recorded, with the nearest views' residuals" if trend.local else
                 "trend recorded" if trend.learned else "no trend learned: nothing moved")
        ax.plot(line, middle, "-", color="tab:orange", label=label)
        ax.fill_between(line, middle - spread, middle + spread, color="tab:orange", alpha=0.2, label="its ±1 std")
    ax.axhline(0, color="grey", lw=0.8)
    ax.set_xlabel("white level of the view [DN]")
    ax.set_ylabel("edge offset: the black reaches further [px]")
    reason = "" if choice is None else choice.reason
    ax.set_title(textwrap.fill(f"Edges against exposure, read as {tone.curve}: {reason}", 90), fontsize=9)
    ax.legend()
    ax.grid(alpha=0.3)
    path = Path(path)
    save_figure(fig, path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_area_series(times: list[float], areas: list[float], stds: list[float], path: str | Path,
                     title: str = "Projected area", time_label: str = "time [s]") -> Path:
    """Af(t) with its ±1 standard deviation band (PNG); NaN areas (frames that failed) leave gaps."""
    plt = _pyplot()
    t = np.asarray(times, float)
    a = np.asarray(areas, float)  # m², the CSV's unit
    s = np.asarray(stds, float)
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.fill_between(t, a - s, a + s, color="tab:blue", alpha=0.25, label="±1 std")
    ax.plot(t, a, ".-", color="tab:blue", markersize=3, lw=1, label="Af")
    failed = np.isnan(a)
    if failed.any():
        ax.plot(t[failed], np.full(failed.sum(), np.nanmin(a) if (~failed).any() else 0), "rx",
                label="not measured")
    ax.set_xlabel(time_label)
    ax.set_ylabel("Af [m²]")
    ax.ticklabel_format(axis="x", useOffset=False)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    # beside the axes: it hides no data, and "best" searches every point (7 s of a 2-hour video's 216 000)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    path = Path(path)
    # zlib's fastest level: the PNG encoded in 30 ms instead of 70 (600 frames), the file 20 % larger
    save_figure(fig, path, dpi=110, bbox_inches="tight", pil_kwargs={"compress_level": 1})
    plt.close(fig)
    return path
