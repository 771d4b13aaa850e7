"""ROS camera_calibration's saved archive (`/tmp/calibrationdata.tar.gz`, written by its SAVE button): the board
views it kept (`left-NNNN.png`; a stereo pair's also `right-NNNN.png`) and its calibration (`ost.yaml`, and
`ost.txt` in ROS 1's INI form; a stereo pair's `left.yaml` and `right.yaml`). Read in place, one member at a time,
never unpacked to disk. No ROS here."""

from __future__ import annotations

import tarfile
import zlib
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path, PurePosixPath

from .files import in_name_order, special_file
from .strict_yaml import decode_text

ARCHIVE_SUFFIXES = (".tar.gz", ".tgz", ".tar", ".tar.bz2", ".tbz2", ".tar.xz", ".txz")
MAX_MEMBER_BYTES = 1 << 30  # a 100 MP PNG is about 300 MB; a larger member is no camera's view
MAX_CALIBRATION_BYTES = 1_000_000  # as any calibration file (strict_yaml.MAX_BYTES)
CALIBRATION_MEMBERS = ("ost.yaml", "ost.txt")  # a camera's calibration, in the order preferred
STEREO_CALIBRATION_MEMBERS = ("left.yaml", "right.yaml")


class ArchiveError(ValueError):
    """An archive that cannot be read, or holds nothing of one camera's; the message says why."""


def is_archive(path: Path) -> bool:
    """Whether a path names a tar archive (camera_calibration's `.tar.gz`, or another compression of one)."""
    return path.name.lower().endswith(ARCHIVE_SUFFIXES)


READ_ERRORS = (tarfile.TarError, EOFError, OSError, zlib.error)


def _by_name(archive: tarfile.TarFile) -> dict[str, tarfile.TarInfo]:
    """The archive's regular files by their base name (camera_calibration writes them at its top level); two
    files of one name in different folders (two sessions packed together) are refused, not one dropped."""
    found: dict[str, tarfile.TarInfo] = {}
    for member in archive.getmembers():
        if member.isfile():
            name = PurePosixPath(member.name).name
            if name in found:
                raise ArchiveError(f"holds {found[name].name} and {member.name}: two sessions in one archive; "
                                   "give each its own")
            found[name] = member
    return found


def _open(path: Path) -> tarfile.TarFile:
    problem = special_file(path)
    if problem:
        raise ArchiveError(problem)
    try:
        return tarfile.open(path, "r:*")
    except FileNotFoundError:
        raise
    except READ_ERRORS as exc:
        raise ArchiveError(f"not a readable tar archive ({exc})") from exc


@contextmanager
def _reading(path: Path) -> Iterator[tarfile.TarFile]:
    """The archive open, what breaks in reading it said as an ArchiveError (a missing file stays one)."""
    try:
        with _open(path) as archive:
            yield archive
    except FileNotFoundError:
        raise
    except READ_ERRORS as exc:
        raise ArchiveError(f"not a readable tar archive ({exc})") from exc


def _members(path: Path) -> dict[str, tarfile.TarInfo]:
    with _reading(path) as archive:
        return _by_name(archive)


def _views(members: dict[str, tarfile.TarInfo], suffixes: Iterable[str]) -> list[str]:
    wanted = set(suffixes)
    images = [name for name in members if PurePosixPath(name).suffix.lower() in wanted]
    if not images:
        raise ArchiveError("holds no image (camera_calibration saves its views as left-NNNN.png)")
    sides = {side for side in ("left", "right") if any(name.startswith(f"{side}-") for name in images)}
    if len(sides) == 2:
        raise ArchiveError("holds a stereo pair's views (left-NNNN.png and right-NNNN.png): calibrate one camera at "
                           "a time, e.g. tar xzf ARCHIVE --wildcards 'left-*' and calibrate on those images")
    return [path.name for path in in_name_order(PurePosixPath(name) for name in images)]


def view_names(path: Path, suffixes: Iterable[str]) -> list[str]:
    """The archive's images (members whose names end in one of `suffixes`), in name order. camera_calibration's
    stereo archive (left- and right- views, two cameras) is refused: one calibration needs one camera's."""
    return _views(_members(path), suffixes)


def read_views(path: Path, suffixes: Iterable[str]) -> Iterator[tuple[str, bytes | None, str]]:
    """Each of `view_names`' images: its name and bytes (or None and why), in name order, the archive opened
    once and one image in memory at a time."""
    try:
        with _open(path) as archive:
            members = _by_name(archive)
            for name in _views(members, suffixes):
                member = members[name]
                if member.size > MAX_MEMBER_BYTES:
                    yield name, None, f"is {member.size} bytes, more than any camera's image"
                    continue
                handle = archive.extractfile(member)
                yield name, (handle.read() if handle is not None else None), "" if handle else "cannot be read"
    except READ_ERRORS as exc:
        raise ArchiveError(f"not a readable tar archive ({exc})") from exc


def calibration_text(path: Path) -> tuple[str, str]:
    """(member name, text) of the archive's calibration: `ost.yaml` (ROS 2's camera_info YAML), else `ost.txt`
    (the INI ROS 1's `ost.ini` holds). A stereo pair's archive (left.yaml, right.yaml) is refused naming them."""
    with _reading(path) as archive:
        members = _by_name(archive)
        stereo = [name for name in STEREO_CALIBRATION_MEMBERS if name in members]
        if stereo:  # its ost.txt then holds both cameras
            raise ArchiveError(f"holds a stereo pair's calibrations ({' and '.join(stereo)}): extract the "
                               f"measured camera's (tar xzf ARCHIVE {stereo[0]}) and give that file")
        name = next((name for name in CALIBRATION_MEMBERS if name in members), None)
        if name is None:
            raise ArchiveError("holds no calibration (camera_calibration saves ost.yaml beside its views)")
        if members[name].size > MAX_CALIBRATION_BYTES:
            raise ArchiveError(f"its {name} is {members[name].size} bytes: larger than any calibration file")
        handle = archive.extractfile(members[name])
        if handle is None:
            raise ArchiveError(f"its {name} cannot be read")
        data = handle.read()
    try:
        return name, decode_text(data)
    except UnicodeDecodeError as exc:
        raise ArchiveError(f"its {name} is not text ({exc})") from exc
