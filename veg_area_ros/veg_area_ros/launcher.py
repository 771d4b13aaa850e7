"""The `veg-area` command's entry point: the command line's imports (OpenCV, numpy, scipy: half a second)
happen inside it, so a Ctrl-C that comes while they load ends the command as any Ctrl-C does, with one line
and exit 130, not a traceback."""

from __future__ import annotations

import sys

EXIT_INTERRUPTED = 130


def main() -> int:
    try:
        from .cli import main as run

        return run()
    except KeyboardInterrupt:
        print("veg-area: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
