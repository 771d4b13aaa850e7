"""The ground floor every reader and writer shares: atomic writes, the size limits inputs are held to, the
order files are taken in.
Imports nothing of the package, so any module may import it."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import glob
import io
import os
import re
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# the largest sensors sold (200 MP phones, 150 MP medium format); measuring costs about 150 MB + 21 bytes a pixel
# (10 MP 0.37 GB, 40 MP 1.0 GB), and a 20000x20000 PNG (400 MP) took 9 GB and minutes to decode before refusing
MAX_IMAGE_PIXELS = 210_000_000


def too_many_pixels(width: int, height: int) -> str | None:
    """Why an image of this size is not measured (more pixels than any camera's), or None."""
    if width * height <= MAX_IMAGE_PIXELS:
        return None
    return (f"{width}x{height} pixels ({width * height / 1e6:.0f} MP) is more than any camera's sensor "
            f"({MAX_IMAGE_PIXELS / 1e6:.0f} MP at most here)")


MAX_IMAGE_SIDE = 32768  # pixels: twice the widest sensors made; larger sizes in a camera_info are corrupt



PathType = TypeVar("PathType", bound=PurePath)


def in_name_order(paths: Iterable[PathType]) -> list[PathType]:
    """Files in the order a file browser shows them: numbers in names compared as numbers (frame_2 before
    frame_10, which plain text order put after frame_1), then the names as text."""
    def key(path: PurePath) -> tuple:
        parts = re.split(r"(\d+)", path.name)
        return [int(part) if k % 2 else part.lower() for k, part in enumerate(parts)], path.name

    return sorted(paths, key=key)


def glob_matches(pattern: str) -> list[Path] | None:
    """The files a glob pattern the shell left alone (quoted, or too many for one command line) matches, as the
    shell would match them (hidden files left out), in a file browser's order; None where `pattern` is no glob
    or names a file of its own."""
    if not glob.has_magic(pattern) or os.path.lexists(pattern):
        return None
    return in_name_order(p for p in map(Path, glob.glob(pattern)) if p.is_file())


def special_file(path: str | os.PathLike, writing: bool = False) -> str | None:
    """Why `path` cannot be read (or, `writing`, written) as a file, or None: a device (/dev/zero never ends: 3 GB
    read before a MemoryError; an atomic write would replace /dev/null itself), a pipe (the read waits for a
    writer, the write for a reader, Ctrl-C too) or a socket. A missing file or a folder is left to the reader's
    own error."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    kind = ("a pipe (FIFO)" if stat.S_ISFIFO(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a socket" if stat.S_ISSOCK(mode) else "no regular file")
    if writing:
        why = ("writing would wait for a reader" if stat.S_ISFIFO(mode) else "a file written there would replace "
               "the device itself" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "no file can be written there")
        return f"is {kind}, not a file ({why})"
    return f"is {kind}, not a file (reading it would never end or would wait for a writer)"


def being_written(path: str | os.PathLike) -> bool:
    """Whether another process is writing `path` as a table row by row now (`open_rows` holds its lock)."""
    try:
        handle = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(handle)  # and with it the shared lock taken to look
    return False


def open_rows(path: str | os.PathLike) -> io.TextIOWrapper:
    """`path` emptied and opened to write a table into row by row, locked against a second writer for as long as
    it is open: two runs given one CSV each truncated it and wrote over the other's rows (both exit 0, the
    longer run's rows lost). FileWriteError where another process holds it."""
    handle = os.open(path, os.O_WRONLY | os.O_CREAT, 0o666)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(handle)
        raise FileWriteError(errno.EAGAIN, f"{path} could not be written (another run is writing it now)",
                             str(path)) from None
    except OSError:  # a file system without locks (some network shares): written unlocked, as before
        pass
    try:
        os.ftruncate(handle, 0)
        return open(handle, "w", newline="", encoding="utf-8")
    except OSError:
        os.close(handle)
        raise


def _umask() -> int:
    """The process's umask, read without changing it where the kernel says (Linux), else by setting it back."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _writer_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_orphans(path: Path) -> None:
    """Temp files of `path` left by a writer that was killed (SIGKILL runs no clean-up): their name holds the
    writer's pid, and a pid that no longer runs cannot finish them."""
    for orphan in path.parent.glob(f".{glob.escape(path.name)}.*.tmp"):
        pid = orphan.name[len(path.name) + 2:].split(".", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not _writer_alive(int(pid)):
            orphan.unlink(missing_ok=True)


class FileWriteError(OSError):
    """A file that could not be written (a full disk, a read-only or vanished folder); the message names it and
    why. What was written before it stays; the file itself is left as it was (writes are atomic). Made by `of`;
    its arguments are OSError's own (errno, message, path), so it crosses a process pool as it is."""

    @classmethod
    def of(cls, path: str | os.PathLike, cause: OSError) -> FileWriteError:
        full = cause.errno in (errno.ENOSPC, errno.EDQUOT)
        return cls(cause.errno, f"{path} could not be written ({os_reason(cause)}{', a full disk?' if full else ''})",
                   str(path))

    def __str__(self) -> str:
        return self.strerror


def os_reason(exc: BaseException) -> str:
    """An OS error's reason as the system words it (No space left on device), else its text or its kind."""
    return getattr(exc, "strerror", None) or str(exc) or type(exc).__name__


def _temporary_beside(path: Path, make_folder: bool = False) -> tuple[int, str]:
    """A temporary file in `path`'s folder (made first, and a killed writer's leftovers of `path` removed, where
    `make_folder`), to be renamed over it (`_replacing`); FileWriteError where `path` is no file to replace (as
    root, the rename would put a regular file where /dev/null was) or the folder takes no file."""
    special = special_file(path, writing=True)
    if special:
        raise FileWriteError(errno.EINVAL, f"{path} {special}", str(path))
    try:
        if make_folder:
            path.parent.mkdir(parents=True, exist_ok=True)
            _remove_orphans(path)
        return tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise FileWriteError.of(path, exc) from exc


@contextlib.contextmanager
def _replacing(path: Path, tmp: str) -> Iterator[None]:
    """The temporary file renamed over `path` once the block wrote it; removed if anything went wrong, an OS
    error (a full disk) raised as FileWriteError."""
    try:
        yield
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError) and not isinstance(exc, FileWriteError):
            raise FileWriteError.of(path, exc) from exc
        raise


def utf8(text: str) -> bytes:
    """Text as UTF-8, where a file name's bytes that are no UTF-8 (kept by Python as surrogates) become U+FFFD,
    as the CSV rows show them: a summary naming such an input failed with a traceback after the work."""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "replace").encode("utf-8")


def write_atomic(path: str | os.PathLike, content: str | bytes) -> None:
    """Write `content` (text as UTF-8, or bytes) via a temporary file in the same folder and rename, so readers
    never see half a file; the file gets the mode the umask gives any new file (mkstemp's own is 0600), and a
    killed writer's leftovers of the same file are removed."""
    path = Path(path)
    fd, tmp = _temporary_beside(path, make_folder=True)
    with _replacing(path, tmp), os.fdopen(fd, "wb") as handle:
        handle.write(utf8(content) if isinstance(content, str) else content)
        handle.flush()
        os.fchmod(handle.fileno(), 0o666 & ~_umask())
        os.fsync(handle.fileno())


def save_figure(figure: Figure, path: str | os.PathLike, **options: object) -> None:
    """A matplotlib figure saved as PNG atomically (a temporary file in the same folder, then renamed): a run
    stopped while it is drawn leaves the last whole plot or none, never a truncated file."""
    path = Path(path)
    fd, tmp = _temporary_beside(path)
    os.close(fd)
    with _replacing(path, tmp):
        figure.savefig(tmp, format="png", **options)
        os.chmod(tmp, 0o666 & ~_umask())
