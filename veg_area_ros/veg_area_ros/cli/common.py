"""What every command shares: exit codes, the one-line error, progress on stderr, argument types, the
check that an output can be written before any work, and CSV tables written atomically."""

from __future__ import annotations

import argparse
import contextlib
import csv
import errno
import glob
import io
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from ..files import FileWriteError, being_written, glob_matches, open_rows, special_file, write_atomic

EXIT_OK = 0
EXIT_FAILED = 1  # with a one-line reason on stderr
EXIT_USAGE = 2  # as argparse exits on a usage error
EXIT_REFUSED = 3  # refused to replace a better calibration
EXIT_INTERRUPTED = 130  # Ctrl-C, what was done so far kept (128 + SIGINT, as a shell reports it)


class CliError(Exception):
    """A failure reported as one line, without a traceback."""

    def __init__(self, message: str, code: int = EXIT_FAILED):
        super().__init__(message)
        self.code = code


def progress(quiet: bool) -> Callable[[str], None]:
    """A function printing progress lines on stderr, or nothing when quiet."""
    def say(message: str) -> None:
        if not quiet:
            print(message, file=sys.stderr, flush=True)
    return say


def _number(text: str, convert: Callable[[str], float], valid: Callable[[float], bool], wanted: str) -> float:
    """`text` converted and checked, or argparse's error 'must be WANTED, got TEXT'."""
    try:
        value = convert(text)
    except ValueError:
        value = None
    if value is None or not valid(value):
        raise argparse.ArgumentTypeError(f"must be {wanted}, got {text}")
    return value


def positive_float(text: str) -> float:
    return _number(text, float, lambda v: math.isfinite(v) and v > 0, "a positive number")


MAX_DISTANCE_M = 100.0  # as the calibration node's calibration_distance_m


def distance_m(text: str) -> float:
    """A camera-to-board distance in metres (a value in millimetres is refused, not recorded as 700 m)."""
    return _number(text, float, lambda v: math.isfinite(v) and 0 < v <= MAX_DISTANCE_M,
                   f"a distance in metres, over 0 and at most {MAX_DISTANCE_M:g} (millimetres given as metres?)")


def liquid_index(text: str) -> float:
    """A liquid's refractive index: water 1.333, sea water 1.34, what a flume may hold up to 1.6; 1 is air's."""
    return _number(text, float, lambda v: 1.2 <= v <= 1.6,
                   "a liquid's refractive index from 1.2 to 1.6 (water 1.333; 1 is air's)")


def positive_int(text: str) -> int:
    return _number(text, int, lambda v: v >= 1, "a whole number of 1 or more")


def probability(text: str) -> float:
    """A confidence level: strictly between 0 and 1."""
    return _number(text, float, lambda v: 0 < v < 1, "between 0 and 1 (0.95 for 95 %)")


NAME_MAX, PATH_MAX = 255, 4096  # bytes: Linux's limits on a name and a whole path


def unwritable(path: Path, folder: bool) -> str | None:
    """Why `path` (a file, or a folder to write into) cannot be written here, or None: checked before any work
    by creating (and removing) a temporary file where it would go (permissions alone miss /proc as root); a name
    or path longer than the file system allows is said as such."""
    longest = max((len(os.fsencode(part)) for part in path.parts), default=0)
    if longest > NAME_MAX:
        return f"has a name of {longest} bytes, more than a file system allows ({NAME_MAX})"
    if len(os.fsencode(str(path.absolute()))) >= PATH_MAX:
        return f"is a path of more than {PATH_MAX} bytes, longer than the system allows"
    if path.is_symlink():
        try:
            os.stat(path)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                return "is a symlink loop (it leads back to itself)"
    if path.exists() and folder and not path.is_dir():
        return "exists and is not a folder"
    if path.exists() and not folder and path.is_dir():
        return "is a folder, not a file"
    special = None if folder else special_file(path, writing=True)
    if special:
        return special
    if not folder and being_written(path):
        return "is being written by another run now (both would write over each other's rows)"
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


def check_writable(outputs: Sequence[tuple[str, str | Path | None, bool]], what: str) -> None:
    """Refuse (exit 2, before any work, nothing written) an output (option, path, is a folder) that cannot be
    written where it would go (`unwritable`)."""
    for option, value, folder in outputs:
        problem = unwritable(Path(value), folder) if value else None
        if problem:
            raise CliError(f"{option} {value}: {problem}; nothing was {what}", EXIT_USAGE)


def overwrites_input(output: Path, inputs: Sequence[str | Path], writes_images: bool = False) -> str | None:
    """Why writing `output` would destroy or pollute an input of the same command, or None: it is that file
    (the same inode, whatever the name or symlink says), or it puts images or videos (an image file, a CSV with
    its plot beside it, a folder of overlays, plots or idealized frames: `writes_images`) inside an input
    folder, whose next reading would take them as frames. A calibration YAML beside its photos is fine."""
    from ..frames import IMAGE_SUFFIXES, VIDEO_SUFFIXES

    try:
        target = output.resolve()
    except (OSError, RuntimeError):  # a symlink loop (RuntimeError in Python 3.11): written over as a link
        return None
    media = writes_images or output.suffix.lower() in IMAGE_SUFFIXES | VIDEO_SUFFIXES
    for given in _with_glob_matches(inputs):
        source = Path(given)
        try:
            if output.exists() and source.exists() and output.samefile(source):
                return f"is the input {given}" + (f" (through {output} -> {target})" if output.is_symlink() else "")
            if media and source.is_dir() and target.is_relative_to(source.resolve()):
                return f"lies inside the input folder {given}"
        except OSError:
            continue
    return None


def _with_glob_matches(inputs: Sequence[str | Path]) -> list[str | Path]:
    """The inputs, and for a quoted glob (`frames/*.png`, which the command expands as the shell would) the
    files it matches and the folders it reads from: an image written there would be read by the next run."""
    found: list[str | Path] = []
    for given in inputs:
        found.append(given)
        matches = glob_matches(str(given))
        if matches is not None:
            parent = Path(given).parent
            folders = {p.parent for p in matches} | (set() if glob.has_magic(str(parent)) else {parent})
            found += [*matches, *(str(folder) for folder in sorted(folders))]
    return found


def check_outputs(outputs: Sequence[tuple[str, str | None, bool]], inputs: Sequence[str | Path], what: str,
                  written: str = "") -> None:
    """Refuse (exit 2, before any work, nothing written) an output (option, path, writes images) that is an
    input or would put images inside an input folder (`overwrites_input`). `written`: what of the option's the
    path is ('its plot ', 'its image '), when it is not the option's own value."""
    for option, value, writes_images in outputs:
        if value:
            problem = overwrites_input(Path(value), [i for i in inputs if i], writes_images)
            if problem:
                named = f"{option}: {written}{value}" if written else f"{option} {value}"
                raise CliError(f"{named} {problem}: it would be written over; nothing was {what}", EXIT_USAGE)


def write_csv(path: Path, columns: Sequence[str], rows: list[dict]) -> None:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, columns, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(path, buffer.getvalue())


class RowLog:
    """A CSV table written as its rows come: each row reaches the file (flushed to the kernel, synced to disk
    at most once a second) before the next frame is measured, so the table is valid after every row and a
    run killed by any signal (SIGKILL included) keeps every row measured. The file is begun only at the
    first row that `worth_keeping` accepts (a measured frame), the rows before it held back: a run that
    measures nothing never replaces an earlier table."""

    def __init__(self, path: Path, columns: Sequence[str], worth_keeping: Callable[[dict], bool]):
        self.path, self.columns, self.worth_keeping = path, columns, worth_keeping
        self.held: list[dict] = []
        self._handle = None
        self._writer: csv.DictWriter | None = None
        self._synced = 0.0
        self._whole_bytes = 0  # the file's size after its last whole row

    @property
    def begun(self) -> bool:
        return self._handle is not None

    def add(self, row: dict) -> None:
        try:
            self._add(row)
        except OSError as exc:  # a full disk: the rows before stay in the file, no later one can follow
            self._abandon()
            raise FileWriteError.of(self.path, exc) from exc

    def _abandon(self) -> None:
        """Close the table at its last whole row: a disk that filled mid-row took part of it (cutting a file
        short needs no space)."""
        if self._handle is not None:
            with contextlib.suppress(OSError):
                self._handle.close()
            self._handle = None
            with contextlib.suppress(OSError):
                if self._whole_bytes:
                    os.truncate(self.path, self._whole_bytes)
                else:  # not even the header: no table at all
                    self.path.unlink()

    def _add(self, row: dict) -> None:
        if self._handle is None:
            if not self.worth_keeping(row):
                self.held.append(row)
                return
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._handle = open_rows(self.path)  # locked: a second run given the same CSV is refused
            self._writer = csv.DictWriter(self._handle, self.columns, extrasaction="ignore")
            self._writer.writeheader()
            self._writer.writerows(self.held)
            self.held = []
        self._writer.writerow(row)
        self._handle.flush()
        self._whole_bytes = os.fstat(self._handle.fileno()).st_size
        if time.monotonic() - self._synced > 1.0:
            os.fsync(self._handle.fileno())
            self._synced = time.monotonic()

    def close(self, write_held: bool = False) -> None:
        """Finish the table; a table never begun is written with its held rows when `write_held`."""
        if self._handle is not None:
            try:
                self._handle.flush()
                os.fsync(self._handle.fileno())
                self._handle.close()
            except OSError as exc:
                self._abandon()
                raise FileWriteError.of(self.path, exc) from exc
            self._handle = None
        elif write_held and self.held:
            write_csv(self.path, self.columns, self.held)
