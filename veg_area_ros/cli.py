"""`veg-area`: the command line for researchers without ROS. Same core as the nodes.

    veg-area calibrate IMAGES_OR_DIR_OR_VIDEO... --board SPEC -o calib.yaml [--json] [--report DIR]
    veg-area measure IMAGE_OR_DIR_OR_VIDEO... --calibration calib.yaml|none --targets targets.yaml [--json]
    veg-area demo

Exit codes: 0 success, 1 failed (with a one-line reason on stderr), 2 usage error, 3 refused to replace a
better calibration.
"""

from __future__ import annotations

import argparse
import contextlib
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
    from .calibration import CalibrationError, View, calibrate, same_pose
    from .frames import VIDEO_SUFFIXES, InputError, expand_inputs, iter_frames, video_frame_count

    say = _progress(args.quiet)
    output = Path(args.output)
    problem = _unwritable(output, folder=False)
    if problem:
        raise CliError(f"-o {output}: {problem}; nothing was calibrated", 2)
    if args.port or args.lens:
        return _calibrate_port(args, say)
    if not args.inputs or not args.board:
        raise CliError("give the board (--board) and its images", 2)
    try:
        board = BoardSpec.parse(args.board)
    except BoardSpecError as exc:
        raise CliError(str(exc), 2) from exc
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
    repeated: list[str] = []
    last_kept: dict[str, object] = {}  # per video: the last view kept, so a pose held still counts once
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
        if frame.time_s is not None:  # a video frame: the board held still for a while is one view, not many
            video = frame.name.rsplit("#", 1)[0]
            if video in last_kept and same_pose(detection, last_kept[video], image_size):
                repeated.append(frame.name)
                say(f"[{seen}] {frame.name}: same pose as the view before it, counted once")
                continue
            last_kept[video] = detection
        views.append(View(frame.name, detection))
        say(f"[{seen}] {frame.name}: {len(detection)} board points")

    if args.medium == "unspecified":
        say("warning: --medium not given: the calibration is recorded with medium 'unspecified' (say air or water: "
            "a calibration holds only in the medium it was made in)")
    if not views:
        if image_size is None:
            raise CliError(f"no readable image among the inputs ({len(unreadable)} unreadable)")
        hint = ""
        if board.kind == "circles":
            hint = (f" (looked for {'a symmetric' if board.symmetric else 'an asymmetric'} grid; for the other "
                    f"kind write circles:{board.cols}x{board.rows}:{board.square:g}"
                    f"{'' if board.symmetric else ':symmetric'})")
        raise CliError(f"no {board} board found in any of {seen} images{hint}; supported boards: chessboard, "
                       "charuco, circles (asymmetric, or :symmetric)")
    try:
        result = calibrate(views, image_size, robust_loss=args.loss,
                           outlier_sigma=None if args.no_outlier_rejection else args.outlier_sigma, progress=say)
    except CalibrationError as exc:
        raise CliError(str(exc)) from exc

    summary = result.summary()
    summary.update(unreadable=unreadable, no_board=no_board, wrong_size=wrong_size, repeated_poses=repeated,
                   output=str(output))
    metadata = {
        "medium": args.medium,
        "calibration_distance_m": args.distance,
        "board": str(board),
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "software": f"veg_area_ros {__version__}",
        **{k: summary[k] for k in ("rms_px", "mean_px", "max_residual_px", "sigma0_px", "views_used",
                                   "views_rejected", "std", "std_covariance", "std_views", "coverage", "warnings")},
        "halves": {k: v for k, v in summary["halves"].items() if k != "z"},
        "projection_std_px": {k: summary["projection_std_px"][k] for k in ("median", "max")},
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


def _calibrate_port(args: argparse.Namespace, say) -> int:
    """`calibrate --port ... --lens air.yaml [underwater views]`: the port fitted from the views (or as measured)
    in front of the air calibration; written as the absorbed plumb_bob equivalent at --absorbed-distance with
    the lens and port in the file's veg_area_ros block."""
    from .board import BoardSpec, BoardSpecError
    from .calib_io import CalibrationFileError, _plain, read_calibration, write_calibration
    from .flat_port import PORT_KEY, FlatPort, FlatPortCamera, PortError, absorbed_at_distance, fit_port, port_to_dict
    from .frames import InputError, expand_inputs, iter_frames

    if not (args.port and args.lens):
        raise CliError("--port and --lens go together: the port's numbers and the lens's air calibration", 2)
    try:
        start = FlatPort.parse(args.port, args.water_index)
        lens_file = read_calibration(args.lens)
    except (PortError, CalibrationFileError) as exc:
        raise CliError(str(exc), 2) from exc
    if lens_file.metadata.get("medium") not in ("air", None):
        say(f"warning: {args.lens} says medium {lens_file.metadata.get('medium')!r}; --lens wants the air calibration")
    lens = lens_file.camera
    std: dict[str, float] = {}
    summary: dict = {"port": "as measured"}
    port = start
    if args.inputs:
        if not args.board:
            raise CliError("give the board (--board) of the underwater views", 2)
        try:
            board = BoardSpec.parse(args.board)
            files = expand_inputs(args.inputs)
        except (BoardSpecError, InputError) as exc:
            raise CliError(str(exc), 2) from exc
        views = []
        for index, frame in enumerate(iter_frames(files), 1):
            if frame.image is None:
                say(f"[{index}] {frame.name}: skipped, {frame.problem}")
                continue
            if (frame.image.shape[1], frame.image.shape[0]) != lens.image_size:
                say(f"[{index}] {frame.name}: skipped, not {lens.width}x{lens.height} like the lens calibration")
                continue
            detection = board.detect(frame.image)
            if detection is None:
                say(f"[{index}] {frame.name}: no {args.board} board found")
                continue
            views.append((detection.object_points, detection.image_points))
            say(f"[{index}] {frame.name}: {len(detection)} points")
        if len(views) < 2:
            raise CliError(f"{len(views)} underwater view(s) with the board: a port fit needs 2 or more")
        try:
            fit = fit_port(lens, views, start, fit_water_index=args.fit_water_index)
        except PortError as exc:
            raise CliError(str(exc)) from exc
        port, std = fit.port, fit.std
        summary = {"port": "fitted", "views": len(views), "rms_px": fit.rms_px, "view_rms_px": fit.view_rms_px,
                   "std": std}
        say(f"port fitted from {len(views)} views: distance {port.distance * 1000:.2f} ± "
            f"{std['distance'] * 1000:.2f} mm, tilt {math.degrees(port.tilt_x_rad):.3f}° / "
            f"{math.degrees(port.tilt_y_rad):.3f}° (± {math.degrees(std['tilt_x_rad']):.3f}° / "
            f"{math.degrees(std['tilt_y_rad']):.3f}°), RMS {fit.rms_px:.3f} px")
    camera = FlatPortCamera(lens, port)
    absorbed, residual = absorbed_at_distance(camera, args.absorbed_distance)
    metadata = {"medium": "water", "date": dt.datetime.now(dt.UTC).isoformat(), "lens_file": str(args.lens),
                PORT_KEY: port_to_dict(camera, std, args.absorbed_distance),
                "absorbed_residual_px": residual, **{k: v for k, v in summary.items() if k != "std"}}
    write_calibration(args.output, absorbed, args.camera_name, metadata)
    summary.update(output=str(args.output), distance_m=port.distance, tilt_x_deg=float(math.degrees(port.tilt_x_rad)),
                   tilt_y_deg=float(math.degrees(port.tilt_y_rad)), water_index=port.water_index,
                   absorbed_residual_px=residual)
    if args.json:
        print(json.dumps(_plain(summary)))
    else:
        print(f"flat port written to {args.output} (plumb_bob equivalent at {args.absorbed_distance:g} m: "
              f"largest misfit {residual:.2f} px)")
    return 0


def _format_calibration(result, output: Path) -> str:
    cam, std = result.camera, result.std
    lines = [f"calibration written to {output}",
             f"views used {result.views_used}, rejected {len(result.rejected_views)}; "
             f"RMS {result.rms_px:.4f} px, mean {result.mean_px:.4f} px, max {result.max_residual_px:.4f} px",
             f"{'param':>6} {'value':>14} {'std':>12} {'(covariance':>12} {'views)':>10}"]
    lines += [f"{name:>6} {value:14.6g} {std[name]:12.3g} {result.std_covariance[name]:12.3g} "
              f"{result.std_views[name]:10.3g}" for name, value in cam.parameters().items()]
    if result.halves:
        lines.append(f"two halves of the views: parameters differ by up to {result.halves['max_z']:.1f} combined "
                     f"std; projection by {result.halves['projection_difference_px']['max']:.2f} px at most")
    lines.append(f"projection uncertainty over the covered image: median "
                 f"{result.projection_std_px['median']:.3f} px, max {result.projection_std_px['max']:.3f} px")
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


def _threshold(text: str) -> float | str:
    if text.lower() == "otsu":
        return "otsu"
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and 0 <= value <= 255):
        raise argparse.ArgumentTypeError(f"must be a number from 0 to 255 or 'otsu', got {text!r}")
    return value


def _levels(text: str) -> tuple[float, float]:
    from .classify import ClassifyError, check_levels

    try:
        return check_levels(text.split(","))
    except ClassifyError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def _roi(text: str):
    from .classify import ClassifyError, check_polygon

    try:
        values = [float(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected x1,y1,x2,y2,x3,y3,... in pixels, got {text!r}") from exc
    if len(values) % 2 or len(values) < 6 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"needs at least 3 x,y corner pairs, got {text!r}")
    try:
        return check_polygon(values)
    except ClassifyError as exc:
        raise argparse.ArgumentTypeError(f"the region {text!r} is empty: its corners enclose no area") from exc


def _unwritable(path: Path, folder: bool) -> str | None:
    """Why `path` (a file, or a folder to write into) cannot be written here, or None: checked before any work
    by creating (and removing) a temporary file where it would go (permissions alone miss /proc as root)."""
    import tempfile

    if path.exists() and folder and not path.is_dir():
        return "exists and is not a folder"
    if path.exists() and not folder and path.is_dir():
        return "is a folder, not a file"
    where = path if folder and path.exists() else path.parent
    while not where.exists():
        where = where.parent
    if not where.is_dir():
        return f"{where} is a file, not a folder"
    try:
        with tempfile.TemporaryFile(dir=where):
            pass
    except OSError as exc:
        return f"cannot be written in {where} ({exc.strerror or exc})"
    return None


def _frame_file_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in Path(name).stem) + ".png"


CSV_COLUMNS = ("frame", "time_s", "stamp_sec", "stamp_nanosec", "area_m2", "area_std_m2", "area_mode",
               "subpixel_applied", "pixel_count", "count_area_m2", "threshold", "scale_std_m2", "threshold_std_m2",
               "discretisation_std_m2", "levels_std_m2", "plane_offset_std_m2", "object_plane_offset_m",
               "scale_m_per_px", "scale_kind", "calibrated", "missing_targets", "error")


def cmd_measure(args: argparse.Namespace) -> int:
    if args.jobs < 0:
        raise CliError("--jobs must be 0 (every core) or more", 2)
    if args.jobs != 1 and len(args.inputs) > 1:
        return _measure_batch(args)
    return _measure(args)[0]


def _measure(args: argparse.Namespace, on_frame=None, stop=None) -> tuple[int, list[dict]]:
    """Measure every frame of args.inputs; (exit code, CSV rows; 130 when interrupted, with what was measured
    so far). `on_frame(index, total)` (a batch worker) replaces the per-frame lines on stdout; `stop()` true
    (the batch was interrupted) ends the series as Ctrl-C does."""
    import cv2

    from .area import NO_CALIBRATION_FOR_OFFSET, AreaMeasurer, PortAreaMeasurer, draw_overlay
    from .bags import BagError, bag_image_count
    from .calib_io import CalibrationFileError, read_calibration, write_calibration
    from .camera_info import info_to_camera
    from .classify import Classifier, ClassifyError
    from .frames import (
        IMAGE_SUFFIXES,
        VIDEO_SUFFIXES,
        InputError,
        expand_inputs,
        is_bag,
        iter_frames,
        video_frame_count,
    )
    from .idealize import FrameSizeError
    from .scale import TargetsError, TargetsSpec

    say = _progress(args.quiet)
    if args.video_step < 1:
        raise CliError("--video-step must be 1 or more", 2)
    camera = port_camera = None
    from_bag = args.calibration.lower() == "bag"  # each frame with the camera_info recorded before it
    if args.calibration.lower() not in ("none", "bag"):
        try:
            calibration = read_calibration(args.calibration)
        except CalibrationFileError as exc:
            raise CliError(str(exc)) from exc
        camera, port_camera = calibration.camera, calibration.port_camera()
    try:
        targets = TargetsSpec.load(args.targets)
        classifier = Classifier(threshold=args.threshold, object=args.object, channel=args.channel,
                                open_px=args.open, close_px=args.close)
    except TargetsError as exc:
        raise CliError(str(exc)) from exc
    except ClassifyError as exc:
        raise CliError(str(exc), 2) from exc
    try:
        files = expand_inputs(args.inputs)
    except InputError as exc:
        raise CliError(str(exc)) from exc
    videos = [f for f in files if f.suffix.lower() in VIDEO_SUFFIXES]
    bags = [f for f in files if is_bag(f)]
    if from_bag and len(bags) != len(files):
        raise CliError("--calibration bag needs rosbag2 inputs (their recorded camera_info)", 2)
    try:
        bag_frames = sum(bag_image_count(b, args.image_topic) for b in bags)
    except BagError as exc:
        raise CliError(str(exc)) from exc
    total = (sum(video_frame_count(v) // args.video_step for v in videos) + bag_frames
             + len(files) - len(videos) - len(bags))
    series = videos + bags
    csv_path = Path(args.csv) if args.csv else (Path(f"{series[0].stem}_area.csv") if series else None)
    single_overlay = args.overlay and Path(args.overlay).suffix.lower() in IMAGE_SUFFIXES
    for option, value, folder in (("--overlay", args.overlay, not single_overlay), ("--csv", args.csv, False),
                                  ("--idealized", args.idealized, True)):
        if value:
            problem = _unwritable(Path(value), folder)
            if problem:
                raise CliError(f"{option} {value}: {problem}; nothing was measured", 2)
    if single_overlay and total > 1:
        raise CliError(f"--overlay {args.overlay} names one image but the input has {total} frames; "
                       "give a folder", 2)

    if targets.object_plane_offset_m is not None and camera is None and not from_bag:
        raise CliError(NO_CALIBRATION_FOR_OFFSET)

    def new_measurer(camera) -> AreaMeasurer | PortAreaMeasurer:
        options = dict(roi=args.roi, threshold_delta=args.sweep_step, area_mode=args.area_mode, levels=args.levels)
        try:
            if port_camera is not None and camera is calibration.camera:  # the exact port model, not the stand-in
                return PortAreaMeasurer(port_camera, targets, classifier, **options)
            return AreaMeasurer(camera, targets, classifier, **options)
        except ClassifyError as exc:
            raise CliError(str(exc), 2) from exc
        except TargetsError as exc:
            raise CliError(str(exc)) from exc

    measurer = new_measurer(camera) if not from_bag else None
    if args.idealized and camera is not None:
        folder = Path(args.idealized)
        write_calibration(folder / "ideal_camera.yaml", camera.ideal(), "ideal",
                          {"idealized_from": str(Path(args.calibration).resolve())})
    rows: list[dict] = []
    measured = 0
    interrupted = False
    try:
        for index, frame in enumerate(iter_frames(files, args.video_step, args.image_topic), 1):
            row = {"frame": frame.name, "time_s": frame.time_s, "error": ""}
            if frame.stamp is not None:
                row["stamp_sec"], row["stamp_nanosec"] = frame.stamp
                if not (args.start_time <= frame.time_s <= args.end_time):
                    continue
            try:
                if frame.image is None:
                    raise InputError(f"skipped: {frame.problem}")
                if from_bag:  # as the live area node: the latest camera_info, a new measurer when it changes
                    if frame.camera_info is None:
                        raise InputError("no camera_info recorded before this frame")
                    recorded = info_to_camera(frame.camera_info)
                    if recorded != camera or measurer is None:
                        camera = recorded
                        measurer = new_measurer(camera)
                result = measurer.measure(frame.image, keep_images=bool(args.overlay or args.idealized))
            except (InputError, FrameSizeError, TargetsError, ClassifyError, ValueError) as exc:
                row["error"] = str(exc)
                say(f"[{index}/{total}] {frame.name}: not measured, {exc}")
            else:
                measured += 1
                summary = result.summary()
                row.update(summary)
                if result.missing_targets:
                    say(f"[{index}/{total}] {frame.name}: targets not found: markers {result.missing_targets}")
                if on_frame is None and (not args.json or index % 25 == 0 or index == total):
                    line = (f"[{index}/{total}] {frame.name}: Af = {result.area_m2:.6g} ± {result.area_std_m2:.2g} m² "
                            f"({result.pixel_count} px, threshold {result.threshold:g}, {result.scale.kind} scale"
                            f"{'' if result.calibrated else ', UNCALIBRATED'})")
                    print(line, file=sys.stderr if args.json else sys.stdout, flush=True)
                if args.overlay:
                    target = Path(args.overlay) if single_overlay else Path(args.overlay) / _frame_file_name(frame.name)
                    target.parent.mkdir(parents=True, exist_ok=True)
                    if not cv2.imwrite(str(target), draw_overlay(result)):
                        say(f"[{index}/{total}] {frame.name}: overlay {target} could not be written")
                if args.idealized and camera is not None:
                    cv2.imwrite(str(Path(args.idealized) / _frame_file_name(frame.name)), result.image)
            if args.json:
                print(json.dumps({k: v for k, v in row.items() if k != "error" or v}), flush=True)
            rows.append(row)
            if on_frame is not None:
                on_frame(index, total)
            if stop is not None and stop():
                raise KeyboardInterrupt
    except KeyboardInterrupt:  # Ctrl-C on a long video or bag: what was measured is kept (CSV, plot)
        interrupted = True

    if csv_path is not None and measured == 0 and csv_path.exists():  # an error-only table must not replace one
        say(f"time series not written: no frame was measured (the existing {csv_path} is kept)")
    elif csv_path is not None and rows:  # a new file lists every frame, with its error where there is one
        _write_area_csv(csv_path, rows)
        say(f"time series: {csv_path}")
        if len(rows) > 1:
            from .report import plot_area_series

            nan = float("nan")
            timed = all(r["time_s"] is not None for r in rows)
            plot = plot_area_series([r["time_s"] if timed else k for k, r in enumerate(rows)],
                                    [r.get("area_m2", nan) for r in rows], [r.get("area_std_m2", nan) for r in rows],
                                    csv_path.with_suffix(".png"), title=f"Projected area, {csv_path.stem}",
                                    time_label="time [s]" if timed else "frame")
            say(f"plot: {plot}")
    if interrupted:  # the frame in hand when Ctrl-C came is not in the rows
        say(f"interrupted after {len(rows)} of {total} frames ({measured} measured)"
            + (f"; the series so far: {csv_path}" if csv_path is not None and rows else ""))
        return 130, rows
    if measured == 0:
        reasons = sorted({r["error"] for r in rows})
        raise CliError(f"no frame measured: {'; '.join(reasons)[:500]}")
    if measured < len(rows):
        say(f"{len(rows) - measured} of {len(rows)} frames not measured (see 'error')")
    return 0, rows


BATCH_COLUMNS = ("input", "frames", "measured", "mean_area_m2", "std_area_m2", "csv", "error")


def _batch_csv_paths(inputs: list[str], folder: Path) -> list[Path]:
    """<stem>_area.csv per input; inputs sharing a stem are told apart by their position."""
    stems = [Path(i.rstrip("/")).stem or "input" for i in inputs]
    return [folder / (f"{k + 1:02d}_{stem}_area.csv" if stems.count(stem) > 1 else f"{stem}_area.csv")
            for k, stem in enumerate(stems)]


def _ignore_ctrl_c() -> None:
    """Batch workers leave Ctrl-C to the main process, which asks them to stop between frames: interrupted
    anywhere (an idle worker, one writing its CSV), a worker would break the pool and lose the others' work."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _batch_summary(source: str, csv_path: str, error: str = "") -> dict:
    """One input's row of batch_summary.csv before anything was measured."""
    return {"input": source, "frames": 0, "measured": 0, "mean_area_m2": "", "std_area_m2": "", "csv": csv_path,
            "error": error}


def _measure_batch_job(options: dict, source: str, csv_path: str, progress, stopping) -> dict:
    """One input of a batch, in a worker process: its CSV and plot, and a one-line summary."""
    import statistics

    args = argparse.Namespace(**dict(options, inputs=[source], csv=csv_path, json=False, quiet=True))
    if options["overlay"]:
        args.overlay = str(Path(options["overlay"]) / Path(csv_path).stem)
    summary = _batch_summary(source, csv_path)
    try:
        code, rows = _measure(args, on_frame=lambda index, total: progress.put((source, index, total)),
                              stop=stopping.is_set)
    except CliError as exc:
        summary["error"] = str(exc)
        return summary
    if code == 130:
        summary["error"] = f"interrupted after {len(rows)} frames"
    areas = [r["area_m2"] for r in rows if not r["error"] and "area_m2" in r]
    summary.update(frames=len(rows), measured=len(areas))
    if areas:
        summary["mean_area_m2"] = statistics.fmean(areas)
        summary["std_area_m2"] = statistics.stdev(areas) if len(areas) > 1 else 0.0
    return summary


def _measure_batch(args: argparse.Namespace) -> int:
    """Each input (video, bag, image or folder) measured by its own worker process, --jobs at a time, with
    one progress line; a CSV + plot per input and batch_summary.csv in --output-dir."""
    import multiprocessing
    import os
    import queue
    import time
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    if args.csv:
        raise CliError("--csv names one file; a batch writes <input>_area.csv per input into --output-dir", 2)
    if args.idealized:
        raise CliError("--idealized is for one input at a time (frames of several inputs would mix)", 2)
    if args.overlay and Path(args.overlay).suffix.lower() in (".png", ".jpg", ".jpeg"):
        raise CliError(f"--overlay {args.overlay} names one image; give a folder for a batch", 2)
    folder = Path(args.output_dir)
    folder.mkdir(parents=True, exist_ok=True)
    jobs = args.jobs or os.cpu_count() or 1
    context = multiprocessing.get_context("spawn")  # workers start clean (OpenCV threads, no forked state)
    options = {k: v for k, v in vars(args).items() if k != "func"}
    csv_paths = _batch_csv_paths(args.inputs, folder)
    say = _progress(args.quiet)
    say(f"batch: {len(args.inputs)} inputs, {min(jobs, len(args.inputs))} at a time")
    with context.Manager() as manager, ProcessPoolExecutor(min(jobs, len(args.inputs)), mp_context=context,
                                                           initializer=_ignore_ctrl_c) as pool:
        progress, stopping = manager.Queue(), manager.Event()
        pending = {pool.submit(_measure_batch_job, options, source, str(path), progress, stopping): source
                   for source, path in zip(args.inputs, csv_paths, strict=True)}
        done_frames: dict[str, tuple[int, int]] = {}
        summaries: dict[str, dict] = {}
        last_line = 0.0
        interrupted = False
        try:
            while pending:
                finished, _ = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                for future in finished:
                    source = pending.pop(future)
                    summaries[source] = future.result()
                    state = summaries[source]["error"] or f"{summaries[source]['measured']} frames measured"
                    say(f"batch: {source} done: {state}")
                with contextlib.suppress(queue.Empty):
                    while True:
                        source, index, total = progress.get_nowait()
                        done_frames[source] = (index, total)
                if time.monotonic() - last_line > 2.0 and pending and done_frames:
                    frames = sum(i for i, _ in done_frames.values())
                    total = sum(t for _, t in done_frames.values())
                    say(f"batch: {len(summaries)}/{len(args.inputs)} inputs done; {frames} of {total} frames "
                        "measured in the inputs begun")
                    last_line = time.monotonic()
        except KeyboardInterrupt:  # the workers stop after their current frame and keep what they measured
            interrupted = True
            stopping.set()
            for future in pending:
                future.cancel()
            for future, source in pending.items():
                try:
                    summaries[source] = future.result()
                except Exception:  # cancelled before it began
                    summaries[source] = _batch_summary(source, "", "interrupted before it began")
    rows = [summaries[source] for source in args.inputs]
    summary_path = folder / "batch_summary.csv"
    _write_csv(summary_path, BATCH_COLUMNS, rows)
    for row in rows:
        if args.json:  # one object per input (the frames are in its CSV)
            print(json.dumps(row), flush=True)
            continue
        mean = f"Af = {row['mean_area_m2']:.6g} m² (sd {row['std_area_m2']:.2g}) over {row['measured']} frames" \
            if row["measured"] else f"not measured: {row['error'] or 'no frame measured'}"
        print(f"{row['input']}: {mean}", flush=True)
    say(f"batch summary: {summary_path}")
    if interrupted:
        say("batch interrupted: what each input measured so far is in its CSV")
        return 130
    failed = [row["input"] for row in rows if not row["measured"]]
    if failed:
        raise CliError(f"{len(failed)} of {len(rows)} inputs gave no measurement: {', '.join(failed)}")
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    from .ros.record_node import main as record_main

    ros_args = ["--ros-args", "-p", f"storage:={args.storage}"]
    if args.output:
        ros_args += ["-p", f"output:={args.output}"]
    ros_args += ["-p", "topics:=[" + ",".join(f"'{t}'" for t in args.topics) + "]"]
    ros_args += ["-p", f"all:={'true' if args.all else 'false'}", "-p", f"duration:={float(args.duration or 0.0)}"]
    return record_main(["veg-area-record", *ros_args])


def cmd_play(args: argparse.Namespace) -> int:
    from .bags import BagError, play_topics
    from .ros.play_node import main as play_main

    try:
        play_topics(args.bag, args.topics)  # a clear error before ROS starts
    except BagError as exc:
        raise CliError(str(exc)) from exc
    if args.delay < 0:
        raise CliError("--delay must be 0 or more", 2)
    ros_args = ["--ros-args", "-p", f"bag:={args.bag}", "-p", f"rate:={args.rate}", "-p", f"delay:={args.delay}"]
    if args.topics:
        ros_args += ["-p", "topics:=[" + ",".join(f"'{t}'" for t in args.topics) + "]"]
    return play_main(["veg-area-play", *ros_args])


def cmd_bag_recover(args: argparse.Namespace) -> int:
    from .bags import BagError, recover_bag

    try:
        recovery = recover_bag(args.bag, args.output)
    except BagError as exc:
        raise CliError(str(exc)) from exc
    for topic, count in recovery.counts.items():
        print(f"{topic}: {count} messages recovered")
    for reason in recovery.dropped:
        print(f"damaged: {reason}", file=sys.stderr)
    if recovery.unchecked_chunks:
        print(f"{recovery.unchecked_chunks} chunk(s) carry no CRC (the writer computed none): damage inside them "
              "cannot be detected", file=sys.stderr)
    print(f"readable bag: {args.output}" + (f" ({len(recovery.dropped)} damaged part(s) left out)"
                                           if recovery.dropped else ""))
    return 0


def cmd_vogel(args: argparse.Namespace) -> int:
    from .bags import BagError, bag_run
    from .drag import DragError, plot_vogel, read_runs, runs_to_vogel, vogel_fit
    from .frames import is_bag

    bags = [Path(i) for i in args.inputs if is_bag(Path(i))]
    if (bags and len(bags) != len(args.inputs)) or (not bags and len(args.inputs) != 1):
        raise CliError("give one experiment table (CSV), or rosbag2 bags (one run each)", 2)
    try:
        if bags:
            runs = [bag_run(b, args.force_axis, args.velocity_axis, args.force_topic, args.velocity_topic,
                            args.area_topic) for b in bags]
            for run in runs:
                print(f"{run['run']}: U = {run['velocity_m_s']:.4g} m/s, F = {run['force_n']:.4g} N, "
                      f"Af = {run['area_m2']:.4g} m² ({run['samples']['force']} force, "
                      f"{run['samples']['velocity']} velocity, {run['samples']['area']} Af samples)",
                      file=sys.stderr)
            velocity, cd_area = runs_to_vogel(runs, args.density, "bags")
        else:
            velocity, cd_area = read_runs(args.inputs[0], args.density)
        fit = vogel_fit(velocity, cd_area, args.confidence)
    except (DragError, BagError) as exc:
        raise CliError(str(exc)) from exc
    plot = Path(args.plot) if args.plot else Path(args.inputs[0].rstrip("/")).with_suffix(".vogel.png")
    plot_vogel(velocity, cd_area, fit, plot)
    result = {"exponent": fit.exponent, "interval": list(fit.interval), "confidence": fit.confidence,
              "coefficient_m2": fit.coefficient, "r_squared": fit.r_squared, "runs": fit.runs, "plot": str(plot)}
    if args.json:
        print(json.dumps(result))
    else:
        low, high = fit.interval
        print(f"Vogel exponent psi = {fit.exponent:.4f}, {fit.confidence:.0%} interval [{low:.4f}, {high:.4f}] "
              f"({fit.runs} runs, R² {fit.r_squared:.4f}); Cd·Af = {fit.coefficient:.4g} m² x U^psi")
        print(f"plot: {plot}")
    return 0


def _write_area_csv(path: Path, rows: list[dict]) -> None:
    _write_csv(path, CSV_COLUMNS,
               [{**row, "missing_targets": " ".join(map(str, row.get("missing_targets", [])))} for row in rows])


def _write_csv(path: Path, columns: Sequence[str], rows: list[dict]) -> None:
    import csv
    import io

    from .calib_io import write_atomic

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, columns, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(path, buffer.getvalue())


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job: the ROS 2 graph (composed in this process) on the built-in synthetic endoscope."""
    from .ros.graph import run_graph

    code = run_graph(Path(args.output), measurements=args.measurements, timeout_s=args.timeout)
    if code:
        raise CliError("the graph did not deliver calibrated measurements in time")
    return 0


def cmd_calibration_demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    return run_demo(Path(args.output), quiet=args.quiet)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="veg-area", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"veg_area_ros {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    cal = sub.add_parser("calibrate", help="self-calibrating bundle adjustment from board images or videos")
    cal.add_argument("inputs", nargs="*", help="images, folders of images, videos (underwater views with --port)")
    cal.add_argument("--board",
                     help="chessboard:COLSxROWS:SQUARE_M | charuco:SXxSY:SQUARE_M:MARKER_M:DICT | "
                          "circles:COLSxROWS:SPACING_M (asymmetric grid) | circles:COLSxROWS:SPACING_M:symmetric")
    cal.add_argument("-o", "--output", required=True, help="camera_info YAML to write")
    cal.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
    cal.add_argument("--report", metavar="DIR", help="write residual and coverage plots (PNG) here")
    cal.add_argument("--medium", default="unspecified", choices=["air", "water", "unspecified"],
                     help="medium of the calibration: say it (recorded as 'unspecified' otherwise)")
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
    cal.add_argument("--port", metavar="flat:DISTANCE_M:THICKNESS_M:N_GLASS",
                     help="an explicit flat port in front of the --lens air calibration: fitted (normal, distance) "
                          "from the underwater views given, or taken as measured when none are given")
    cal.add_argument("--lens", metavar="AIR_YAML", help="the lens's calibration in air (with --port)")
    cal.add_argument("--water-index", type=_positive_float, default=1.333, help="refractive index of the water")
    cal.add_argument("--fit-water-index", action="store_true", help="fit the water's index too (with --port)")
    cal.add_argument("--absorbed-distance", type=_positive_float, default=0.7, metavar="M",
                     help="distance of the plane for the absorbed plumb_bob equivalent written for ROS tools")
    cal.set_defaults(func=cmd_calibrate)

    mea = sub.add_parser("measure", help="projected area Af of an object in images, folders or videos")
    mea.add_argument("inputs", nargs="+", help="images, folders of images, videos, rosbag2 bags (folders)")
    mea.add_argument("--calibration", required=True,
                     help="camera_info YAML from 'veg-area calibrate', 'none' to measure the raw image, or 'bag' "
                          "for the camera_info recorded in the bag (as the live area node used it)")
    mea.add_argument("--image-topic", default=None, help="image topic of a bag (default: its only Image topic)")
    mea.add_argument("--start-time", type=float, default=-math.inf, metavar="S",
                     help="bag frames stamped from this time on (seconds, header stamp)")
    mea.add_argument("--end-time", type=float, default=math.inf, metavar="S", help="bag frames up to this time")
    mea.add_argument("--targets", required=True, help="targets YAML: ArUco marker ids or hand-picked points")
    mea.add_argument("--threshold", type=_threshold, default="otsu", help="0..255 or 'otsu' (default)")
    mea.add_argument("--object", default="dark", choices=["dark", "bright", "green"],
                     help="object darker/brighter than the background, or greener (excess-green index)")
    mea.add_argument("--channel", default="grey", choices=["grey", "blue", "green", "red"],
                     help="band the threshold acts on (dark/bright)")
    mea.add_argument("--roi", type=_roi, default=None, metavar="x1,y1,x2,y2,...",
                     help="region of interest, polygon in idealized-image pixels (default: inside the targets)")
    mea.add_argument("--area-mode", default="subpixel", choices=["subpixel", "count"],
                     help="subpixel (default): each edge pixel counts its object share from its grey level "
                          "between the object's and the background's; count: whole pixels, as in the paper")
    mea.add_argument("--levels", type=_levels, default=None, metavar="OBJECT,BACKGROUND",
                     help="sub-pixel mode: the object's and background's grey levels (default: from each frame)")
    mea.add_argument("--open", type=int, default=0, metavar="PX", help="morphological opening radius")
    mea.add_argument("--close", type=int, default=0, metavar="PX", help="morphological closing radius")
    mea.add_argument("--sweep-step", type=_positive_float, default=5.0,
                     help="threshold step of the sweep and of the threshold uncertainty (grey levels)")
    mea.add_argument("--json", action="store_true", help="one JSON object per frame on stdout (a batch: per input)")
    mea.add_argument("--overlay", metavar="PNG_OR_DIR", help="draw mask, ROI and targets (a file, or a folder)")
    mea.add_argument("--csv", metavar="FILE", help="time series CSV (+ PNG plot beside it); "
                     "default for a video: VIDEO_area.csv here")
    mea.add_argument("--idealized", metavar="DIR", help="write the idealized frames and their camera here")
    mea.add_argument("--video-step", type=int, default=1, help="measure every Nth video frame")
    mea.add_argument("--jobs", type=int, default=1, metavar="N",
                     help="batch: measure the inputs N at a time in worker processes, 0 = every core; a CSV and "
                          "plot per input and batch_summary.csv go to --output-dir")
    mea.add_argument("--output-dir", default=".", metavar="DIR", help="where a batch writes (default: here)")
    mea.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    mea.set_defaults(func=cmd_measure)

    rec = sub.add_parser("record", help="record topics into a rosbag2 bag (MCAP, or sqlite3) as they come, "
                         "serialized (ROS 2 node; Ctrl-C closes the bag)")
    rec.add_argument("topics", nargs="*", default=["image_raw", "camera_info", "projected_area",
                                                   "projected_area/info"],
                     help="topics (default: image_raw camera_info projected_area projected_area/info); a topic "
                          "never seen is a warning and exit 1")
    rec.add_argument("--all", action="store_true", help="every topic on the graph")
    rec.add_argument("--duration", type=_positive_float, default=None, metavar="S", help="stop after S seconds")
    rec.add_argument("-o", "--output", help="bag folder to create (default veg_area_<date-time>)")
    rec.add_argument("--storage", default="mcap", choices=["mcap", "sqlite3"])
    rec.set_defaults(func=cmd_record)

    play = sub.add_parser("play", help="replay a rosbag2 bag at the recorded pace with the recorded QoS, as "
                          "'ros2 bag play' does (ROS 2 node; stops at the end)")
    play.add_argument("bag", help="the bag folder")
    play.add_argument("--topics", nargs="+", default=None, help="topics to replay (default: all)")
    play.add_argument("--rate", type=_positive_float, default=1.0, help="pace, 1 = as recorded")
    play.add_argument("--delay", type=float, default=1.0, metavar="S",
                      help="seconds to wait before the first message, for subscribers to connect (default 1)")
    play.set_defaults(func=cmd_play)

    recover = sub.add_parser("bag-recover", help="rebuild a readable bag from an MCAP recording that was killed")
    recover.add_argument("bag", help="the broken bag folder (or its .mcap file)")
    recover.add_argument("output", help="new bag folder")
    recover.set_defaults(func=cmd_bag_recover)

    vog = sub.add_parser("vogel", help="fit the Vogel exponent (Cd·Af ∝ U^psi) to an experiment table, with "
                         "its confidence interval and a log-log plot")
    vog.add_argument("inputs", nargs="+", metavar="TABLE_OR_BAGS",
                     help="a CSV with velocity_m_s, force_n, area_m2 (optional density) per run, or rosbag2 bags "
                          "recorded with force, velocity and projected_area, one run each")
    vog.add_argument("--force-axis", default="+x",
                     help="bags: force component along the flow, +x .. -z (a minus sign: --force-axis=-y)")
    vog.add_argument("--velocity-axis", default="+x", help="bags: velocity component along the flow")
    vog.add_argument("--force-topic", default="/force", help="bags: geometry_msgs/WrenchStamped topic")
    vog.add_argument("--velocity-topic", default="/velocity", help="bags: geometry_msgs/TwistStamped topic")
    vog.add_argument("--area-topic", default="/projected_area", help="bags: Af topic (Vector3Stamped, x = Af)")
    vog.add_argument("--density", type=_positive_float, default=998.2, help="water density, kg/m³")
    vog.add_argument("--confidence", type=float, default=0.95)
    vog.add_argument("--plot", help="PNG (default: the first input's name + .vogel.png)")
    vog.add_argument("--json", action="store_true")
    vog.set_defaults(func=cmd_vogel)

    demo = sub.add_parser("demo", help="the main job on the built-in default: synthetic underwater camera -> "
                          "calibration node -> area node, Af against the true area")
    demo.add_argument("--output", default="veg_area_demo", help="folder for the served calibration")
    demo.add_argument("--measurements", type=int, default=10, help="calibrated frames to average")
    demo.add_argument("--timeout", type=_positive_float, default=300.0, help="seconds before giving up")
    demo.set_defaults(func=cmd_demo)

    cdemo = sub.add_parser("calibration-demo", help="calibrate a synthetic endoscope in air and water, "
                           "compare with the true camera (no ROS)")
    cdemo.add_argument("--output", default="veg_area_demo", help="folder for the calibration and report")
    cdemo.add_argument("-q", "--quiet", action="store_true")
    cdemo.set_defaults(func=cmd_calibration_demo)
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
