"""A held-out check of Af on real photos of a printed chessboard: calibrate with `veg-area calibrate` on every
other photo of a folder, then measure the black area of each photo of the other half (test/board_photos.py's
set-up: the rectangle through the outer squares' centres, the four outer inner corners as targets) in the
default mode (auto: the reading the calibration records), with the shares and counted, with the calibration
file as `veg-area measure` reads it. Prints each photo's error
from the print's squares and its reported std, and per mode the spread, the worst photo and how far each photo
lies from the set's mean in its own std, with the targets' calliper term (the same for every photo of one
print) and without it.

    PYTHONPATH=veg_area_ros:test .venv/bin/python test/held_out_board.py FOLDER --board chessboard:8x6:0.03 \\
        --medium water [--half 0|1|all] [--model auto]

`--half all` calibrates on every photo and measures every photo with that file (a camera calibrated on
its own photos, as a user who measures the boards they calibrated on does; the photos are then not held out).

The ink's gain shifts every photo of one print alike: the spread between photos and the std's cover of it are
what is judged, the mean only bounded."""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import board_photos
import numpy as np

from veg_area_ros.calib_io import read_calibration
from veg_area_ros.cli import main as veg_area
from veg_area_ros.settings import MeasurementSettings

MODES = ("auto", "subpixel", "count")  # the default (the reading the calibration records), the shares, counted
WELL_EXPOSED = 0.01  # share of the board's pixels at 250 or more


@dataclass
class PhotoRow:
    name: str
    clipped_share: float
    errors: dict[str, float]  # per mode, Af over the print's black area, minus 1
    stds: dict[str, float]  # per mode, the reported std over that area
    stds_without_calliper: dict[str, float]
    warnings: list[str]


@dataclass
class ModeSummary:
    mean: float
    spread: float  # the photos' standard deviation
    worst: float  # the largest distance from the mean
    median_std: float
    largest_z: float  # the largest distance from the mean in the photo's own std
    largest_z_without_calliper: float
    within_3: int


ALL = "all"  # every photo calibrated on and measured


def halves(folder: Path, half: int | str) -> tuple[list[Path], list[Path]]:
    """(the photos calibrated on, the photos measured): alternate photos in name order, `half` choosing which;
    ALL: every photo, both times."""
    photos = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    if half == ALL:
        return photos, photos
    return photos[half::2], photos[1 - half::2]


def check(folder: Path, board: str, medium: str, half: int | str = 0, model: str = "auto",
          work: Path | None = None) -> tuple[list[PhotoRow], dict[str, ModeSummary], dict]:
    """(each measured photo's row, a summary per mode over the well-exposed ones, the calibration's metadata)."""
    kind, size, square = board.split(":")
    with contextlib.ExitStack() as stack:
        work = work or Path(stack.enter_context(tempfile.TemporaryDirectory()))
        calibrated_on, measured = work / "calibrated_on", work / "measured"
        for target, photos in zip((calibrated_on, measured), halves(folder, half), strict=True):
            target.mkdir(parents=True, exist_ok=True)
            for photo in photos:
                (target / photo.name).symlink_to(photo.resolve())
        output = work / "calibration.yaml"
        with contextlib.redirect_stdout(io.StringIO()) as said:
            code = veg_area(["calibrate", str(calibrated_on), "--board", board, "--medium", medium, "--model", model,
                             "-o", str(output), "-q"])
        if code != 0:
            raise RuntimeError(f"veg-area calibrate exited {code}: {said.getvalue()[-2000:]}")
        calibration = read_calibration(output)
        kept, board_photos.SQUARE_M = board_photos.SQUARE_M, float(square)  # the print's: the file's distances hold
        try:
            found = board_photos.board_photos(measured, f"{kind}:{size}:1", camera=calibration.camera)
        finally:
            board_photos.SQUARE_M = kept
        rows = [_row(photo, calibration) for photo in found]
    return rows, summarise(rows), calibration.metadata


def _row(photo: board_photos.BoardPhoto, calibration) -> PhotoRow:
    errors, stds, bare, warnings = {}, {}, {}, []
    for mode in MODES:
        settings = MeasurementSettings(roi=tuple(np.ravel(photo.roi)), area_mode=mode)
        for targets, into in ((photo.targets, stds), (replace(photo.targets, distance_std_m=0.0), bare)):
            result = settings.measurer(calibration.camera, targets,
                                       calibration_conditions=calibration.metadata).measure(photo.frame)
            into[mode] = result.area_std_m2 / photo.true_area_m2
        errors[mode] = result.area_m2 / photo.true_area_m2 - 1
        if mode == "auto":
            warnings = list(result.warnings)
    return PhotoRow(photo.name, photo.clipped_share, errors, stds, bare, warnings)


def well_exposed(rows: list[PhotoRow]) -> list[PhotoRow]:
    return [row for row in rows if row.clipped_share < WELL_EXPOSED]


def scatter(errors: np.ndarray, stds: np.ndarray) -> tuple[float, float, float]:
    """(the photos' spread, the worst photo's distance from their mean, the largest such distance in the photo's
    own std), from their relative errors and stds."""
    centred = errors - errors.mean()
    return float(np.std(errors, ddof=1)), float(np.max(np.abs(centred))), float(np.max(np.abs(centred) / stds))


def summarise(rows: list[PhotoRow]) -> dict[str, ModeSummary]:
    well = well_exposed(rows)
    summary = {}
    for mode in MODES:
        errors = np.array([row.errors[mode] for row in well])
        stds = np.array([row.stds[mode] for row in well])
        spread, worst, largest = scatter(errors, stds)
        summary[mode] = ModeSummary(float(errors.mean()), spread, worst, float(np.median(stds)), largest,
                                    scatter(errors, np.array([row.stds_without_calliper[mode] for row in well]))[2],
                                    int(np.sum(np.abs((errors - errors.mean()) / stds) <= 3)))
    return summary


def draw_photos(ax, modes: dict[str, tuple[np.ndarray, np.ndarray]],
                without_calliper: dict[str, np.ndarray] | None = None) -> dict[str, tuple[float, float, float]]:
    """Each photo's Af from its set's mean (relative errors, per mode: 'default' and 'count') with ±1 of its
    reported std on `ax`, and, thicker, the std without the targets' calliper where given. A bar that misses the
    zero line is a std that did not hold at 1 std. Returns per mode the spread and the worst photo (%) and the
    largest distance from the mean in the photo's std."""
    figures = {}
    for offset, (mode, colour) in zip((-0.15, 0.15), (("default", "tab:blue"), ("count", "tab:grey")), strict=True):
        errors, stds = modes[mode]
        centred = 100 * (errors - errors.mean())
        x = np.arange(len(errors)) + offset
        spread, worst, largest = scatter(errors, stds)
        figures[mode] = (100 * spread, 100 * worst, largest)
        ax.errorbar(x, centred, yerr=100 * stds, fmt="o", ms=4, capsize=2, color=colour,
                    label=f"{mode}: sd {figures[mode][0]:.2f} %, worst {figures[mode][1]:.2f} %")
        if without_calliper is not None:
            ax.errorbar(x, centred, yerr=100 * without_calliper[mode], fmt="none", elinewidth=2.5, color=colour,
                        alpha=0.5)
    ax.axhline(0, color="black", lw=0.8)
    return figures


def plot(rows: list[PhotoRow], title: str, path: Path) -> Path:
    """The well-exposed photos drawn by draw_photos (PNG), the default mode's figures beside the count's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    well = well_exposed(rows)
    named = {"default": "auto", "count": "count"}
    figure, ax = plt.subplots(figsize=(max(6.0, 0.22 * len(well) + 2), 4.2))
    draw_photos(ax, {shown: (np.array([row.errors[mode] for row in well]), np.array([row.stds[mode] for row in well]))
                     for shown, mode in named.items()},
                {shown: np.array([row.stds_without_calliper[mode] for row in well]) for shown, mode in named.items()})
    ax.set_xticks(np.arange(len(well)), [Path(row.name).stem for row in well], rotation=90, fontsize=6)
    ax.set_ylabel("Af from the set's mean [%], ±1 reported std")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--board", required=True, help="chessboard:COLSxROWS:SQUARE_M")
    parser.add_argument("--medium", required=True, choices=("air", "water"))
    parser.add_argument("--half", choices=("0", "1", ALL), default="0",
                        help=f"which half is calibrated on ({ALL}: every photo, each measured with that file)")
    parser.add_argument("--model", default="auto")
    parser.add_argument("--plot", type=Path, help="draw each photo's Af from the mean with its std (PNG) here")
    args = parser.parse_args(argv)
    half = args.half if args.half == ALL else int(args.half)
    rows, summary, metadata = check(args.folder, args.board, args.medium, half, args.model)
    if args.plot:
        title = (f"{args.folder.name}: every photo, calibrated on all of them" if half == ALL
                 else f"{args.folder.name}: half {1 - half} measured, calibrated on half {half}")
        plot(rows, title, args.plot)
    print(f"calibration: model {metadata.get('model_choice', {}).get('chosen', 'plumb_bob (none chosen)')}, "
          f"edge trend: {metadata.get('edge_trend_evidence', 'none recorded')}; "
          f"area mode {metadata.get('area_mode', 'subpixel (none recorded)')}: "
          f"{metadata.get('area_mode_evidence', 'no evidence recorded')}")
    for row in rows:
        print(f"{row.name}  clipped {100 * row.clipped_share:5.2f} %  "
              + "  ".join(f"{mode} {100 * row.errors[mode]:+.3f} ± {100 * row.stds[mode]:.3f} %" for mode in MODES))
    well = len(well_exposed(rows))
    print(f"{len(rows)} photos measured, {well} with under {100 * WELL_EXPOSED:g} % of the board's pixels clipped:")
    for mode, s in summary.items():
        print(f"  {mode:8s} mean {100 * s.mean:+.3f} %, spread {100 * s.spread:.3f} %, worst {100 * s.worst:.3f} % "
              f"from the mean; std median {100 * s.median_std:.3f} %; |z| at most {s.largest_z:.2f} "
              f"({s.largest_z_without_calliper:.2f} without the targets' calliper), within 3 std {s.within_3}/{well}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
