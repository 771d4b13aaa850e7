"""What a C decoder prints while it decodes: libjpeg's warnings are the only sign of a corrupt scan (OpenCV
decodes it without an error), and it prints them to the process's stderr. The capture swaps file descriptor 2
for the call; one call at a time in the process (two threads swapping at once left stderr pointing at a closed
file, and each could read the other's warning), and lines that are not the decoder's (another thread's
output that landed there) are written on to stderr, not taken for a warning. A program that reads frames in
one thread while another prints (`veg-area measure` on a video) has its Python-level stderr wait for the
capture (`hold_stderr_during_captures`), so its lines never pass through it and keep their order.

No ROS here.
"""

from __future__ import annotations

import fcntl
import os
import re
import sys
import tempfile
import threading
from collections.abc import Callable
from typing import TextIO, TypeVar

Result = TypeVar("Result")

# every warning libjpeg(-turbo) emits (jerror.h's JWRN_ messages); no other text counts as the decoder's
LIBJPEG_WARNING = re.compile(r"(Corrupt JPEG data\b|Premature end of JPEG file|Invalid SOS parameters for sequential"
                             r"|Inconsistent progression sequence|Warning: unknown JFIF revision"
                             r"|Unknown Adobe color transform|Application transferred too many scanlines)")
# FFmpeg's log lines name the component that writes them: "[h264 @ 0x55d0c8a1b2c0] error while decoding MB 3 7"
FFMPEG_MESSAGE = re.compile(r"\[[\w:.-]+ @ 0x[0-9a-f]+\] ")


class _Capture:
    """One append-only file per process that stderr points at during a call. Another thread's write can still
    be on its way when stderr is put back; it lands at the file's end whole (O_APPEND) and is read and passed
    on at the next call instead of being lost with a file closed under it."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.fd: int | None = None
        self.read_upto = 0

    def opened(self) -> int:
        if self.fd is None:
            fd, path = tempfile.mkstemp(prefix="veg_area_stderr_")
            os.unlink(path)
            fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) | os.O_APPEND)
            self.fd = fd
        return self.fd

    def new_lines(self) -> list[str]:
        """The whole lines written since the last read (a line still being written waits for the next)."""
        end = os.fstat(self.fd).st_size
        data = os.pread(self.fd, end - self.read_upto, self.read_upto)
        whole = data.rfind(b"\n") + 1
        self.read_upto += whole
        return data[:whole].decode("utf-8", "replace").splitlines(keepends=True)


_CAPTURE = _Capture()


def with_decoder_messages(call: Callable[[], Result], is_decoders: Callable[[str], object] = LIBJPEG_WARNING.match
                          ) -> tuple[Result, str]:
    """`call()`'s result and the lines it printed to stderr that `is_decoders` recognises, joined by spaces;
    every other line printed meanwhile goes on to stderr."""
    sys.stderr.flush()
    with _CAPTURE.lock:
        capture = _CAPTURE.opened()
        earlier = _CAPTURE.new_lines()  # another thread's, late after the previous call
        saved = os.dup(2)
        try:
            os.dup2(capture, 2)
            try:
                result = call()
            finally:
                os.dup2(saved, 2)
            ours, others = [], []
            for line in _CAPTURE.new_lines():
                (ours if is_decoders(line.strip()) else others).append(line)
            if earlier or others:
                os.write(saved, "".join(earlier + others).encode())
        finally:
            os.close(saved)
    return result, " ".join(" ".join(ours).split())


class _HeldStream:
    """A text stream whose writes wait while a capture has stderr (attributes as the wrapped stream's)."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        with _CAPTURE.lock:
            return self._stream.write(text)

    def flush(self) -> None:
        with _CAPTURE.lock:
            self._stream.flush()

    def __getattr__(self, name: str) -> object:
        return getattr(self._stream, name)


def hold_stderr_during_captures() -> None:
    """Make `sys.stderr`'s writes wait while a capture has file descriptor 2 (once per process)."""
    if not isinstance(sys.stderr, _HeldStream) and sys.stderr is not None:
        sys.stderr = _HeldStream(sys.stderr)
