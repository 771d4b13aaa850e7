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

NEW_SUBFILE_TYPE, IMAGE_WIDTH, IMAGE_LENGTH = 254, 256, 257
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


def _page_sizes(handle) -> list[tuple[int, int, int]]:  # noqa: ANN001 (a binary file)
    """(width, height, NewSubfileType) of each directory in the main chain."""
    header = handle.read(16)
    order = {b"II": "<", b"MM": ">"}.get(header[:2])
    if order is None:
        return []
    version = struct.unpack(order + "H", header[2:4])[0]
    if version == 42:
        count_format, entry_size, offset_format, offset = "H", 12, "I", struct.unpack(order + "I", header[4:8])[0]
    elif version == 43:  # BigTIFF
        count_format, entry_size, offset_format, offset = "Q", 20, "Q", struct.unpack(order + "Q", header[8:16])[0]
    else:
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
