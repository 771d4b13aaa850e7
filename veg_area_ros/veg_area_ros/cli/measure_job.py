"""One `measure` run: the job the command line asked for (`MeasureJob`), measured frame by frame into its CSV
time series, plot, overlays and idealized frames. `cli.measure` builds it; `cli.batch` gives each worker one."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, fields
from datetime import UTC
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from ..calib_io import metadata_for
from ..settings import MeasurementSettings
from .common import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    RowLog,
    check_outputs,
    check_writable,
    progress,
)

if TYPE_CHECKING:
    from ..area import AreaMeasurer
    from ..calib_io import CalibrationFile
    from ..camera_model import BrownCamera
    from ..port_area import PortAreaMeasurer

CSV_COLUMNS = ("frame", "time_s", "stamp_sec", "stamp_nanosec", "area_m2", "area_std_m2", "area_mode",
               "subpixel_applied", "pixel_count", "count_area_m2", "threshold", "tone_curve", "scale_std_m2",
               "threshold_std_m2", "discretisation_std_m2", "levels_std_m2", "plane_offset_std_m2",
               "calibration_std_m2", "object_plane_offset_m", "exposure_std_m2", "glare_std_m2", "edge_trend_std_m2",
               "edge_trend_m2", "scale_m_per_px", "scale_kind", "marker_std_px", "calibrated", "missing_targets",
               "warnings", "error")

SEGMENT_FRAMES = 1000


class TimeBound(NamedTuple):
    """A bound of --start-time/--end-time: seconds after a bag's first image, or an absolute stamp."""

    seconds: float
    absolute: bool = False

    def at(self, stamp: float, since_start: float) -> float:
        """How far this bound lies after a frame (stamped `stamp`, `since_start` after its bag's first image)."""
        return self.seconds - (stamp if self.absolute else since_start)

    def __str__(self) -> str:
        return f"unix:{self.seconds:.3f}" if self.absolute else f"{self.seconds:g} s"


def time_bound(text: str) -> TimeBound:
    """--start-time/--end-time: seconds after the first image, `unix:SECONDS`, or an ISO time."""
    from datetime import datetime

    if text.startswith("unix:"):
        try:
            return TimeBound(float(text[5:]), True)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"unix: needs seconds since 1970, got {text!r}") from exc
    try:
        return TimeBound(float(text))
    except ValueError:
        pass
    try:
        moment = datetime.fromisoformat(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"a time is seconds after the first image, unix:SECONDS or an ISO time "
                                         f"(2026-06-01T10:31:05Z), got {text!r}") from exc
    if moment.tzinfo is None:
        raise argparse.ArgumentTypeError(f"say the time zone of {text!r} (Z for UTC, or +02:00)")
    return TimeBound(moment.astimezone(UTC).timestamp(), True)


EARLIEST, LATEST = TimeBound(-math.inf), TimeBound(math.inf)


@dataclass(frozen=True)
class MeasureJob:
    """One `measure` run over its inputs: what the command line asked for, checked; a batch gives each worker
    its own copy with one input."""

    inputs: tuple[str, ...]
    calibration: str  # a YAML file, 'none' or 'bag'
    targets: str
    settings: MeasurementSettings
    image_topic: str | None = None
    start_time: TimeBound = EARLIEST  # seconds after each bag's first image, unless absolute
    end_time: TimeBound = LATEST
    video_step: int = 1
    csv: str | None = None
    overlay: str | None = None
    idealized: str | None = None
    json: bool = False
    quiet: bool = False
    background: str | None = None  # an image of the empty scene: evens the light for sub-pixel shares
    # a video or bag is measured in segments of this many frames, each begun afresh (markers found anew,
    # weights and light rebuilt): the unit a cluster splits a long input into, same rows whoever measures it
    segment_frames: int = SEGMENT_FRAMES
    frame_range: tuple[int, int] | None = None  # (start, stop): these frames of the one video or bag only

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> MeasureJob:
        from ..classify import ClassifyError

        if args.video_step < 1:
            raise CliError("--video-step must be 1 or more", EXIT_USAGE)
        for option, value in (("--start-time", args.start_time), ("--end-time", args.end_time)):
            if math.isnan(value.seconds):
                raise CliError(f"{option} must be a time in seconds, got nan", EXIT_USAGE)
        if args.start_time.absolute == args.end_time.absolute and args.start_time.seconds > args.end_time.seconds:
            raise CliError(f"--start-time {args.start_time} lies after --end-time {args.end_time}: no frame "
                           "could be measured", EXIT_USAGE)
        try:
            settings = MeasurementSettings(threshold=args.threshold, object=args.object, channel=args.channel,
                                           roi=args.roi, open_px=args.open, close_px=args.close,
                                           area_mode=args.area_mode, levels=args.levels,
                                           sweep_step=args.sweep_step, tone_curve=args.tone_curve)
        except ClassifyError as exc:
            raise CliError(str(exc), EXIT_USAGE) from exc
        if args.segment_frames < 1:
            raise CliError("--segment-frames must be 1 or more", EXIT_USAGE)
        if args.idealized and args.calibration.lower() == "none":  # nothing was written, without a word
            raise CliError("--idealized writes the frames idealized by their calibration; with --calibration none "
                           "there is none (the raw frames are the input)", EXIT_USAGE)
        names = {f.name for f in fields(cls)} - {"settings", "inputs", "frame_range"}
        return cls(inputs=tuple(args.inputs), settings=settings, **{name: getattr(args, name) for name in names})


def frame_file_name(name: str) -> str:
    """The image file an overlay or idealized frame is written to, named after its frame: an image's stem, a
    video's or bag's frame as stem_NNNNNN (every frame its own file; they all wrote STEM.png before)."""
    base, _, index = name.rpartition("#")
    stem = f"{Path(base).stem}_{int(index):06d}" if base and index.isdigit() else Path(name).stem
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in stem) + ".png"


def measure(job: MeasureJob, on_frame: Callable[[int, int], None] | None = None,
            stop: Callable[[], bool] | None = None, part: bool = False) -> tuple[int, list[dict]]:
    """Measure every frame of the job's inputs; (exit code, CSV rows; EXIT_INTERRUPTED when interrupted, with
    what was measured so far). `on_frame(index, total)` (a batch worker) replaces the per-frame lines on stdout;
    `stop()` true (the batch was interrupted) ends the series as Ctrl-C does. `part`: one range of a longer
    input (a cluster task): the rows only, no file written and no verdict on the run."""
    import cv2

    from ..bags import BagError, bag_images
    from ..calib_io import CalibrationFileError, read_calibration, write_calibration
    from ..camera_info import info_to_camera
    from ..classify import ClassifyError
    from ..frames import (
        IMAGE_SUFFIXES,
        VIDEO_SUFFIXES,
        InputError,
        decodable_ahead,
        decoded,
        expand_inputs,
        is_bag,
        iter_frames,
        tiff_pages,
        video_frame_count,
    )
    from ..idealize import FrameSizeError
    from ..light import LightError
    from ..locate import NO_CALIBRATION_FOR_OFFSET
    from ..overlay import draw_overlay
    from ..targets import TargetsError, TargetsNotFoundError, TargetsSpec

    say = progress(job.quiet)
    camera = port_camera = file_camera = conditions = None
    from_bag = job.calibration.lower() == "bag"  # each frame with the camera_info recorded before it
    if job.calibration.lower() not in ("none", "bag"):
        try:
            calibration = read_calibration(job.calibration)
        except CalibrationFileError as exc:
            raise CliError(str(exc)) from exc
        camera, port_camera = calibration.camera, calibration.port_camera()
        file_camera, conditions = camera, calibration.metadata
    try:
        targets = TargetsSpec.load(job.targets)
    except TargetsError as exc:
        raise CliError(str(exc)) from exc
    try:
        files = expand_inputs(list(job.inputs))  # photos OpenCV does not read: said by the command (cmd_measure)
    except InputError as exc:
        raise CliError(str(exc)) from exc
    videos = [f for f in files if f.suffix.lower() in VIDEO_SUFFIXES]
    bags = [f for f in files if is_bag(f)]
    stacks = {f: len(pages) for f in files if (pages := tiff_pages(f))}  # a TIFF stack's pages are a series
    trimmed = math.isfinite(job.start_time.seconds) or math.isfinite(job.end_time.seconds)
    if trimmed and not bags:
        raise CliError("--start-time and --end-time pick bag frames by their header stamp; the inputs hold no bag",
                       EXIT_USAGE)
    if from_bag and len(bags) != len(files):
        raise CliError("--calibration bag needs rosbag2 inputs (their recorded camera_info)", EXIT_USAGE)
    try:
        bag_frames = 0
        for bag in bags:
            topic, count, others = bag_images(bag, job.image_topic)
            bag_frames += count
            if others and job.image_topic is None:  # a choice among the bag's image topics is said
                say(f"{bag.name}: measuring {topic} (the raw frames first, then zstd, then compressed, then video "
                    "packets: the same frames, lossless first, inter-frame last); also recorded and not read: "
                    f"{', '.join(others)}")
        # a calibration file for another camera than the one a bag's camera_info describes: said in each result
        other_camera = {} if file_camera is None else {
            b.name: problem for b in bags if (problem := _other_camera(b, job.image_topic, calibration))}
    except BagError as exc:
        raise CliError(str(exc)) from exc
    total = (sum(video_frame_count(v) // job.video_step for v in videos) + bag_frames + sum(stacks.values())
             + len(files) - len(videos) - len(bags) - len(stacks))
    series = videos + list(stacks) + bags
    if job.frame_range is not None:
        if len(files) != 1 or not (videos or bags):
            raise CliError("a frame range applies to one video or bag", EXIT_USAGE)
        total = len(range(job.frame_range[0], job.frame_range[1], job.video_step if videos else 1))
    csv_path = None if part else Path(job.csv) if job.csv else (Path(f"{series[0].stem}_area.csv") if series
                                                                 else None)
    check_outputs([("--csv", str(csv_path) if csv_path else None, True),  # its plot goes beside it
                   ("--overlay", job.overlay, True), ("--idealized", job.idealized, True)],
                  [*job.inputs, job.calibration if job.calibration.lower() not in ("none", "bag") else None,
                   job.targets, job.background], "measured")
    single_overlay = job.overlay and Path(job.overlay).suffix.lower() in IMAGE_SUFFIXES
    if job.idealized and Path(job.idealized).suffix.lower() in IMAGE_SUFFIXES and not Path(job.idealized).is_dir():
        raise CliError(f"--idealized {job.idealized} names an image, but it is a folder: the idealized frames and "
                       "their camera (ideal_camera.yaml) are written into it; give a folder name", EXIT_USAGE)
    sources = [*job.inputs, *files, job.calibration if job.calibration.lower() not in ("none", "bag") else None,
               job.targets, job.background]
    if csv_path is not None and csv_path.suffix.lower() == ".png":
        raise CliError(f"--csv {csv_path}: the series' plot is written beside it as {csv_path.with_suffix('.png')}, "
                       "over the CSV itself; name the CSV .csv", EXIT_USAGE)
    if csv_path is not None and total > 1:  # the plot beside the CSV, named after it (drawn for 2+ frames)
        check_outputs([("--csv", str(csv_path.with_suffix(".png")), False)], sources, "measured",
                      "its plot ")
    for option, folder in (("--overlay", None if single_overlay else job.overlay), ("--idealized", job.idealized)):
        if folder:  # each frame's image in the folder, named after its input: not over an input of the same name
            check_outputs([(option, str(Path(folder) / frame_file_name(f.name)), False) for f in files], sources,
                          "measured", "its image ")
    check_writable([("--overlay", job.overlay, not single_overlay), ("--csv", csv_path, False),  # default too
                    ("--idealized", job.idealized, True)], "measured")
    folders = {option: Path(value).absolute() for option, value in (("--overlay", job.overlay),
                                                                    ("--idealized", job.idealized))
               if value and not (option == "--overlay" and single_overlay)}
    for option, folder in folders.items():
        if csv_path is not None and Path(csv_path).absolute() == folder:
            raise CliError(f"--csv {csv_path} and {option} {folder} name the same path: a file and a folder "
                           "cannot be one; nothing was measured", EXIT_USAGE)
    if single_overlay and total > 1:
        raise CliError(f"--overlay {job.overlay} names one image but the input has {total} frames; "
                       "give a folder", EXIT_USAGE)

    if targets.object_plane_offset_m is not None and camera is None and not from_bag:
        raise CliError(NO_CALIBRATION_FOR_OFFSET)

    background = None
    if job.background:
        from ..frames import read_image

        background_notes: list[str] = []
        background, problem = read_image(Path(job.background), notes=background_notes)
        if background is None:
            raise CliError(f"--background {job.background}: {problem}", EXIT_USAGE)
        for note in background_notes:
            say(f"--background {job.background}: {note}")

    def new_measurer(camera: BrownCamera | None, recorded_conditions: dict | None = None
                     ) -> AreaMeasurer | PortAreaMeasurer:
        try:  # the exact port model for frames of the port file's camera, not its plumb_bob stand-in
            return job.settings.measurer(camera, targets, port_camera if camera is file_camera else None,
                                         background, conditions if camera is file_camera else recorded_conditions)
        except (ClassifyError, LightError) as exc:
            raise CliError(str(exc), EXIT_USAGE) from exc
        except TargetsError as exc:
            raise CliError(str(exc)) from exc

    def auto_notes(recorded: dict | None, source: str) -> list[str]:
        """What the run says of the tone curve and the reading a calibration's metadata records, for each set
        to auto that the metadata decides."""
        notes = []
        if recorded and job.settings.tone_curve == "auto" and "tone_curve" in recorded:
            curve = job.settings.tone_curve_for(recorded)
            if curve != recorded["tone_curve"]:  # the excess-green index is no light to decode
                notes.append(f"tone curve {curve}: {source} records {recorded['tone_curve']}, which does not "
                             f"apply to --object {job.settings.object}")
            else:
                evidence = recorded.get("tone_curve_evidence", "no evidence recorded")
                notes.append(f"tone curve {curve}, as {source} records it ({evidence}); --tone-curve sets another")
        if recorded and job.settings.area_mode == "auto" and "area_mode" in recorded:
            evidence = recorded.get("area_mode_evidence", "no evidence recorded")
            notes.append(f"area mode {recorded['area_mode']}, as {source} records it ({evidence}); "
                         "--area-mode sets another")
        return notes

    said: set[str] = set()  # what a bag's metadata made the run say, said once

    def say_once(note: str) -> None:
        if note not in said:
            said.add(note)
            say(note)

    def bag_conditions(camera: BrownCamera | None, text: str | None) -> dict | None:
        """The metadata recorded beside the bag's camera_info (camera_info/metadata) if it is that camera's."""
        if text is None:
            return None
        try:
            recorded = metadata_for(camera, text)
        except ValueError as exc:
            say_once(f"the bag's camera_info/metadata is not used: {exc}")
            return None
        for note in auto_notes(recorded, "the bag's camera_info/metadata"):
            say_once(note)
        return recorded

    measurer = new_measurer(camera) if not from_bag else None
    recorded_metadata = None  # a bag's camera_info/metadata the measurer was made with
    for note in auto_notes(conditions, job.calibration):
        say(note)
    if job.settings.area_mode == "auto" and not from_bag and camera is not None and "area_mode" not in (conditions
                                                                                                       or {}):
        why = (conditions or {}).get("area_mode_evidence", "no board views of this camera were measured with it: "
                                     "made elsewhere or from a ChArUco board")
        say(f"area mode subpixel: {job.calibration} records no reading judged on its views ({why}); the shares "
            "are exact on renders, but some cameras' real photos read better counted: calibrate with veg-area "
            "calibrate on chessboard photos to judge it, or set --area-mode")
    if job.idealized and camera is not None:
        folder = Path(job.idealized)
        write_calibration(folder / "ideal_camera.yaml", camera.ideal(), "ideal",
                          {"idealized_from": str(Path(job.calibration).resolve())})
    rows: list[dict] = []
    # each row on disk before the next frame; begun at the first frame measured with an object in it (a run of
    # errors or empty frames keeps an earlier table)
    log = RowLog(csv_path, CSV_COLUMNS, lambda row: not row["error"] and not _no_object(row)) \
        if csv_path is not None else None
    warned: dict[str, int] = {}
    dictionary_hinted = False  # the other ArUco families tried once, on the first frame without a target
    unwritten: list[str] = []  # overlay or idealized images that could not be written
    stamps: list[tuple[float, float]] = []  # (stamp, since its bag's start) of the frames left out by the range
    starts: dict[str, float] = {}

    def run_start(name: str) -> float:
        """The header stamp of the first image of the bag named `name` (once per bag)."""
        if name not in starts:
            from ..bags import bag_first_stamp
            from ..frames import shown_name

            path = next(f for f in files if shown_name(Path(f)) == name)
            starts[name] = bag_first_stamp(path, job.image_topic) or 0.0
        return starts[name]

    interrupted = False
    segment = None
    try:
        # the next frames decoded while this one is measured (same frames, same order)
        ahead = decodable_ahead(files)
        frames = iter_frames(files, job.video_step, job.image_topic, job.frame_range, encoded=ahead)
        if ahead:  # decoded (a Motion-JPEG video's frames by two threads) and greyed off this thread
            frames = decoded(frames)
        for index, frame in enumerate(frames, 1):
            row = {"frame": frame.name, "time_s": frame.time_s, "error": ""}
            line = ""
            if frame.position is not None and (where := (frame.name.rsplit("#", 1)[0],
                                                        frame.position // job.segment_frames)) != segment:
                segment = where  # a new input or segment begins afresh
                if measurer is not None:
                    measurer.start_segment()
            if frame.stamp is not None:
                row["stamp_sec"], row["stamp_nanosec"] = frame.stamp
                if trimmed:  # only then is the bag's first image read
                    since = frame.time_s - run_start(frame.name.rsplit("#", 1)[0])
                    if not (job.start_time.at(frame.time_s, since) <= 0 <= job.end_time.at(frame.time_s, since)):
                        stamps.append((frame.time_s, since))
                        continue
            try:
                if frame.image is None:
                    row["lost"] = frame.lost  # not a CSV column: counted at the end
                    raise InputError(f"skipped: {frame.problem}")
                if from_bag:  # as the live area node: the latest camera_info, a new measurer when it changes
                    if frame.camera_info is None:
                        raise InputError(frame.camera_info_problem or "no camera_info recorded before this frame")
                    recorded = info_to_camera(frame.camera_info)
                    if recorded != camera or frame.camera_metadata != recorded_metadata or measurer is None:
                        camera, recorded_metadata = recorded, frame.camera_metadata
                        measurer = new_measurer(camera, bag_conditions(camera, recorded_metadata))
                result = measurer.measure(frame.image, keep_images=bool(job.overlay or job.idealized),
                                          grey=frame.grey)
                result.warnings.extend(frame.notes)
                if frame.name.rsplit("#", 1)[0] in other_camera:
                    result.warnings.append(other_camera[frame.name.rsplit("#", 1)[0]])
            except (InputError, FrameSizeError, TargetsError, ClassifyError, ValueError) as exc:
                if (not dictionary_hinted and isinstance(exc, TargetsNotFoundError) and exc.markers_found == 0
                        and targets.markers and frame.image is not None):
                    from ..board import to_grey
                    from ..board_hint import dictionary_hint

                    dictionary_hinted = True
                    exc = TargetsError(f"{exc}{dictionary_hint(targets.dictionary, to_grey(frame.image))}")
                row["error"] = str(exc)
                say(f"[{index}/{total}] {frame.name}: not measured, {exc}")
            else:
                row.update(result.summary())
                for warning in result.warnings:  # each kind in full once; how often, at the end
                    kind = warning.split(":", 1)[0]
                    if kind not in warned:
                        say(f"[{index}/{total}] {frame.name}: warning: {warning}")
                    warned[kind] = warned.get(kind, 0) + 1
                if on_frame is None and (not job.json or index % 25 == 0 or index == total):
                    line = (f"[{index}/{total}] {frame.name}: Af = {result.area_m2:.6g} ± {result.area_std_m2:.2g} m² "
                            f"({result.pixel_count} px, threshold {result.threshold:g}, {result.scale.kind} scale"
                            f"{'' if result.calibrated else ', UNCALIBRATED'})")
                images = []  # the images this frame asks for, while they can be written (a full disk: none more)
                if job.overlay and not unwritten:
                    target = Path(job.overlay) if single_overlay else Path(job.overlay) / frame_file_name(frame.name)
                    images.append((target, draw_overlay(result)))
                if job.idealized and camera is not None and not unwritten:
                    images.append((Path(job.idealized) / frame_file_name(frame.name), result.image))
                for target, image in images:
                    target.parent.mkdir(parents=True, exist_ok=True)
                    if not cv2.imwrite(str(target), image):
                        unwritten.append(str(target))
                        say(f"[{index}/{total}] {frame.name}: {target} could not be written (a full disk?); no "
                            "more overlay or idealized images are written, the rows go on")
                        break
            rows.append(row)
            if log is not None:  # on disk before it is shown
                log.add(csv_row(row))
            if line:
                print(line, file=sys.stderr if job.json else sys.stdout, flush=True)
            if job.json:
                print(json.dumps({k: v for k, v in row.items() if (k != "error" or v) and k != "lost"}), flush=True)
            if on_frame is not None:
                on_frame(index, total)
            if stop is not None and stop():
                raise KeyboardInterrupt
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM on a long video or bag: what was measured is kept (CSV, plot)
        interrupted = True
    except BrokenPipeError:  # stdout closed (`... --json | head -n 1`): stop quietly, the CSV keeps what was done
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        interrupted = True
    if part:
        return (EXIT_INTERRUPTED if interrupted else EXIT_OK), rows
    # counted from the rows: the frame in hand when Ctrl-C came is left out of both
    measured = sum(1 for row in rows if not row["error"])
    if warned and measured > 1:
        say("warnings: " + "; ".join(f"{kind} on {count} of {measured} frames" for kind, count in warned.items()))

    if log is not None and not log.begun and rows and csv_path.exists():  # errors or empty frames only
        say(f"time series not written: no frame was measured with an object in it (the existing {csv_path} "
            "is kept)")
    elif log is not None and rows:  # a new file lists every frame, with its error where there is one
        log.close(write_held=True)
        say(f"time series: {csv_path}")
        if len(rows) > 1:
            say(f"plot: {plot_series(rows, csv_path)}")
    if interrupted:  # the frame in hand when Ctrl-C came is not in the rows
        say(f"interrupted after {len(rows)} of {total} frames ({measured} measured)"
            + (f"; the series so far: {csv_path}" if csv_path is not None and rows else ""))
        return EXIT_INTERRUPTED, rows
    if measured == 0:
        reasons = sorted({r["error"] for r in rows})
        if not rows and stamps:  # every frame fell outside the time range
            raise CliError(f"no frame measured: no frame lies between --start-time {job.start_time} and "
                           f"--end-time {job.end_time} (the frames lie {min(s for _, s in stamps):.3f} to "
                           f"{max(s for _, s in stamps):.3f} s after their bag's first image, stamped "
                           f"{min(t for t, _ in stamps):.3f} to {max(t for t, _ in stamps):.3f} s)")
        raise CliError(f"no frame measured: {'; '.join(reasons)[:500] or 'the inputs hold no frame'}")
    if measured < len(rows):
        say(f"{len(rows) - measured} of {len(rows)} frames not measured (see 'error')")
    if not part and len(rows) > 1:  # the run as a whole: its mean and that mean's uncertainty
        from ..series import series_summary, summary_line

        say(summary_line(series_summary(rows)))
    if no_object_anywhere(rows):
        where = "the frame" if measured == 1 else f"any of the {measured} frames"
        print(f"veg-area measure: no object found in {where} measured (see the warnings); check the threshold, "
              "--object and the ROI", file=sys.stderr, flush=True)
        return EXIT_FAILED, rows
    if unwritten:  # the rows are whole, the images are not: said even when quiet, and not a success
        print(f"veg-area measure: {unwritten[0]} could not be written (a full disk?), nor any image after it; the "
              f"{measured} frames measured are kept" + (f" in {csv_path}" if csv_path is not None else ""),
              file=sys.stderr, flush=True)
        return EXIT_FAILED, rows
    problem = frames_lost(rows, total)
    if problem:  # said even when quiet: the series has holes
        print(f"veg-area measure: {problem}; the {measured} frames measured are kept"
              + (f" in {csv_path}" if csv_path is not None else ""), file=sys.stderr, flush=True)
        return EXIT_FAILED, rows
    return EXIT_OK, rows


def _no_object(row: dict) -> bool:
    warnings = row.get("warnings", ())  # a list, or the CSV cell that joins it
    return any(w.startswith("no object found") for w in (warnings.split(" | ") if isinstance(warnings, str)
                                                          else warnings))


def no_object_anywhere(rows: list[dict]) -> bool:
    """Whether frames were measured and none held an object (Af 0 everywhere: the settings or the scene are
    wrong, not the plant gone): a run like that exits 1."""
    measured = [row for row in rows if not row["error"]]
    return bool(measured) and all(_no_object(row) for row in measured)


def frames_lost(rows: list[dict], total: int | None = None) -> str:
    """What was lost to damaged or unreadable input ('' when nothing): a run that lost frames exits 1. `total`:
    the frames the inputs declare (default: the rows, a lost stretch counted by its length)."""
    lost = sum(row.get("lost", 0) for row in rows)
    if not lost:
        return ""
    if total is None:
        total = sum(1 for row in rows if not row.get("lost")) + lost
    where = "; ".join(f"{row['frame']}: {row['error'].removeprefix('skipped: ')}" for row in rows if row.get("lost"))
    return f"{lost} of {total} frames could not be read ({where[:400]})"


def plot_series(rows: list[dict], csv_path: Path) -> Path:
    from ..report import plot_area_series

    nan = float("nan")
    times, title, label = series_axis(rows, csv_path.stem.encode("utf-8", "surrogateescape").decode("utf-8", "replace"))
    return plot_area_series(times, [r.get("area_m2", nan) for r in rows], [r.get("area_std_m2", nan) for r in rows],
                            csv_path.with_suffix(".png"), title=title, time_label=label)


def series_axis(rows: list[dict], name: str) -> tuple[list[float], str, str]:
    """The Af(t) plot's time axis: seconds since the first frame (a bag's stamps are seconds since 1970: its
    start is said in the title as a date), or frame numbers where frames have no time."""
    if not all(r["time_s"] is not None for r in rows):
        return list(range(len(rows))), f"Projected area, {name}", "frame"
    start = min(r["time_s"] for r in rows)
    begun = ""
    if any("stamp_sec" in r for r in rows):
        from datetime import datetime

        begun = f", from {datetime.fromtimestamp(start, UTC).isoformat(timespec='milliseconds')}"
    return [r["time_s"] - start for r in rows], f"Projected area, {name}{begun}", "time since the first frame [s]"


def csv_row(row: dict) -> dict:
    """A measured row as the CSV holds it: lists joined into one cell."""
    return {**row, "missing_targets": " ".join(map(str, row.get("missing_targets", []))),
            "warnings": " | ".join(row.get("warnings", []))}



def _other_camera(bag: Path, image_topic: str | None, calibration: CalibrationFile) -> str:
    """The warning for a bag measured with a calibration file of another camera than its recorded camera_info
    describes; '' where they agree or the bag has no calibrated camera_info."""
    from ..bags import bag_camera_info
    from ..camera_info import info_to_camera, other_camera

    found = bag_camera_info(bag, image_topic)
    if found is None:
        return ""
    topic, fields = found
    try:
        recorded = info_to_camera(fields)
    except ValueError:  # an uncalibrated camera_info (all zeros) says nothing of the camera
        return ""
    std = calibration.metadata.get("std")
    problem = other_camera(calibration.camera, recorded, std.get("fx") if isinstance(std, dict) else None)
    return (f"calibration of another camera: {problem} ({topic}); measure with --calibration bag, or with this "
            "camera's file") if problem else ""
