"""`veg-area`: the command line for researchers without ROS. Same core as the nodes.

    veg-area calibrate IMAGES_OR_DIR_OR_VIDEO... --board SPEC -o calib.yaml [--json] [--report DIR]
    veg-area demo

Exit codes: 0 success, 1 failed (with a one-line reason on stderr), 2 usage error, 3 refused to replace a
better calibration.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from . import __version__

EXIT_FAILED = 1
EXIT_REFUSED = 3


class CliError(Exception):
    """A failure reported as one line, without a traceback."""

    def __init__(self, message: str, code: int = EXIT_FAILED):
        super().__init__(message)
        self.code = code


def _progress(quiet: bool):
    def say(message: str) -> None:
        if not quiet:
            print(message, file=sys.stderr, flush=True)
    return say


def _positive_float(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def cmd_calibrate(args: argparse.Namespace) -> int:
    from .board import BoardSpec, BoardSpecError
    from .calib_io import CalibrationFileError, quality_rms, read_calibration, write_calibration
    from .calibration import CalibrationError, View, calibrate
    from .frames import VIDEO_SUFFIXES, InputError, expand_inputs, iter_frames, video_frame_count

    say = _progress(args.quiet)
    try:
        board = BoardSpec.parse(args.board)
    except BoardSpecError as exc:
        raise CliError(str(exc), 2) from exc
    output = Path(args.output)
    try:
        files = expand_inputs(args.inputs)
    except InputError as exc:
        raise CliError(str(exc)) from exc

    previous = None
    if output.exists() and not args.force:
        try:
            previous = read_calibration(output)
        except CalibrationFileError as exc:
            raise CliError(f"{output} exists and is not a readable calibration ({exc}); "
                             "use --force to replace it", EXIT_REFUSED) from exc

    step = args.video_step
    if step <= 0:  # about 60 frames per video: consecutive frames add little but time
        counts = [video_frame_count(f) for f in files if f.suffix.lower() in VIDEO_SUFFIXES]
        step = max(1, max(counts, default=0) // 60)

    views: list[View] = []
    image_size: tuple[int, int] | None = None
    unreadable: list[str] = []
    no_board: list[str] = []
    wrong_size: list[str] = []
    seen = 0
    for frame in iter_frames(files, step):
        seen += 1
        if frame.image is None:
            unreadable.append(frame.name)
            say(f"[{seen}] {frame.name}: skipped, {frame.problem}")
            continue
        size = (frame.image.shape[1], frame.image.shape[0])
        if image_size is None:
            image_size = size
        elif size != image_size:
            wrong_size.append(frame.name)
            say(f"[{seen}] {frame.name}: skipped, {size[0]}x{size[1]} differs from {image_size[0]}x{image_size[1]}")
            continue
        detection = board.detect(frame.image)
        if detection is None:
            no_board.append(frame.name)
            say(f"[{seen}] {frame.name}: no {board.kind} board found")
            continue
        views.append(View(frame.name, detection))
        say(f"[{seen}] {frame.name}: {len(detection)} board points")

    if not views:
        if image_size is None:
            raise CliError(f"no readable image among the inputs ({len(unreadable)} unreadable)")
        raise CliError(f"no {board} board found in any of {seen} images")
    try:
        result = calibrate(views, image_size, robust_loss=args.loss,
                           outlier_sigma=None if args.no_outlier_rejection else args.outlier_sigma, progress=say)
    except CalibrationError as exc:
        raise CliError(str(exc)) from exc

    summary = result.summary()
    summary.update(unreadable=unreadable, no_board=no_board, wrong_size=wrong_size, output=str(output))
    metadata = {
        "medium": args.medium,
        "calibration_distance_m": args.distance,
        "board": str(board),
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "software": f"veg_area_ros {__version__}",
        **{k: summary[k] for k in ("rms_px", "mean_px", "max_residual_px", "sigma0_px", "views_used",
                                   "views_rejected", "std", "coverage", "warnings")},
    }

    if previous is not None and previous.camera.image_size == result.camera.image_size \
            and quality_rms(previous) < result.rms_px:
        raise CliError(
            f"{output} holds a better calibration (RMS {quality_rms(previous):.4f} px) than this one "
            f"({result.rms_px:.4f} px); kept it. Use --force to replace it, or write elsewhere with -o",
            EXIT_REFUSED)
    write_calibration(output, result.camera, args.camera_name, metadata)
    if args.report:
        from .report import write_calibration_report

        for path in write_calibration_report(result, args.report):
            say(f"report: {path}")
    for warning in result.warnings:
        say(f"warning: {warning}")
    if args.json:
        print(json.dumps(summary))
    else:
        print(_format_calibration(result, output))
    return 0


def _format_calibration(result, output: Path) -> str:
    cam, std = result.camera, result.std
    lines = [f"calibration written to {output}",
             f"views used {result.views_used}, rejected {len(result.rejected_views)}; "
             f"RMS {result.rms_px:.4f} px, mean {result.mean_px:.4f} px, max {result.max_residual_px:.4f} px",
             f"{'param':>6} {'value':>14} {'std':>12}"]
    lines += [f"{name:>6} {value:14.6g} {std[name]:12.3g}" for name, value in cam.parameters().items()]
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


def cmd_demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    return run_demo(Path(args.output), quiet=args.quiet)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="veg-area", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"veg_area_ros {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    cal = sub.add_parser("calibrate", help="self-calibrating bundle adjustment from board images or videos")
    cal.add_argument("inputs", nargs="+", help="images, folders of images, videos")
    cal.add_argument("--board", required=True,
                     help="chessboard:COLSxROWS:SQUARE_M | charuco:SXxSY:SQUARE_M:MARKER_M:DICT | "
                          "circles:COLSxROWS:SPACING_M")
    cal.add_argument("-o", "--output", required=True, help="camera_info YAML to write")
    cal.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
    cal.add_argument("--report", metavar="DIR", help="write residual and coverage plots (PNG) here")
    cal.add_argument("--medium", default="air", choices=["air", "water"], help="medium of the calibration")
    cal.add_argument("--distance", type=_positive_float, default=None,
                     help="camera-to-board distance of the calibration, metres (recorded in the file)")
    cal.add_argument("--camera-name", default="camera")
    cal.add_argument("--loss", default="linear", choices=["linear", "huber", "soft_l1", "cauchy"],
                     help="robust loss for the bundle adjustment")
    cal.add_argument("--outlier-sigma", type=_positive_float, default=4.0,
                     help="reject points beyond this many robust standard deviations")
    cal.add_argument("--no-outlier-rejection", action="store_true")
    cal.add_argument("--video-step", type=int, default=0, help="use every Nth video frame (0: about 60 per video)")
    cal.add_argument("--force", action="store_true", help="replace the output even if it holds a better fit")
    cal.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    cal.set_defaults(func=cmd_calibrate)

    demo = sub.add_parser("demo", help="the built-in default: calibrate a synthetic underwater endoscope")
    demo.add_argument("--output", default="veg_area_demo", help="folder for the calibration and report")
    demo.add_argument("-q", "--quiet", action="store_true")
    demo.set_defaults(func=cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except CliError as exc:
        print(f"veg-area {args.command}: {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        print(f"veg-area {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
