"""An image file's EXIF orientation, and its pixels kept in the grid they were stored in (the sensor's).

A phone or a DSLR writes which way up it was held (EXIF tag 274, 1-8), and OpenCV, like a photo viewer, turns
the image by it when decoding. A phone's video carries the same as a rotation
of its container's display matrix. A camera held by hand around a board, or pointing straight down at a flume,
writes a different tag from shot to shot: turned, the same sensor gave 640x480 and 480x640 frames, so a
calibration kept only the views of one orientation (and fitted the sensor turned), and a photo taken the other
way round was refused by it. The lens's geometry belongs to the sensor's grid, so frames are read as stored,
and a frame whose tag would have turned it says so (its pixel coordinates are not a viewer's).

No ROS here.
"""

from __future__ import annotations

import struct

import numpy as np

ORIENTATION_TAG = 0x0112
EXIF_PREFIX = b"Exif\x00\x00"
# what a viewer does to the stored image for each tag
SHOWN_AS = {2: "mirrored left to right", 3: "turned 180°", 4: "mirrored top to bottom",
            5: "mirrored along its diagonal", 6: "turned 90° clockwise", 7: "mirrored along its other diagonal",
            8: "turned 90° anticlockwise"}


def _tiff_orientation(tiff: bytes) -> int:
    """The orientation tag of a TIFF structure's first directory (EXIF's IFD0); 1 where there is none."""
    if tiff.startswith(EXIF_PREFIX):
        tiff = tiff[len(EXIF_PREFIX):]
    order = {b"II": "<", b"MM": ">"}.get(tiff[:2])
    if order is None:
        return 1
    try:
        (directory,) = struct.unpack_from(order + "I", tiff, 4)
        (count,) = struct.unpack_from(order + "H", tiff, directory)
        for k in range(min(count, 1000)):
            tag, kind = struct.unpack_from(order + "HH", tiff, directory + 2 + 12 * k)
            if tag == ORIENTATION_TAG and kind == 3:  # a SHORT, stored first in the value field
                (value,) = struct.unpack_from(order + "H", tiff, directory + 2 + 12 * k + 8)
                return value if value in SHOWN_AS else 1
    except struct.error:
        pass
    return 1


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


def stored_orientation(data: bytes) -> int:
    """The EXIF orientation (1-8) a JPEG, PNG, WebP or TIFF file records; 1 where it records none."""
    if data[:2] == b"\xff\xd8":
        return _tiff_orientation(_jpeg_exif(data))
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return _tiff_orientation(_chunk(data, 8, True, b"eXIf"))
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return _tiff_orientation(_chunk(data, 12, False, b"EXIF"))
    if is_tiff(data):
        return _tiff_orientation(data)
    return 1


def is_tiff(data: bytes) -> bool:
    """OpenCV turns a TIFF by its orientation even when told not to: `as_stored` turns it back."""
    return data[:4] in (b"II*\x00", b"MM\x00*")


def as_stored(shown: np.ndarray, orientation: int) -> np.ndarray:
    """The stored grid of an image that was turned for showing by `orientation` (the inverse of SHOWN_AS)."""
    undo = {2: lambda x: x[:, ::-1], 3: lambda x: x[::-1, ::-1], 4: lambda x: x[::-1],
            5: lambda x: np.swapaxes(x, 0, 1), 6: lambda x: np.rot90(x, 1),
            7: lambda x: np.swapaxes(x, 0, 1)[::-1, ::-1], 8: lambda x: np.rot90(x, -1)}
    return np.ascontiguousarray(undo[orientation](shown)) if orientation in undo else shown


def video_rotation_note(degrees: float) -> str:
    """What a video's frame read as stored says where its container's display matrix would have turned it."""
    turn = round(degrees) % 360
    if turn == 0:
        return ""
    return (f"video rotation {turn}° not applied: read as stored, the sensor's pixel grid that the calibration "
            "holds for, which a video player shows turned; a ROI or hand-picked pixels are taken in the stored grid")


def orientation_note(orientation: int) -> str:
    """What a frame read as stored says where its file would have been turned ('' where it would not)."""
    if orientation not in SHOWN_AS:
        return ""
    return (f"EXIF orientation {orientation} not applied: read as stored, the sensor's pixel grid that the "
            f"calibration holds for, which a photo viewer shows {SHOWN_AS[orientation]}; a ROI or hand-picked "
            "pixels are taken in the stored grid")
