"""`veg-area`: the command line for researchers without ROS, on the same core as the nodes.

    veg-area calibrate IMAGES_OR_DIR_OR_VIDEO... --board SPEC -o calib.yaml [--json] [--report DIR]
    veg-area calibrate [UNDERWATER_VIEWS...] --port flat:D:T:N --lens air.yaml -o water.yaml
    veg-area measure IMAGE_OR_DIR_OR_VIDEO_OR_BAG... --calibration calib.yaml|none|bag --targets targets.yaml
    veg-area record [TOPICS...] | play BAG | bag-recover BAG NEW_BAG
    veg-area vogel TABLE.csv | BAGS...
    veg-area demo | calibration-demo
    veg-area doctor

Exit codes (cli.common): 0 success, 1 failed (with a one-line reason on stderr), 2 usage error, 3 refused to
replace a better calibration, 130 interrupted (what was done so far is kept).
"""

from __future__ import annotations

import argparse
import codecs
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING

from .. import __version__
from ..decoder_messages import hold_stderr_during_captures
from ..files import FileWriteError
from . import bags, calibrate, demos, doctor, flume, measure
from .common import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, CliError

if TYPE_CHECKING:
    from types import FrameType
    from typing import NoReturn


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="veg-area", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"veg_area_ros {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    calibrate.add_parser(sub)
    measure.add_parser(sub)
    bags.add_parsers(sub)
    flume.add_parser(sub)
    demos.add_parsers(sub)
    doctor.add_parser(sub)
    return parser


def _terminate_as_interrupt(number: int, frame: FrameType | None) -> NoReturn:
    """SIGTERM (timeout, Slurm, docker stop) ends a run as Ctrl-C does: what was measured is kept."""
    raise KeyboardInterrupt


# options whose value may start with a minus (an ROI corner left of or above the image): argparse would read
# `--roi -100,0,...` as two options
NEGATIVE_VALUE_OPTIONS = ("--roi",)


def joined_negative_values(argv: Sequence[str]) -> list[str]:
    """`--roi -100,0,...` as `--roi=-100,0,...`, what argparse understands; anything after `--` untouched."""
    joined: list[str] = []
    tokens = iter(argv)
    for token in tokens:
        if token == "--":
            joined += [token, *tokens]
            break
        if token in NEGATIVE_VALUE_OPTIONS:
            value = next(tokens, None)
            if value is not None and value[:1] == "-" and value[1:2].isdigit():
                joined.append(f"{token}={value}")
                continue
            joined += [token] if value is None else [token, value]
            continue
        joined.append(token)
    return joined


def _shown_anyway(error: UnicodeError) -> tuple[str | bytes, int]:
    """A file name that is no UTF-8 is shown with its own bytes, as ls does; a character the terminal's
    encoding lacks (± or m² on an ASCII locale) as its escape, never a traceback after the work."""
    try:
        return codecs.lookup_error("surrogateescape")(error)
    except UnicodeError:
        return codecs.lookup_error("backslashreplace")(error)


codecs.register_error("veg_area_shown", _shown_anyway)


def main(argv: Sequence[str] | None = None) -> int:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(AttributeError, ValueError):
            stream.reconfigure(errors="veg_area_shown")
    hold_stderr_during_captures()  # a frame read in another thread may have stderr for its decoder's words
    args = build_parser().parse_args(joined_negative_values(sys.argv[1:] if argv is None else argv))
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate_as_interrupt)
    try:
        code = args.func(args)
        sys.stdout.flush()  # here, not at exit: a reader gone by then (`| head`) is handled below
        return code
    except CliError as exc:
        print(f"veg-area {args.command}: {exc}", file=sys.stderr)
        return exc.code
    except FileWriteError as exc:  # a full disk mid-run: said, what was written before stays
        print(f"veg-area {args.command}: {exc}; what was written before it stays", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print(f"veg-area {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # stdout closed early (`... --json | head -c 10`): what was written stays written
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return EXIT_OK
