"""Which pages of a TIFF file are a stack of frames: the images of its main chain of directories that have the
first one's size and are not reduced-resolution previews. ImageJ and Fiji save a stack (a timelapse, a burst)
as one TIFF, a page per frame; cameras and scanners may add a thumbnail page, and pyramid TIFFs (microscopy)
smaller copies, which are no frames. Read from the directories alone (tags 254, 256, 257, and each page's
Orientation, 274, which OpenCV applies to a page whatever its flags), classic TIFF and BigTIFF, without decoding
a pixel.

No ROS here.
"""

from __future__ import annotations

import os
import struct

NEW_SUBFILE_TYPE, IMAGE_WIDTH, IMAGE_LENGTH, IMAGE_DESCRIPTION, ORIENTATION = 254, 256, 257, 270, 274
# ImageJ's time units for a stack's frame interval (its Image > Properties), in seconds
TIME_UNITS = {"sec": 1.0, "s": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "msec": 1e-3, "min": 60.0,
              "minute": 60.0, "minutes": 60.0, "hour": 3600.0, "hours": 3600.0, "h": 3600.0}
MAX_DESCRIPTION = 65536
REDUCED_RESOLUTION = 1  # NewSubfileType bit 0: a preview of another page
MAX_PAGES = 1_000_000  # a chain longer than this is damaged (or loops)
_TYPE_FORMATS = {3: "H", 4: "I", 16: "Q"}  # SHORT, LONG, LONG8: the types a size or a subfile type takes


def stack_pages(path: str | os.PathLike) -> list[int]:
    """The page numbers (from 0, in the main chain, as OpenCV numbers them) of a TIFF's frames where it holds
    two or more of the first page's size; [] for one image (with or without previews), a file that is no TIFF
    or whose directories cannot be read (it is then read as one image, as before)."""
    try:
        with open(path, "rb") as handle:
            sizes = _page_sizes(handle)
    except (OSError, struct.error, ValueError):
        return []
    if not sizes:
        return []
    first = sizes[0][:2]
    pages = [k for k, (width, height, kind, _) in enumerate(sizes)
             if (width, height) == first and not kind & REDUCED_RESOLUTION]
    return pages if len(pages) > 1 else []


def page_orientations(path: str | os.PathLike) -> list[int]:
    """Each page's Orientation tag (1-8; 1 where it has none or an invalid one) in the main chain, as
    `stack_pages` numbers them; [] where the directories cannot be read."""
    try:
        with open(path, "rb") as handle:
            sizes = _page_sizes(handle)
    except (OSError, struct.error, ValueError):
        return []
    return [orientation if 1 <= orientation <= 8 else 1 for *_, orientation in sizes]


def frame_interval(path: str | os.PathLike) -> float | None:
    """Seconds between a stack's frames as ImageJ and Fiji record them (`finterval=` in the first page's
    ImageDescription, in its `tunit`, seconds by default), or None: a timelapse saved as a stack is then a
    time series in seconds, as a video is."""
    try:
        with open(path, "rb") as handle:
            description = _first_description(handle)
    except (OSError, struct.error, ValueError):
        return None
    if not description.startswith("ImageJ="):
        return None
    fields = dict(line.split("=", 1) for line in description.splitlines() if "=" in line)
    try:
        interval = float(fields.get("finterval", "nan"))
    except ValueError:
        return None
    unit = TIME_UNITS.get(fields.get("tunit", "sec").strip().lower())
    return interval * unit if unit and 0 < interval < float("inf") else None


def _first_description(handle) -> str:  # noqa: ANN001 (a binary file)
    """The first page's ImageDescription (ASCII), or ''."""
    layout = _header(handle)
    if layout is None:
        return ""
    entries, _ = _directory(handle, layout, layout[3])
    if IMAGE_DESCRIPTION not in entries:
        return ""
    kind, count, value = entries[IMAGE_DESCRIPTION]
    order, offset_format = layout[0], layout[2]
    if kind != 2 or count > MAX_DESCRIPTION:
        return ""
    if count <= len(value):  # held in the entry itself
        text = value[:count]
    else:
        handle.seek(struct.unpack(order + offset_format, value)[0])
        text = handle.read(count)
    return text.split(b"\0", 1)[0].decode("latin-1")


def _header(handle) -> tuple[str, str, str, int] | None:  # noqa: ANN001 (a binary file)
    """(byte order, directory count format, offset format, first directory's offset) of a classic TIFF or a
    BigTIFF; None for a file that is neither."""
    header = handle.read(16)
    order = {b"II": "<", b"MM": ">"}.get(header[:2])
    if order is None:
        return None
    version = struct.unpack(order + "H", header[2:4])[0]
    if version == 42:
        return order, "H", "I", struct.unpack(order + "I", header[4:8])[0]
    if version == 43:  # BigTIFF
        return order, "Q", "Q", struct.unpack(order + "Q", header[8:16])[0]
    return None


def _directory(handle, layout: tuple[str, str, str, int], offset: int  # noqa: ANN001 (a binary file)
               ) -> tuple[dict[int, tuple[int, int, bytes]], int]:
    """A directory's entries, tag -> (type, count, value field: the value itself, left-justified, or where it
    lies), and the next directory's offset (0: the last). ValueError where it runs past the file."""
    order, count_format, offset_format, _ = layout
    count_size, offset_size = struct.calcsize(count_format), struct.calcsize(offset_format)
    entry_size = 4 + 2 * offset_size  # tag, type, count, value field
    handle.seek(offset)
    (count,) = struct.unpack(order + count_format, handle.read(count_size))
    block = handle.read(count * entry_size + offset_size)
    if len(block) < count * entry_size + offset_size:
        raise ValueError("a directory runs past the file")
    entries = {}
    for k in range(count):
        entry = block[k * entry_size:(k + 1) * entry_size]
        tag, kind = struct.unpack(order + "HH", entry[:4])
        (values,) = struct.unpack(order + offset_format, entry[4:4 + offset_size])
        entries[tag] = (kind, values, entry[4 + offset_size:])
    (following,) = struct.unpack(order + offset_format, block[count * entry_size:])
    return entries, following


def _page_sizes(handle) -> list[tuple[int, int, int, int]]:  # noqa: ANN001 (a binary file)
    """(width, height, NewSubfileType, Orientation) of each directory in the main chain."""
    layout = _header(handle)
    if layout is None:
        return []
    order, offset = layout[0], layout[3]
    sizes: list[tuple[int, int, int, int]] = []
    seen: set[int] = set()
    while offset and offset not in seen and len(sizes) < MAX_PAGES:
        seen.add(offset)
        entries, offset = _directory(handle, layout, offset)
        tags = {tag: struct.unpack_from(order + _TYPE_FORMATS[kind], value)[0]
                for tag, (kind, _, value) in entries.items()
                if tag in (NEW_SUBFILE_TYPE, IMAGE_WIDTH, IMAGE_LENGTH, ORIENTATION) and kind in _TYPE_FORMATS}
        sizes.append((tags.get(IMAGE_WIDTH, 0), tags.get(IMAGE_LENGTH, 0), tags.get(NEW_SUBFILE_TYPE, 0),
                      tags.get(ORIENTATION, 1)))
    return sizes
