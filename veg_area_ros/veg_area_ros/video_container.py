"""What a video's container says of how its levels encode light, and where its keyframes are. No ROS here.

Phones film HDR video by default (iPhones since 2020 in HLG, many Android phones in PQ, HDR10). OpenCV
decodes such a stream to 8 bits, and its grey levels then encode light by neither `linear` nor `srgb` (the
same samples tagged HLG or PQ decode markedly brighter than untagged): Otsu's threshold and the edges' shares
sit off the edges as on an sRGB video read as linear. An MP4 or QuickTime file (ISO base media) names the curve
in its video sample entry's colour box (`colr`, `nclx` in MP4, `nclc` in QuickTime) as an ITU-T H.273 transfer
code point. Only the boxes on the way there are read: `moov` whole (a few MB for hours of video), the rest
skipped by its size."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

HDR_TRANSFERS = {16: "PQ (SMPTE ST 2084, HDR10)", 18: "HLG (ARIB STD-B67)"}  # H.273 transfer characteristics
VISUAL_ENTRY_FIELDS = 78  # a visual sample entry's fixed fields before its child boxes (ISO/IEC 14496-12)
STSD_FIELDS = 8  # version, flags and the entry count
MAX_MOOV_BYTES = 512 * 1024 * 1024  # a movie header is a few MB even for hours; more is not a movie header


def box_header(head: bytes, at: int, room: int) -> tuple[bytes, int, int] | None:
    """(type, header length, box size) of the box whose header starts at head[at:], where `room` bytes are left
    for it (a size of 0: the rest); None where it does not fit in them."""
    size, kind = struct.unpack_from(">I4s", head, at)
    header = 8
    if size == 1 and room >= 16 and at + 16 <= len(head):
        (size,), header = struct.unpack_from(">Q", head, at + 8), 16
    elif size == 0:
        size = room
    return None if size < header or size > room else (kind, header, size)


def boxes(data: bytes, start: int = 0, end: int | None = None) -> Iterator[tuple[bytes, int, int]]:
    """(type, body start, body end) of each box in data[start:end]; stops at the first one that does not fit."""
    end = len(data) if end is None else end
    offset = start
    while offset + 8 <= end:
        found = box_header(data, offset, end - offset)
        if found is None:
            return
        kind, header, size = found
        yield kind, offset + header, offset + size
        offset += size


def movie_header(path: Path) -> bytes | None:
    """The body of the file's `moov` box, or None for a file that is not ISO base media or has none."""
    try:
        with open(path, "rb") as file:
            file.seek(0, 2)
            length, offset = file.tell(), 0
            while offset + 8 <= length:
                file.seek(offset)
                found = box_header(file.read(16), 0, length - offset)
                if found is None or not all(32 <= c < 127 for c in found[0]):
                    return None  # not a box: no ISO base media file
                kind, header, size = found
                if kind == b"moov":
                    if size - header > MAX_MOOV_BYTES:
                        return None
                    file.seek(offset + header)
                    return file.read(size - header)
                offset += size
    except OSError:
        return None
    return None


def transfer_characteristics(path: Path) -> int | None:
    """The H.273 transfer code point the first video track's colour box names, or None where it names none."""
    moov = movie_header(path)
    for table in _video_sample_tables(moov) if moov is not None else ():
        stsd = table.get(b"stsd")
        if stsd is None:
            continue
        for _, entry_start, entry_end in boxes(moov, stsd[0] + STSD_FIELDS, stsd[1]):
            for kind, s, e in boxes(moov, entry_start + VISUAL_ENTRY_FIELDS, entry_end):
                if kind == b"colr" and e - s >= 10 and moov[s:s + 4] in (b"nclx", b"nclc"):
                    return struct.unpack_from(">H", moov, s + 6)[0]
    return None


@dataclass(frozen=True)
class Keyframes:
    """The first video track's keyframes (sync samples, from 0, in decoding order); `reordered`: its frames are
    shown in another order than decoded (B-frames, a composition offset table)."""

    frames: tuple[int, ...] | None  # None: every frame is one (the table is absent)
    reordered: bool

    def next_after(self, frame: int) -> int | None:
        """The first keyframe after `frame`, None where there is none."""
        if self.frames is None:
            return frame + 1
        return next((key for key in self.frames if key > frame), None)


def keyframes(path: Path) -> Keyframes | None:
    """An MP4 or QuickTime file's keyframes (its sync sample table, `stss`); None where the file lists none
    (another container, a damaged header)."""
    moov = movie_header(path)
    for table in _video_sample_tables(moov) if moov is not None else ():
        reordered = b"ctts" in table
        if b"stss" not in table:
            return Keyframes(None, reordered)
        start, end = table[b"stss"]
        if end - start < 8:
            return None
        (count,) = struct.unpack_from(">I", moov, start + 4)
        if count > (end - start - 8) // 4:
            return None
        numbers = struct.unpack_from(f">{count}I", moov, start + 8)
        return Keyframes(tuple(sorted(number - 1 for number in numbers)), reordered)
    return None


def _video_sample_tables(moov: bytes) -> Iterator[dict[bytes, tuple[int, int]]]:
    """Each video track's sample table boxes (`stbl`'s children: stsd, stss, ctts ...) by type."""
    for kind, start, end in boxes(moov):
        if kind != b"trak":
            continue
        inside = {kind: (s, e) for kind, s, e in boxes(moov, start, end)}
        if b"mdia" not in inside:
            continue
        media = {kind: (s, e) for kind, s, e in boxes(moov, *inside[b"mdia"])}
        handler = media.get(b"hdlr")
        if handler is None or moov[handler[0] + 8:handler[0] + 12] != b"vide" or b"minf" not in media:
            continue
        table = next(((s, e) for kind, s, e in boxes(moov, *media[b"minf"]) if kind == b"stbl"), None)
        if table is not None:
            yield {kind: (s, e) for kind, s, e in boxes(moov, *table)}


def hdr_note(path: Path) -> str:
    """What a frame of an HDR video says of its levels ('' where the container names no HDR curve)."""
    curve = HDR_TRANSFERS.get(transfer_characteristics(path))
    if curve is None:
        return ""
    return (f"HDR video ({curve}): its grey levels follow that curve, which neither tone curve here reads "
            "(linear, srgb), so the threshold and the edges' shares sit off the object's edges (a few % of Af on "
            "a small object, as an sRGB video read as linear); film in SDR (a phone's HDR video off) to measure")
