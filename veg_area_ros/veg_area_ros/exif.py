"""The EXIF a photo carries (a JPEG's APP1 segment, a PNG's eXIf chunk, a WebP's EXIF chunk, a TIFF's own first
directory) and the two tags the package reads from it: the orientation (`orientation` applies it) and the time
the photo was taken (a timelapse's frames are a time series). No ROS here."""

from __future__ import annotations

import datetime as dt
import re
import struct

EXIF_PREFIX = b"Exif\x00\x00"
ORIENTATION_TAG = 0x0112
EXIF_DIRECTORY_TAG = 0x8769  # IFD0's pointer to the Exif directory
DATE_TIME_ORIGINAL_TAG = 0x9003  # "YYYY:MM:DD HH:MM:SS", the camera's clock when the shutter opened
OFFSET_TIME_ORIGINAL_TAG = 0x9011  # "+01:00": the clock's zone (EXIF 2.31)
SUBSEC_TIME_ORIGINAL_TAG = 0x9291  # "25": the fraction of the second, as digits
SHORT, LONG, ASCII = 3, 4, 2
MAX_ENTRIES = 1000  # a directory with more is corrupt
EXIF_TIME = re.compile(r"(\d{4}):(\d\d):(\d\d) (\d\d):(\d\d):(\d\d)")
EXIF_ZONE = re.compile(r"([+-])(\d\d):(\d\d)")


def is_tiff(data: bytes) -> bool:
    """Whether the bytes begin as a TIFF structure does (either byte order): a TIFF file, or an EXIF block."""
    return data[:4] in (b"II*\x00", b"MM\x00*")


def exif_tiff(data: bytes) -> bytes:
    """The TIFF structure of a JPEG's, PNG's, WebP's or TIFF's EXIF (from its byte-order mark), b"" if none."""
    if data[:2] == b"\xff\xd8":
        block = _jpeg_exif(data)
    elif data[:8] == b"\x89PNG\r\n\x1a\n":
        block = _chunk(data, 8, True, b"eXIf")
    elif data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        block = _chunk(data, 12, False, b"EXIF")
    else:
        block = data
    block = block.removeprefix(EXIF_PREFIX)
    return block if is_tiff(block) else b""


def _jpeg_exif(data: bytes) -> bytes:
    offset = 2
    while offset + 4 <= len(data) and data[offset] == 0xFF:
        marker = data[offset + 1]
        if marker == 0xDA:  # start of scan: the metadata segments are all before it
            break
        (length,) = struct.unpack_from(">H", data, offset + 2)
        if marker == 0xE1 and data[offset + 4:offset + 10] == EXIF_PREFIX:
            return data[offset + 4:offset + 2 + length]
        offset += 2 + length
    return b""


def _chunk(data: bytes, offset: int, big_endian: bool, wanted: bytes) -> bytes:
    """The payload of the first chunk named `wanted` in a PNG's chunks (length, then name, then a CRC after the
    payload) or a RIFF file's (name, then length; payloads padded to even), b"" where there is none."""
    while offset + 8 <= len(data):
        if big_endian:
            length, kind = struct.unpack_from(">I4s", data, offset)
        else:
            kind, length = struct.unpack_from("<4sI", data, offset)
        if kind == wanted:
            return data[offset + 8:offset + 8 + length]
        if kind == b"IEND":
            break
        offset += 8 + length + (4 if big_endian else length & 1)
    return b""


def _entries(tiff: bytes, order: str, directory: int) -> dict[int, tuple[int, int, int]]:
    """A TIFF directory's entries: tag -> (type, count, offset of the 4-byte value field)."""
    (count,) = struct.unpack_from(order + "H", tiff, directory)
    found = {}
    for k in range(min(count, MAX_ENTRIES)):
        tag, kind, values = struct.unpack_from(order + "HHI", tiff, directory + 2 + 12 * k)
        found[tag] = (kind, values, directory + 2 + 12 * k + 8)
    return found


def _ascii(tiff: bytes, order: str, entry: tuple[int, int, int] | None) -> str:
    if entry is None or entry[0] != ASCII:
        return ""
    _, count, field = entry
    start = field if count <= 4 else struct.unpack_from(order + "I", tiff, field)[0]
    return tiff[start:start + count].split(b"\x00", 1)[0].decode("ascii", "replace").strip()


def exif_tags(data: bytes) -> tuple[int, str, str, str]:
    """(orientation, DateTimeOriginal, SubSecTimeOriginal, OffsetTimeOriginal) of a photo's EXIF: 1 and empty
    texts where it records none (or its structure is broken)."""
    tiff = exif_tiff(data)
    order = {b"II": "<", b"MM": ">"}.get(tiff[:2])
    if order is None:
        return 1, "", "", ""
    try:
        first = _entries(tiff, order, struct.unpack_from(order + "I", tiff, 4)[0])
        orientation = 1
        if ORIENTATION_TAG in first and first[ORIENTATION_TAG][0] == SHORT:
            (orientation,) = struct.unpack_from(order + "H", tiff, first[ORIENTATION_TAG][2])
    except struct.error:
        return 1, "", "", ""
    pointer = first.get(EXIF_DIRECTORY_TAG)
    if pointer is None or pointer[0] != LONG:
        return orientation, "", "", ""
    try:  # a broken Exif directory leaves the orientation read before it
        exif = _entries(tiff, order, struct.unpack_from(order + "I", tiff, pointer[2])[0])
        taken, fraction, zone = (_ascii(tiff, order, exif.get(tag)) for tag in (
            DATE_TIME_ORIGINAL_TAG, SUBSEC_TIME_ORIGINAL_TAG, OFFSET_TIME_ORIGINAL_TAG))
    except struct.error:
        return orientation, "", "", ""
    return orientation, taken, fraction, zone


def capture_time(data: bytes) -> tuple[float, bool] | None:
    """When a photo was taken, from its EXIF DateTimeOriginal and SubSecTimeOriginal: (seconds since 1970, whether
    the zone is known). With OffsetTimeOriginal the seconds are UTC's; without it (most cameras) they are the
    camera's clock read as if it were UTC, right for the times between photos of one camera. None without the
    tag or with a time no clock shows ("0000:00:00 00:00:00" where the camera's clock was never set)."""
    _, taken, fraction, zone = exif_tags(data)
    parts = EXIF_TIME.fullmatch(taken)
    if parts is None:
        return None
    try:
        moment = dt.datetime(*map(int, parts.groups()), tzinfo=dt.UTC)
    except ValueError:
        return None
    offset = EXIF_ZONE.fullmatch(zone)
    if offset is not None:
        sign, hours, minutes = offset.groups()
        moment -= (1 if sign == "+" else -1) * dt.timedelta(hours=int(hours), minutes=int(minutes))
    seconds = moment.timestamp()
    if fraction.isdigit():
        seconds += int(fraction) / 10 ** len(fraction)
    return seconds, offset is not None
