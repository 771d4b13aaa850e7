"""Which pages of a TIFF file are a stack of frames: the images of its main chain of directories that have the
first one's size and are not reduced-resolution previews. ImageJ and Fiji save a stack (a timelapse, a burst)
as one TIFF, a page per frame; cameras and scanners may add a thumbnail page, and pyramid TIFFs (microscopy)
smaller copies, which are no frames. Read from the directories alone (tags 254, 256, 257), classic TIFF and
BigTIFF, without decoding a pixel.

No ROS here.
"""

from __future__ import annotations

import os
import struct

NEW_SUBFILE_TYPE, IMAGE_WIDTH, IMAGE_LENGTH, IMAGE_DESCRIPTION = 254, 256, 257, 270
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
    pages = [k for k, (width, height, kind) in enumerate(sizes)
             if (width, height) == first and not kind & REDUCED_RESOLUTION]
    return pages if len(pages) > 1 else []


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
    order, count_format, entry_size, offset_format, offset = _header(handle)
    if order is None:
        return ""
    offset_size = struct.calcsize(offset_format)
    handle.seek(offset)
    (entries,) = struct.unpack(order + count_format, handle.read(struct.calcsize(count_format)))
    block = handle.read(entries * entry_size)
    for k in range(entries):
        entry = block[k * entry_size:(k + 1) * entry_size]
        tag, kind = struct.unpack(order + "HH", entry[:4])
        if tag != IMAGE_DESCRIPTION or kind != 2:
            continue
        (count,) = struct.unpack(order + offset_format, entry[4:4 + offset_size])
        if count <= offset_size:
            text = entry[4 + offset_size:4 + offset_size + count]
        elif count <= MAX_DESCRIPTION:
            handle.seek(struct.unpack(order + offset_format, entry[4 + offset_size:])[0])
            text = handle.read(count)
        else:
            return ""
        return text.split(b"\0", 1)[0].decode("latin-1")
    return ""


def _header(handle) -> tuple[str | None, str, int, str, int]:  # noqa: ANN001 (a binary file)
    """(byte order, directory count format, entry size, offset format, first directory's offset); order None
    for a file that is no TIFF."""
    header = handle.read(16)
    order = {b"II": "<", b"MM": ">"}.get(header[:2])
    if order is None:
        return None, "", 0, "", 0
    version = struct.unpack(order + "H", header[2:4])[0]
    if version == 42:
        return order, "H", 12, "I", struct.unpack(order + "I", header[4:8])[0]
    if version == 43:  # BigTIFF
        return order, "Q", 20, "Q", struct.unpack(order + "Q", header[8:16])[0]
    return None, "", 0, "", 0


def _page_sizes(handle) -> list[tuple[int, int, int]]:  # noqa: ANN001 (a binary file)
    """(width, height, NewSubfileType) of each directory in the main chain."""
    order, count_format, entry_size, offset_format, offset = _header(handle)
    if order is None:
        return []
    count_size, offset_size = struct.calcsize(count_format), struct.calcsize(offset_format)
    sizes: list[tuple[int, int, int]] = []
    seen: set[int] = set()
    while offset and offset not in seen and len(sizes) < MAX_PAGES:
        seen.add(offset)
        handle.seek(offset)
        (entries,) = struct.unpack(order + count_format, handle.read(count_size))
        block = handle.read(entries * entry_size + offset_size)
        if len(block) < entries * entry_size + offset_size:
            raise ValueError("a directory runs past the file")
        tags = {}
        for k in range(entries):
            entry = block[k * entry_size:(k + 1) * entry_size]
            tag, kind = struct.unpack(order + "HH", entry[:4])
            if tag in (NEW_SUBFILE_TYPE, IMAGE_WIDTH, IMAGE_LENGTH) and kind in _TYPE_FORMATS:
                value = entry[4 + offset_size:]  # after the count: the value itself, left-justified
                tags[tag] = struct.unpack_from(order + _TYPE_FORMATS[kind], value)[0]
        sizes.append((tags.get(IMAGE_WIDTH, 0), tags.get(IMAGE_LENGTH, 0), tags.get(NEW_SUBFILE_TYPE, 0)))
        (offset,) = struct.unpack(order + offset_format, block[entries * entry_size:])
    return sizes
