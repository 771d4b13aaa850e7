"""`veg-area measure`: its options and its dispatch. One input (or `--jobs 1`) is measured here by
`cli.measure_job`; several inputs with `--jobs N` go to worker processes (`cli.batch`)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..settings import AREA_MODE_CHOICES, TONE_CURVE_CHOICES, MeasurementSettings
from .batch import measure_batch
from .common import EXIT_USAGE, CliError, positive_float
from .measure_job import SEGMENT_FRAMES, MeasureJob, TimeBound, measure, time_bound

DEFAULTS = MeasurementSettings()


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
    from ..classify import ClassifyError
    from ..settings import given_levels

    try:
        return given_levels(text.split(","))
    except (ClassifyError, ValueError) as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def _roi(text: str) -> tuple[float, ...]:
    from ..classify import ClassifyError
    from ..settings import roi_polygon

    try:
        values = [float(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected x1,y1,x2,y2,x3,y3,... in pixels, got {text!r}") from exc
    try:
        return tuple(roi_polygon(values) or ())
    except ClassifyError as exc:
        raise argparse.ArgumentTypeError(f"{exc}, got {text!r}") from exc


def add_parser(sub: argparse._SubParsersAction) -> None:
    mea = sub.add_parser("measure", help="projected area Af of an object in images, folders or videos")
    mea.add_argument("inputs", nargs="+",
                     help="images, folders of images, TIFF stacks, videos, rosbag2 bags (folders), ROS 1 .bag "
                          "files; a quoted glob ('frames/*.png') is expanded as the shell would")
    mea.add_argument("--calibration", required=True,
                     help="camera_info YAML from 'veg-area calibrate', 'none' to measure the raw image, or 'bag' "
                          "for the camera_info recorded in the bag (as the live area node used it)")
    mea.add_argument("--image-topic", default=None,
                     help="image topic of a bag, sensor_msgs/Image or CompressedImage (default: its only image "
                          "topic); its camera_info is the sibling in its namespace, as image_transport pairs them")
    mea.add_argument("--start-time", type=time_bound, default=TimeBound(-math.inf), metavar="S",
                     help="bag frames from this many seconds after the bag's first image on (its header stamp); "
                          "an absolute time as unix:SECONDS or an ISO time (2026-06-01T10:31:05Z)")
    mea.add_argument("--end-time", type=time_bound, default=TimeBound(math.inf), metavar="S",
                     help="bag frames up to this many seconds after the first image (or unix:/ISO, as above)")
    mea.add_argument("--targets", required=True, help="targets YAML: ArUco marker ids or hand-picked points")
    mea.add_argument("--threshold", type=_threshold, default=DEFAULTS.threshold,
                     help=f"0..255 or 'otsu' (default {DEFAULTS.threshold})")
    mea.add_argument("--object", default=DEFAULTS.object, choices=["dark", "bright", "green"],
                     help="object darker/brighter than the background, or greener (excess-green index)")
    mea.add_argument("--channel", default=DEFAULTS.channel, choices=["grey", "blue", "green", "red"],
                     help="band the threshold acts on (dark/bright)")
    mea.add_argument("--roi", type=_roi, default=None, metavar="x1,y1,x2,y2,...",
                     help="region of interest, polygon in idealized-image pixels (default: inside the targets)")
    mea.add_argument("--area-mode", default=DEFAULTS.area_mode, choices=list(AREA_MODE_CHOICES),
                     help="subpixel: each edge pixel counts its object share from its grey level between the "
                          "object's and the background's; count: whole pixels, as in the paper; auto (default): "
                          "the one the calibration file records, judged by `calibrate` on its own board views "
                          "(the count where the shares do not read them better), else subpixel")
    mea.add_argument("--levels", type=_levels, default=None, metavar="OBJECT,BACKGROUND",
                     help="sub-pixel mode: the object's and background's grey levels (default: from each frame)")
    mea.add_argument("--tone-curve", default=DEFAULTS.tone_curve, choices=list(TONE_CURVE_CHOICES),
                     help="how the camera encodes light in its grey levels: auto (default) takes the curve the "
                          "calibration file records, judged by `calibrate` on its own board views near and far, "
                          "else linear; linear (raw and machine-vision cameras, our renders) or srgb (most JPEG "
                          "photos and video, action cameras): Otsu's threshold and the sub-pixel shares are then "
                          "read in light (docs/measuring.md)")
    mea.add_argument("--open", type=int, default=DEFAULTS.open_px, metavar="PX", help="morphological opening radius")
    mea.add_argument("--close", type=int, default=DEFAULTS.close_px, metavar="PX", help="morphological closing radius")
    mea.add_argument("--background", metavar="IMAGE",
                     help="sub-pixel mode: a frame of the empty scene (the flume before the plant goes in), same "
                          "camera and settings, to even the light with (default: the light is fitted per frame)")
    mea.add_argument("--sweep-step", type=positive_float, default=DEFAULTS.sweep_step,
                     help="threshold step of the sweep and of the threshold uncertainty (grey levels, at most 127)")
    mea.add_argument("--json", action="store_true", help="one JSON object per frame on stdout (a batch: per input)")
    mea.add_argument("--overlay", metavar="PNG_OR_DIR", help="draw mask, ROI and targets (a file, or a folder)")
    mea.add_argument("--csv", metavar="FILE", help="time series CSV (+ PNG plot beside it); "
                     "default for a video: VIDEO_area.csv here")
    mea.add_argument("--idealized", metavar="DIR", help="write the idealized frames and their camera here")
    mea.add_argument("--video-step", type=int, default=1, help="measure every Nth video frame")
    mea.add_argument("--jobs", type=int, default=None, metavar="N",
                     help="several inputs: measure them N at a time in worker processes on this machine, 0 = every "
                          "core (default 1); a CSV and plot per input and batch_summary.csv go to --output-dir")
    mea.add_argument("--scheduler", metavar="ADDRESS",
                     help="measure on a Dask cluster: the address of its scheduler (tcp://head:8786); the inputs "
                          "must be readable by the workers at the same paths (a shared filesystem); long videos "
                          "and bags are split into segments over the workers")
    mea.add_argument("--segment-frames", type=int, default=None, metavar="N",
                     help=f"a video or bag is measured in segments of N frames, each begun afresh (markers found "
                          f"anew, weights and light rebuilt), whoever measures it (default {SEGMENT_FRAMES})")
    mea.add_argument("--output-dir", default=None, metavar="DIR",
                     help="where several inputs or a --scheduler run write (default: here)")
    mea.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    mea.set_defaults(func=cmd_measure)


def _refuse_options_the_inputs_ignore(args: argparse.Namespace) -> None:
    """--video-step where no input can be a video (bags included), --segment-frames where none is a video or bag
    and --image-topic where none is a bag were ignored in silence.
    Photos a folder holds that OpenCV does not read are said here, once, whoever measures (a batch's processes, a
    cluster's workers)."""
    from ..frames import IMAGE_SUFFIXES, InputError, expand_inputs, is_bag

    segments_given = args.segment_frames is not None
    if not segments_given:
        args.segment_frames = SEGMENT_FRAMES
    unread: list[str] = []
    try:
        files = expand_inputs(args.inputs, unread)
    except InputError:
        return  # said with its reason where the inputs are read
    if segments_given and files and all(f.suffix.lower() in IMAGE_SUFFIXES for f in files):
        raise CliError(f"--segment-frames {args.segment_frames} splits a video or bag into segments; the inputs are "
                       "images", EXIT_USAGE)
    for note in unread:
        print(f"warning: {note}", file=sys.stderr, flush=True)
    if args.video_step > 1 and files and all(f.suffix.lower() in IMAGE_SUFFIXES or is_bag(f) for f in files):
        bags = sum(is_bag(f) for f in files)
        kinds = ("images" if not bags else "images and bags" if bags < len(files) else
                 "bags (every frame of a bag is measured; --start-time and --end-time trim it)")
        raise CliError(f"--video-step {args.video_step} takes every Nth frame of a video; the inputs are {kinds}",
                       EXIT_USAGE)
    if args.image_topic and not any(is_bag(f) for f in files):
        raise CliError(f"--image-topic {args.image_topic} picks a bag's image topic; the inputs hold no bag",
                       EXIT_USAGE)


def cmd_measure(args: argparse.Namespace) -> int:
    if args.jobs is not None and args.jobs < 0:
        raise CliError("--jobs must be 0 (every core) or more", EXIT_USAGE)
    if args.scheduler and args.overlay:
        raise CliError("--overlay is not written by a --scheduler run (the frames are measured on the cluster's "
                       "workers); measure the inputs whose overlays you want on this machine", EXIT_USAGE)
    if args.scheduler and args.jobs is not None:
        raise CliError("--jobs counts this machine's processes; with --scheduler the cluster's workers measure",
                       EXIT_USAGE)
    _refuse_options_the_inputs_ignore(args)
    job = MeasureJob.from_args(args)
    folder = Path(args.output_dir or ".")
    if args.scheduler:
        from .cluster import measure_on_cluster

        return measure_on_cluster(job, args.scheduler, folder)
    if len(args.inputs) > 1:  # one behaviour whatever runs it: a CSV per input and the summary
        return measure_batch(job, 1 if args.jobs is None else args.jobs, folder)
    if args.output_dir is not None:
        raise CliError("--output-dir is where several inputs (or a --scheduler run) are written; for one input "
                       "give --csv", EXIT_USAGE)
    if args.jobs not in (None, 1):
        raise CliError("--jobs spreads several inputs over processes; one input is measured in one "
                       "(--scheduler splits a long one)", EXIT_USAGE)
    return measure(job)[0]
