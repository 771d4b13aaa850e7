"""A JPEG's marker structure checked without decoding it: a scrambled or cut scan, which libjpeg decodes into
a grey smear with no more than a warning on stderr (a scrambled middle measured -47 %). Used for image files
and for the JPEG frames of `compressed` image messages alike. No ROS here.
"""

from __future__ import annotations

import re
import struct

JPEG_START = b"\xff\xd8"
JPEG_STANDALONE_MARKERS = {0x01, *range(0xD0, 0xD9)}  # TEM, restarts, start of image: no length follows
_JPEG_SEGMENTS = {0xC4, 0xCC, 0xDA, 0xDB, 0xDC, 0xDD, 0xFE, *range(0xE0, 0xF0)}  # may follow a scan
_MARKER_IN_SCAN = re.compile(rb"\xff[\x01-\xfe]")  # FF 00 is a stuffed byte, FF FF a fill byte


def jpeg_structure_problem(data: bytes) -> str | None:
    """What breaks a JPEG's marker structure, or None. In a scan's entropy-coded data a 0xFF byte is followed
    only by 0x00 (stuffing) or the restart markers in order; scrambled data shows other markers there, which
    libjpeg only warns about while it decodes a grey smear (a scrambled middle measured -47 %)."""
    offset = 2
    while offset + 2 <= len(data):
        if data[offset] != 0xFF:
            return f"no marker at byte {offset}"
        marker = data[offset + 1]
        if marker == 0xFF:
            offset += 1
            continue
        if marker == 0xD9:
            return None
        if marker in JPEG_STANDALONE_MARKERS:
            offset += 2
            continue
        if offset + 4 > len(data):
            break
        (length,) = struct.unpack(">H", data[offset + 2:offset + 4])
        if length < 2 or offset + 2 + length > len(data):
            return f"segment 0xFF{marker:02X} at byte {offset} runs past the file"
        if marker == 0xDA and not (length >= 8 and length == 6 + 2 * data[offset + 4] and 1 <= data[offset + 4] <= 4):
            return f"bad scan header at byte {offset}"
        offset += 2 + length
        if marker != 0xDA:
            continue
        expected_restart = 0
        for found in _MARKER_IN_SCAN.finditer(data, offset):
            code = found.group()[1]
            if 0xD0 <= code <= 0xD7:
                if code - 0xD0 != expected_restart:
                    return f"restart marker {code - 0xD0} where {expected_restart} was due, at byte {found.start()}"
                expected_restart = (expected_restart + 1) % 8
                continue
            if code == 0xD9 or code in _JPEG_SEGMENTS:
                offset = found.start()
                break
            return f"marker 0xFF{code:02X} inside the image data at byte {found.start()}"
        else:
            return "no end-of-image marker after the image data"
    return "no end-of-image marker"
