"""`veg-area demo` (the main job: the ROS 2 graph on the built-in synthetic endoscope) and
`veg-area calibration-demo` (the synthetic endoscope calibrated in air and water, no ROS)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .common import EXIT_FAILED, CliError, check_writable, positive_float, positive_int


def _check_output(folder: str) -> Path:
    check_writable([("--output", folder, True)], "run")
    return Path(folder)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    demo = sub.add_parser("demo", help="the main job on the built-in default: synthetic underwater camera -> "
                          "calibration node -> area node, Af against the true area")
    demo.add_argument("--output", default="veg_area_demo", help="folder for the served calibration")
    demo.add_argument("--measurements", type=positive_int, default=10,
                      help="calibrated frames to average (default %(default)s)")
    demo.add_argument("--timeout", type=positive_float, default=300.0, help="seconds before giving up")
    demo.set_defaults(func=cmd_demo)

    cdemo = sub.add_parser("calibration-demo", help="calibrate a synthetic endoscope in air and water, "
                           "compare with the true camera (no ROS)")
    cdemo.add_argument("--output", default="veg_area_demo", help="folder for the calibration and report")
    cdemo.add_argument("-q", "--quiet", action="store_true")
    cdemo.set_defaults(func=cmd_calibration_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job: the ROS 2 graph (composed in this process) on the built-in synthetic endoscope."""
    from ..ros.graph import run_graph

    code = run_graph(_check_output(args.output), measurements=args.measurements, timeout_s=args.timeout)
    if code == EXIT_FAILED:
        raise CliError("the graph did not deliver calibrated measurements in time")
    return code


def cmd_calibration_demo(args: argparse.Namespace) -> int:
    from ..sim.calibration_demo import run_demo

    return run_demo(_check_output(args.output), quiet=args.quiet)
