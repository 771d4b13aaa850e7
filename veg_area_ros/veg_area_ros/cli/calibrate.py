"""`veg-area calibrate`: self-calibrating bundle adjustment from board images or videos, or a flat port fitted
in front of an air calibration (`--port --lens`); writes a camera_info YAML, refusing to replace a better one."""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from .common import (
    EXIT_REFUSED,
    EXIT_USAGE,
    CliError,
    check_outputs,
    check_writable,
    distance_m,
    liquid_index,
    positive_float,
    progress,
)

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator

    import numpy as np

    from ..board import BoardSpec, Detection
    from ..calibration import CalibrationResult
    from ..frames import Frame
    from ..guidance import ViewStats
    from ..tone_evidence import BoardCase, ToneChoice

VIEWS_PER_VIDEO = 60  # consecutive frames add little but time
DETECT_WORKERS = 2  # board searches at once: the two cores of a lab PC (OpenCV runs them without the GIL)


DEFAULT_LOSS, DEFAULT_OUTLIER_SIGMA = "linear", 4.0  # the board fit's
DEFAULT_WATER_INDEX, DEFAULT_ABSORBED_DISTANCE_M = 1.333, 0.7  # the port's
FRAME_LINES = 30  # frames with a line each; then one line every PROGRESS_EVERY_S
PROGRESS_EVERY_S = 2.0


def add_parser(sub: argparse._SubParsersAction) -> None:
    cal = sub.add_parser("calibrate", help="self-calibrating bundle adjustment from board images or videos")
    cal.add_argument("inputs", nargs="*", help="images, folders of images, TIFF stacks, videos, bags (underwater "
                                               "views with --port); a quoted glob is expanded as the shell would")
    cal.add_argument("--board",
                     help="chessboard:COLSxROWS:SQUARE_M | charuco:SXxSY:SQUARE_M:MARKER_M:DICT (add :legacy "
                          "for OpenCV's layout before 4.6 and calib.io's) | circles:COLSxROWS:SPACING_M "
                          "(asymmetric grid) | circles:COLSxROWS:SPACING_M:symmetric")
    cal.add_argument("-o", "--output", required=True, help="camera_info YAML to write")
    cal.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
    cal.add_argument("--report", metavar="DIR", help="write residual and coverage plots (PNG) here")
    cal.add_argument("--medium", default="unspecified", choices=["air", "water", "unspecified"],
                     help="medium of the calibration: say it (recorded as 'unspecified' otherwise)")
    cal.add_argument("--distance", type=distance_m, default=None,
                     help="camera-to-board distance of the calibration, metres (recorded in the file)")
    cal.add_argument("--camera-name", default="camera")
    cal.add_argument("--model", choices=["auto", "plumb_bob", "rational_polynomial", "equidistant"],
                     help="camera model (ROS's distortion_model): auto (the default) fits all three and picks the "
                          "one that best predicts held-out views; plumb_bob for most lenses, rational_polynomial "
                          "and equidistant (fisheye) for wide ones")
    cal.add_argument("--loss", default=DEFAULT_LOSS, choices=["linear", "huber", "soft_l1", "cauchy"],
                     help="robust loss for the bundle adjustment")
    cal.add_argument("--outlier-sigma", type=positive_float, default=DEFAULT_OUTLIER_SIGMA,
                     help="reject points beyond this many robust standard deviations")
    cal.add_argument("--no-outlier-rejection", action="store_true")
    cal.add_argument("--video-step", type=int, default=0,
                     help=f"use every Nth frame of a video or bag (0: about {VIEWS_PER_VIDEO} per video or bag, one "
                          "from each run of frames at a varying place, so no pose cycle of the camera is sampled at "
                          "one phase)")
    cal.add_argument("--replace", "--force", dest="replace", action="store_true",
                     help="write the output even where the calibration it holds is judged better (by projection "
                          "uncertainty, views and coverage, not RMS: fewer views always fit with a lower RMS)")
    cal.add_argument("--image-topic", default=None,
                     help="image topic of a bag of board views (default: its only image topic; a stereo pair's "
                          "bag holds two)")
    cal.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    cal.add_argument("--port", metavar="flat:DISTANCE_M:THICKNESS_M:N_GLASS",
                     help="an explicit flat port in front of the --lens air calibration: fitted (normal, distance) "
                          "from the underwater views given, or taken as measured when none are given")
    cal.add_argument("--lens", metavar="AIR_YAML", help="the lens's calibration in air (with --port)")
    cal.add_argument("--water-index", type=liquid_index, default=DEFAULT_WATER_INDEX,
                     help="refractive index of the water")
    cal.add_argument("--fit-water-index", action="store_true", help="fit the water's index too (with --port)")
    cal.add_argument("--absorbed-distance", type=distance_m, default=DEFAULT_ABSORBED_DISTANCE_M, metavar="M",
                     help="distance of the plane for the absorbed plumb_bob equivalent written for ROS tools")
    cal.set_defaults(func=cmd_calibrate)


@dataclass
class BoardViews:
    """The board views found in the inputs, and what was skipped and why (file names)."""

    views: list = field(default_factory=list)
    image_size: tuple[int, int] | None = None
    seen: int = 0
    unreadable: list[str] = field(default_factory=list)
    no_board: list[str] = field(default_factory=list)
    wrong_size: list[str] = field(default_factory=list)
    repeated: list[str] = field(default_factory=list)
    notes: dict[str, list[str]] = field(default_factory=dict)  # what reading assumed (EXIF, 16-bit), by its kind
    guide: object | None = None  # guidance.CalibrationGuide over the views: their variety, what is still needed


def collect_views(files: list[Path], board: BoardSpec, step: int, say: Callable[[str], None],
                  image_size: tuple[int, int] | None = None, size_source: str = "the first image",
                  spread: bool = False, image_topic: str | None = None) -> BoardViews:
    """Detect the board in every frame (every `step`th of a video; `spread`: one in each run of `step` at a
    varying place, see frames.iter_video), with a progress line per frame for the first FRAME_LINES frames and
    then one every PROGRESS_EVERY_S (a frame that could not be read or has another size is always said).
    Frames of another size than `image_size` (default: the first readable frame's) are skipped; in a video, a
    pose held still over several frames counts once."""
    from ..calibration import View, same_pose
    from ..frames import decodable_ahead, iter_frames
    from ..guidance import CalibrationGuide, view_stats
    from ..pipeline import ordered_map, prefetched

    found = BoardViews(image_size=image_size)
    last_kept: dict[str, object] = {}  # per video: the last view kept
    said_at = [-math.inf]

    def frame_line(seen: int, text: str) -> None:
        if seen <= FRAME_LINES:
            say(text)
        elif time.monotonic() - said_at[0] >= PROGRESS_EVERY_S:
            said_at[0] = time.monotonic()
            say(f"[{seen}] {len(found.views)} views so far, {len(found.no_board)} frames without a board, "
                f"{len(found.repeated)} repeats; {text.split('] ', 1)[-1]}")

    def detect(frame: Frame) -> tuple[Detection | None, ViewStats | None]:
        """The board, and the numbers the guidance judges the view by (on the worker, beside the search)."""
        detection = None if frame.image is None else board.detect(frame.image)
        if detection is None:
            return None, None
        return detection, view_stats(detection, frame.image, board, frame.image.shape[1::-1])

    # frames searched by two threads (OpenCV releases Python's lock), judged here in their order; a video's
    # frames also decoded in a thread of their own
    # the board is found in grey: colour costs time
    frames = iter_frames(files, step, image_topic, grey=True, spread=spread, bag_step=step)
    if decodable_ahead(files):
        frames = prefetched(frames, depth=2 * DETECT_WORKERS)
    for frame, (detection, stats) in ordered_map(detect, frames, workers=DETECT_WORKERS):
        found.seen += 1
        seen = found.seen
        if frame.image is None:
            found.unreadable.append(frame.name)
            say(f"[{seen}] {frame.name}: skipped, {frame.problem}")
            continue
        for note in frame.notes:  # an EXIF orientation not applied, a 16-bit depth: said once for all frames
            found.notes.setdefault(note.split(":", 1)[0], []).append(note)
        size = (frame.image.shape[1], frame.image.shape[0])
        if found.image_size is None:
            found.image_size = size
        elif size != found.image_size:
            found.wrong_size.append(frame.name)
            say(f"[{seen}] {frame.name}: skipped, {size[0]}x{size[1]} differs from {size_source}'s "
                f"{found.image_size[0]}x{found.image_size[1]}")
            continue
        if detection is None:
            found.no_board.append(frame.name)
            frame_line(seen, f"[{seen}] {frame.name}: no {board.kind} board found")
            continue
        if frame.position is not None:  # a video's (a bag's) frame: the board held still a while is one view
            video = frame.name.rsplit("#", 1)[0]
            if video in last_kept and same_pose(detection, last_kept[video], found.image_size):
                found.repeated.append(frame.name)
                frame_line(seen, f"[{seen}] {frame.name}: same pose as the view before it, counted once")
                continue
            last_kept[video] = detection
        found.views.append(View(frame.name, detection))
        if found.guide is None:
            found.guide = CalibrationGuide(board, found.image_size)
        verdict = found.guide.offer(detection, frame.image, keep=True, stats=stats)  # the user chose them: advice
        advice = f" ({verdict.reason})" if not verdict.kept and verdict.kind != "similar" else ""
        frame_line(seen, f"[{seen}] {frame.name}: {len(detection)} board points{advice}")
    for notes in found.notes.values():
        say(f"{len(notes)} of {found.seen} frames: {notes[-1]}")
    if found.seen > FRAME_LINES:
        say(f"{found.seen} frames: {len(found.views)} views, {len(found.no_board)} without a board, "
            f"{len(found.repeated)} repeats of the pose before")
    if found.guide is not None:
        needed = found.guide.still_needed()
        say(f"still needed: {needed}" if needed else "variety of the views: enough for every parameter")
    return found


def _board_and_files(args: argparse.Namespace, say: Callable[[str], None]) -> tuple[BoardSpec, list[Path]]:
    from ..bags import BagError, bag_image_count
    from ..board import BoardSpec, BoardSpecError
    from ..frames import InputError, expand_inputs, is_bag

    try:
        board = BoardSpec.parse(args.board)
    except BoardSpecError as exc:
        raise CliError(str(exc), EXIT_USAGE) from exc
    unread: list[str] = []
    try:
        files = expand_inputs(args.inputs, unread, archives=True)
    except InputError as exc:
        raise CliError(str(exc)) from exc
    bags = [f for f in files if is_bag(f)]
    if args.image_topic and not bags:
        raise CliError(f"--image-topic {args.image_topic} picks a bag's image topic; the inputs hold no bag",
                       EXIT_USAGE)
    try:  # a bag with several image topics (a stereo pair, raw beside compressed) is refused before any work
        for bag in bags:
            bag_image_count(bag, args.image_topic)
    except BagError as exc:
        raise CliError(str(exc), EXIT_USAGE) from exc
    for note in unread:
        say(f"warning: {note}")
    return board, files


HINT_FRAMES = 3  # frames a board spec's likely mistakes are tried on when it is found in none


def _hint(board: BoardSpec, files: list[Path], step: int, image_topic: str | None = None) -> str:
    """What board a few of the frames hold instead of `board`, said with the mistake, or ''."""
    from itertools import islice

    from ..board_hint import board_hint
    from ..frames import iter_frames

    frames = iter_frames(files, step, image_topic, grey=True, spread=True, bag_step=step)
    greys = [frame.image for frame in islice((f for f in frames if f.image is not None), HINT_FRAMES)]
    return board_hint(board, greys)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from ..archive import is_archive
    from ..bags import bag_image_count
    from ..calib_io import CalibrationFileError, fit_metadata, read_calibration, write_calibration
    from ..calibration import CalibrationError, calibrate
    from ..camera_model import implausibility
    from ..frames import IMAGE_SUFFIXES, VIDEO_SUFFIXES, is_bag, video_frame_count
    from ..replacement import judge

    say = progress(args.quiet)
    output = Path(args.output)
    check_outputs([("-o", args.output, False), ("--report", args.report, True)], [*args.inputs, args.lens],
                  "calibrated")
    check_writable([("-o", output, False), ("--report", args.report, True)], "calibrated")
    if args.fit_water_index and not (args.port and args.lens and args.inputs):
        raise CliError("--fit-water-index fits the water's index from underwater views through a port: it needs "
                       "--port, --lens and the underwater views", EXIT_USAGE)
    if args.no_outlier_rejection and args.outlier_sigma != DEFAULT_OUTLIER_SIGMA:
        raise CliError(f"--outlier-sigma {args.outlier_sigma:g} sets where outliers are rejected, and "
                       "--no-outlier-rejection rejects none: give one of them", EXIT_USAGE)
    if args.port or args.lens:
        if args.model is not None:
            raise CliError("--model does not apply with --port/--lens: the lens's model is its air calibration's "
                           "(--lens)", EXIT_USAGE)
        unused = [option for option, given in (
            ("--distance", args.distance is not None), ("--medium air", args.medium == "air"),
            ("--report", args.report is not None), ("--loss", args.loss != DEFAULT_LOSS),
            ("--outlier-sigma", args.outlier_sigma != DEFAULT_OUTLIER_SIGMA),
            ("--no-outlier-rejection", args.no_outlier_rejection)) if given]
        if unused:  # the port's fit has none of these; its file is for water at --absorbed-distance
            raise CliError(f"{', '.join(unused)} {'does' if len(unused) == 1 else 'do'} not apply with --port/--lens "
                           "(the port's file is for water; its plane is --absorbed-distance)", EXIT_USAGE)
        if output.exists() and not args.replace:
            raise CliError(f"{output} exists: a port calibration is not judged against the one it holds; use "
                           "--replace to write over it", EXIT_REFUSED)
        return _calibrate_port(args, say)
    unused = [option for option, given in (
        ("--water-index", args.water_index != DEFAULT_WATER_INDEX),
        ("--absorbed-distance", args.absorbed_distance != DEFAULT_ABSORBED_DISTANCE_M)) if given]
    if unused:
        raise CliError(f"{', '.join(unused)} {'applies' if len(unused) == 1 else 'apply'} only with --port and --lens "
                       "(a lens behind a flat port)", EXIT_USAGE)
    if not args.inputs or not args.board:
        raise CliError("give the board (--board) and its images", EXIT_USAGE)
    board, files = _board_and_files(args, say)
    if args.video_step > 1 and all(f.suffix.lower() in IMAGE_SUFFIXES or is_archive(f) for f in files):
        raise CliError(f"--video-step {args.video_step} takes every Nth frame of a video; the inputs are images",
                       EXIT_USAGE)

    previous = None
    if output.exists() and not args.replace:
        try:
            previous = read_calibration(output)
        except CalibrationFileError as exc:
            raise CliError(f"{output} exists and is not a readable calibration ({exc}); "
                           "use --replace to replace it", EXIT_REFUSED) from exc

    step = args.video_step
    if step <= 0:
        counts = [video_frame_count(f) for f in files if f.suffix.lower() in VIDEO_SUFFIXES] + [
            bag_image_count(f, args.image_topic) for f in files if is_bag(f)]  # a bag is sampled as a video
        step = max(1, max(counts, default=0) // VIEWS_PER_VIDEO)
    found = collect_views(files, board, step, say, spread=args.video_step <= 0, image_topic=args.image_topic)

    if args.medium == "unspecified":
        say("warning: --medium not given: the calibration is recorded with medium 'unspecified' (say air or water: "
            "a calibration holds only in the medium it was made in)")
    if not found.views:
        if found.image_size is None:
            raise CliError(f"no readable image among the inputs ({len(found.unreadable)} unreadable)"
                           if found.unreadable else "the inputs hold no frame (an empty video or bag?)")
        hint = _hint(board, files, step, args.image_topic)
        raise CliError(f"no {board} board found in any of {found.seen} images{hint}; "
                       "supported boards: chessboard, charuco, circles (asymmetric, or :symmetric)")
    try:
        result = calibrate(found.views, found.image_size, robust_loss=args.loss,
                           outlier_sigma=None if args.no_outlier_rejection else args.outlier_sigma, progress=say,
                           model=args.model or "auto")
    except CalibrationError as exc:
        raise CliError(str(exc)) from exc
    problem = implausibility(result.camera)
    if problem:  # measure would refuse the file: it is not written
        raise CliError(f"the fit is no lens's ({problem}; fx {result.camera.fx:.1f} px, fy/fx "
                       f"{result.camera.aspect:.3g}, principal point ({result.camera.xp:.0f}, {result.camera.yp:.0f}) "
                       f"px): is --board {board} the board in the images? Nothing was written")

    tone = judge_tone_curve(found, files, board, result, step, args.video_step <= 0, say, args.image_topic)
    summary = result.summary()
    summary.update(unreadable=found.unreadable, no_board=found.no_board, wrong_size=found.wrong_size,
                   repeated_poses=found.repeated, output=str(output), variety=found.guide.summary(),
                   tone_curve=tone.as_dict())
    if previous is not None:
        verdict = judge(previous.camera, previous.metadata, result)
        if not verdict.replace:
            raise CliError(f"{output}: kept the calibration it holds: {verdict.reason}. Use --replace to write this "
                           "one anyway, or write elsewhere with -o", EXIT_REFUSED)
        say(f"{output}: replaced: {verdict.reason}")
    metadata = fit_metadata(summary, args.medium, args.distance, str(board), "veg-area calibrate")
    metadata.update(tone.metadata())  # the tone curve and edge trend measuring reads, and why
    write_calibration(output, result.camera, args.camera_name, metadata)
    if args.report:
        from ..report import write_calibration_report

        for path in write_calibration_report(result, args.report, found.guide, tone):
            say(f"report: {path}")
    for warning in result.warnings:
        say(f"warning: {warning}")
    if args.json:
        print(json.dumps(summary))
    else:
        print(format_calibration(result, output))
        print(f"tone curve {tone.curve}" + ("" if tone.decided else " (the default)") + f": {tone.reason}")
        if tone.edge_trend is not None:
            print(f"edge trend with exposure: {tone.edge_trend.reason}")
        if tone.reading is not None:
            print(f"area mode {tone.reading.mode}" + ("" if tone.reading.decided else " (the default)")
                  + f": {tone.reading.reason}")
    return 0


def judge_tone_curve(found: BoardViews, files: list[Path], board: BoardSpec, fit: CalibrationResult, step: int,
                     spread: bool, say: Callable[[str], None], image_topic: str | None = None) -> ToneChoice:
    """Which tone curve the camera encodes light with, judged on the calibration's own board views
    (tone_evidence): up to tone_evidence.MAX_TREND_VIEWS of them (MAX_VIEWS judge the curve), evenly over the
    board's sizes, read again one at a time (a frame is kept only while it is measured)."""
    from collections import Counter

    from ..frames import iter_frames, shown_name
    from ..tone_evidence import MIN_READING_VIEWS, choose_tone_curve, chosen_cases, judged_first

    named = Counter(view.name for view in found.views)  # a name two files share cannot be read again surely
    camera = fit.camera
    cases = chosen_cases([view for view in fit.used(found.views) if named[view.name] == 1], board, camera)
    if len(cases) < MIN_READING_VIEWS:  # said as such, without reading any frame again
        return choose_tone_curve(iter(()), board, camera)
    wanted = {case.name: case for case in cases}

    def sources(names: Iterable[str]) -> set[str]:  # images, and videos' frames NAME#N
        return set(names) | {name.rsplit("#", 1)[0] for name in names}

    judged = judged_first(cases)[1]
    read, read_first = sources(wanted), sources(judged)
    say(f"tone curve: measuring the board's black area in {len(cases)} views, near and far")
    # the judged views' files first: the others are then read under the curve taken only
    ordered = sorted((f for f in files if shown_name(f) in read), key=lambda f: shown_name(f) not in read_first)

    def views() -> Iterator[tuple[BoardCase, np.ndarray]]:
        for frame in iter_frames(ordered, step, image_topic, grey=True, spread=spread, bag_step=step):
            if frame.name in wanted and frame.image is not None:
                yield wanted.pop(frame.name), frame.image

    return choose_tone_curve(views(), board, camera, judged)


def _calibrate_port(args: argparse.Namespace, say: Callable[[str], None]) -> int:
    """`calibrate --port ... --lens air.yaml [underwater views]`: the port fitted from the views (or as measured)
    in front of the air calibration; written as the absorbed plumb_bob equivalent at --absorbed-distance with
    the lens and port in the file's veg_area_ros block."""
    from ..calib_io import CalibrationFileError, plain, provenance, read_calibration, write_calibration
    from ..camera_uncertainty import CameraCovariance
    from ..flat_port import PORT_KEY, FlatPort, FlatPortCamera, PortError, absorbed_at_distance, fit_port, port_to_dict

    if not (args.port and args.lens):
        raise CliError("--port and --lens go together: the port's numbers and the lens's air calibration",
                       EXIT_USAGE)
    try:
        start = FlatPort.parse(args.port, args.water_index)
        lens_file = read_calibration(args.lens)
    except (PortError, CalibrationFileError) as exc:
        raise CliError(str(exc), EXIT_USAGE) from exc
    if lens_file.metadata.get("medium") not in ("air", None):
        say(f"warning: {args.lens} says medium {lens_file.metadata.get('medium')!r}; --lens wants the air calibration")
    lens = lens_file.camera
    try:  # the lens's own uncertainty moves the fitted port and, when measuring, Af
        lens_covariance = CameraCovariance.from_conditions(lens_file.metadata, lens)
    except ValueError as exc:
        raise CliError(f"{args.lens}: the lens calibration's {exc}", EXIT_USAGE) from exc
    said_of_lens = []
    if lens_covariance is None:
        said_of_lens.append(f"the lens calibration {args.lens} records no covariance of its parameters (a file "
                            "not fitted by veg-area calibrate): the port's std and Af's std count the lens as exact")
        say(f"warning: {said_of_lens[0]}")
    std: dict[str, float] = {}
    summary: dict = {"port": "as measured"}
    port = start
    if args.inputs:
        if not args.board:
            raise CliError("give the board (--board) of the underwater views", EXIT_USAGE)
        board, files = _board_and_files(args, say)
        found = collect_views(files, board, max(1, args.video_step), say, lens.image_size, "the lens calibration",
                              image_topic=args.image_topic)
        views = [(view.detection.object_points, view.detection.image_points) for view in found.views]
        if len(views) < 2:
            raise CliError(f"{len(views)} underwater view(s) with the board: a port fit needs 2 or more")
        try:
            fit = fit_port(lens, views, start, fit_water_index=args.fit_water_index,
                           lens_covariance=None if lens_covariance is None else lens_covariance.matrix)
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
    metadata = {"medium": "water", **provenance("veg-area calibrate --port"), "lens_file": str(args.lens),
                PORT_KEY: port_to_dict(camera, std, args.absorbed_distance,
                                       None if lens_covariance is None else lens_covariance.as_dict()),
                "absorbed_residual_px": residual, **{k: v for k, v in summary.items() if k != "std"},
                **({"warnings": said_of_lens} if said_of_lens else {})}
    write_calibration(args.output, absorbed, args.camera_name, metadata)
    summary.update(output=str(args.output), distance_m=port.distance, tilt_x_deg=float(math.degrees(port.tilt_x_rad)),
                   tilt_y_deg=float(math.degrees(port.tilt_y_rad)), water_index=port.water_index,
                   absorbed_residual_px=residual, **({"warnings": said_of_lens} if said_of_lens else {}))
    if args.json:
        print(json.dumps(plain(summary)))
    else:
        print(f"flat port written to {args.output} ({absorbed.model} equivalent at {args.absorbed_distance:g} m: "
              f"largest misfit {residual:.2f} px)")
    return 0


def format_calibration(result: CalibrationResult, output: Path) -> str:
    """The fit's quality indicators and parameters with their three uncertainties, as a table."""
    cam, std = result.camera, result.std
    lines = [f"calibration written to {output}",
             f"views used {result.views_used}, repeats counted once "
             f"{len(result.rejected_views) - len(result.rejected)}, rejected {len(result.rejected)}; "
             f"RMS {result.rms_px:.4f} px, mean {result.mean_px:.4f} px, max {result.max_residual_px:.4f} px",
             f"model {cam.model}" + (f": {result.model_choice['reason']}" if result.model_choice else ""),
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
