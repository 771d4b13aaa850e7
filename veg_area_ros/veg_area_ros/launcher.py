"""The `veg-area` command's entry point: the command line's imports (OpenCV, numpy, scipy: half a second)
happen inside it, so a Ctrl-C that comes while they load ends the command as any Ctrl-C does, with one line
and exit 130, not a traceback."""

from __future__ import annotations

import signal
import sys

EXIT_INTERRUPTED = 130


def main() -> int:
    interrupted = []

    # remembered: inside numpy's C start-up it surfaces as an ImportError
    def on_interrupt(signum: int, frame: object) -> None:  # frame: a FrameType, left unimported to start fast
        interrupted.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_interrupt)
    try:
        from .cli import main as run

        signal.signal(signal.SIGINT, signal.default_int_handler)
        return run()
    except KeyboardInterrupt:
        print("veg-area: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except ImportError:
        if not interrupted:
            raise
        print("veg-area: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
