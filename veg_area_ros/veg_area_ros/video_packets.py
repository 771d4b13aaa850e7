"""Inter-frame video recorded in a bag, one compressed frame per message: Foxglove's CompressedVideo (H.264,
H.265, VP9, AV1; what `foxglove_compressed_video_transport` records) and ffmpeg_image_transport's FFMPEGPacket.

A frame of such a stream needs the frames before it, so the packets are not decoded one by one: they are
written back to back into stream files that OpenCV's FFmpeg decodes in order, and `VideoPacketStream` pairs each
decoded frame with its message. H.264, VP8, VP9 and AV1 go into IVF files whose timestamps number the packets,
so each frame comes back with its own packet's number (exact with B-frames too); H.265, which FFmpeg's IVF reader
does not take, goes into one Annex B stream whose frames come in capture order and are paired with the messages
in the order of their stamps. Packets before the stream's first keyframe cannot be decoded and are said so.

No ROS here: the messages are read from their CDR bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import cv2
import numpy as np

from .bit_depth import StreamDepth
from .cdr import CdrReader, Header, ImageMessageError

FOXGLOVE_VIDEO = "foxglove_msgs/msg/CompressedVideo"
FFMPEG_PACKET = "ffmpeg_image_transport_msgs/msg/FFMPEGPacket"
DECODED_VIDEO_TYPES = (FOXGLOVE_VIDEO, FFMPEG_PACKET)
# theora_image_transport's packets are Ogg packets whose stream headers are sent once to each subscriber
UNDECODED_VIDEO_TYPES = ("theora_image_transport/msg/Packet",)
ANNEX_B = ("h264", "hevc")
# decoded from IVF files (FFmpeg's IVF reader takes H.264 as well, not H.265)
IVF_FOURCC = {"h264": b"H264", "vp8": b"VP80", "vp9": b"VP90", "av1": b"AV01"}
CHUNK_PACKETS = 240  # an IVF file holds this many packets at least, up to the next keyframe
MAX_REORDER = 16  # H.264 holds back at most 16 frames to reorder them: a frame not given by then is dropped
AV_PKT_FLAG_KEY = 1  # FFMPEGPacket.flags: libavcodec's packet flags


@dataclass(frozen=True)
class VideoPacket:
    """One message's compressed frame: its header (Foxglove's timestamp and frame_id as one), the codec named
    as `codec_name` names it, the bytes, and whether the packet says it is a keyframe (None: it does not say)."""

    header: Header
    codec: str
    data: memoryview
    keyframe_flag: bool | None = None


def codec_name(text: str) -> str:
    """A codec as FFmpeg names it, from a Foxglove `format` (h264, h265, vp9, av1) or an FFMPEGPacket
    `encoding` ("hevc;yuv420p;bgr8;bgr8", or the encoder of older versions: libx264, h264_nvenc, hevc_vaapi);
    the text itself (lower case) where it names none of these."""
    first = text.split(";", 1)[0].strip().lower()
    for name, marks in (("h264", ("264", "avc")), ("hevc", ("265", "hevc")), ("vp9", ("vp9",)),
                        ("vp8", ("vp8",)), ("av1", ("av1",))):
        if any(mark in first for mark in marks):
            return name
    return first


def decode_video_packet(msgtype: str, buffer) -> VideoPacket:
    """Serialized CompressedVideo or FFMPEGPacket -> a VideoPacket, its data a view (no copy) of `buffer`."""
    reader = CdrReader(buffer)
    if msgtype == FOXGLOVE_VIDEO:
        sec, nanosec = reader.unpack("iI")
        frame_id = reader.string()
        data = reader.octets()
        return VideoPacket(Header(sec, nanosec, frame_id), codec_name(reader.string()), data)
    if msgtype == FFMPEG_PACKET:
        header = reader.header()
        reader.unpack("ii")  # width, height: the decoder reads them from the stream
        encoding = reader.string()
        reader.unpack("Q")  # pts: the frames are paired with their messages by the stamps
        flags, _ = reader.unpack("BB")  # flags, is_bigendian
        return VideoPacket(header, codec_name(encoding), reader.octets(), bool(flags & AV_PKT_FLAG_KEY))
    raise ImageMessageError(f"{msgtype} is not a video packet read here")


def _nal_types(codec: str, data: bytes) -> list[int]:
    """The NAL unit types of Annex B data, each after its 00 00 01 start code (H.264: the low 5 bits of the
    unit's first byte; H.265: 6 bits after its first)."""
    types, start = [], data.find(b"\x00\x00\x01")
    while 0 <= start < len(data) - 3:
        byte = data[start + 3]
        types.append(byte & 0x1F if codec == "h264" else (byte >> 1) & 0x3F)
        start = data.find(b"\x00\x00\x01", start + 3)
    return types


def _av1_obu_types(data: bytes) -> Iterator[int]:
    """The OBU types of AV1's low-overhead bitstream (each OBU with its size field)."""
    offset = 0
    while offset < len(data):
        header = data[offset]
        extension = (header >> 2) & 1
        offset += 1 + extension
        yield (header >> 3) & 0xF
        if not (header >> 1) & 1:  # no size field: the OBU runs to the end
            return
        size = shift = 0
        while offset < len(data):
            byte = data[offset]
            offset += 1
            size |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                break
        offset += size


def _vp9_is_keyframe(data: bytes) -> bool:
    """A VP9 frame's uncompressed header: frame_marker (2 bits), profile (2), a reserved bit in profile 3,
    show_existing_frame, frame_type (0: a keyframe)."""
    if not data or data[0] >> 6 != 2:
        return False
    bits = f"{data[0]:08b}{data[1] if len(data) > 1 else 0:08b}"
    position = 4 + (bits[2:4] == "11")  # profile 3 (its low bit first, then its high bit)
    return bits[position] == "0" and bits[position + 1] == "0"


def is_keyframe(packet: VideoPacket) -> bool:
    """Whether the stream can begin to be decoded at this packet: its flag where it has one; else an IDR NAL unit
    (H.264), an IRAP picture (H.265: BLA, IDR, CRA), a sequence header (AV1), a key frame (VP8, VP9)."""
    if packet.keyframe_flag is not None:
        return packet.keyframe_flag
    data = bytes(packet.data)
    if packet.codec == "h264":
        return 5 in _nal_types("h264", data)
    if packet.codec == "hevc":
        return any(16 <= kind <= 23 for kind in _nal_types("hevc", data))
    if packet.codec == "vp9":
        return _vp9_is_keyframe(data)
    if packet.codec == "vp8":
        return bool(data) and not data[0] & 1
    if packet.codec == "av1":
        return 1 in _av1_obu_types(data)
    return False


def _closed_keyframe(packet: VideoPacket) -> bool:
    """A keyframe that nothing after it refers past (an H.264 IDR; any VP8, VP9 or AV1 keyframe), so that
    decoding can start again there without losing a frame: an H.264 I-frame flagged as a keyframe in an open GOP
    is not one."""
    if packet.codec == "h264":
        return 5 in _nal_types("h264", bytes(packet.data))
    return is_keyframe(packet)


def _hevc_skipped_leading(data: bytes) -> bool:
    """An H.265 picture that the decoder drops where decoding begins at a CRA: RASL (NAL types 8, 9)."""
    vcl = [kind for kind in _nal_types("hevc", data) if kind < 32]
    return bool(vcl) and vcl[0] in (8, 9)


@dataclass(frozen=True)
class DecodedVideoFrame:
    """One video packet's frame as the stream decoded it (`video_packets.VideoPacketStream`), or why it has none;
    read as an Image message's fields are."""

    header: Header
    frame: np.ndarray | None
    problem: str = ""
    note: str = ""  # what makes the frame's pairing or its pixels less sure (REORDERED_NOTE, CONCEALED_NOTE)

    def pixels(self, depth: StreamDepth | None = None, notes: list[str] | None = None) -> np.ndarray:
        if self.frame is None:
            raise ImageMessageError(self.problem)
        if self.note and notes is not None:
            notes.append(self.note)
        return self.frame


REORDERED_NOTE = ("the video stream reorders its frames (B-frames): this frame was paired with its message by the "
                  "stamps, in the order the camera took them")
LEADING_SKIPPED = "a leading picture of the CRA keyframe the stream begins at, which the decoder skips"
CONCEALED_NOTE = ("a packet of the video stream since its last keyframe has no frame: this frame may refer to it, "
                  "and the decoder then filled in what it lacked")


class VideoPacketStream:
    """A bag topic's video packets decoded in order. `add` every packet in recording order (it is written to a
    stream file in `folder`, or counted as undecodable before the first keyframe), then `frames()` pairs
    each added packet with its decoded frame or the reason it has none.

    H.264, VP8, VP9 and AV1 are written into IVF files whose timestamps number the packets, and the decoder
    hands each frame back with its packet's number: the pairing is exact, B-frames too, and a packet the decoder
    gives no frame for is that packet's row alone (`IvfChunk`). FFmpeg's IVF reader does not take H.265: it is
    decoded as one Annex B stream and its frames paired with the packets by their stamps."""

    def __init__(self, folder: str | Path, topic: str) -> None:
        self.topic = topic
        self.codec: str | None = None
        self.folder = Path(folder)
        self.stamps: list[int] = []  # per packet: its stamp (ns)
        self.problems: list[str] = []  # per packet: why it has no frame ("" where it has one)
        self.frames_decoded = 0
        self._started = False
        self._cra_leading = False  # began at an H.265 CRA: its RASL pictures are not output
        self._chunks: list[IvfChunk] = []
        self._decoded = self._decode_chunks()
        self._taken = 0  # the packets whose results have been given
        self._annex_b: BinaryIO | None = None
        self.notes: list[str] = []  # per packet: CONCEALED_NOTE where a packet before it since a keyframe is lost
        self._lost_since_keyframe = False

    def add(self, packet: VideoPacket) -> None:
        if self.codec is None:
            self.codec = packet.codec
        problem = ""
        if packet.codec != self.codec:
            problem = f"its codec is {packet.codec}, the topic's first packet's {self.codec}"
        elif self.codec not in IVF_FOURCC and self.codec not in ANNEX_B:
            problem = f"the codec {self.codec!r} is not one read here (h264, h265/hevc, vp8, vp9, av1)"
        elif self.codec in ANNEX_B and not bytes(packet.data[:4]).startswith((b"\x00\x00\x01", b"\x00\x00\x00\x01")):
            problem = f"its {self.codec} data is not in Annex B form (start codes), as CompressedVideo requires"
        elif self.codec == "h264" and not {1, 5} & set(_nal_types("h264", bytes(packet.data))):
            problem = "it holds no picture (no slice NAL unit): the decoder would stop at it"
        elif not self._started:
            if is_keyframe(packet):
                self._started = True
                self._cra_leading = self.codec == "hevc" and not {19, 20} & set(
                    _nal_types("hevc", bytes(packet.data)))
            else:
                problem = ("recorded before the stream's first keyframe: an inter-frame video's frame cannot be "
                           "decoded without the keyframe before it")
        elif self._cra_leading:
            if _hevc_skipped_leading(bytes(packet.data)):
                self._add(packet.header.nanoseconds, LEADING_SKIPPED, lost=False)  # no later picture refers to it
                return
            self._cra_leading = False
        if not problem:
            if self._lost_since_keyframe and _closed_keyframe(packet):
                self._lost_since_keyframe = False
            self._write(packet)
        self._add(packet.header.nanoseconds, problem)

    def _add(self, stamp: int, problem: str, lost: bool = True) -> None:
        self.notes.append(CONCEALED_NOTE if self._lost_since_keyframe and not problem else "")
        self._lost_since_keyframe |= bool(problem) and lost and self._started
        self.stamps.append(stamp)
        self.problems.append(problem)

    def _write(self, packet: VideoPacket) -> None:
        if self.codec not in IVF_FOURCC:
            if self._annex_b is None:
                self._annex_b = (self.folder / f"stream.{self.codec}").open("wb")
            self._annex_b.write(packet.data)
            return
        keyframe = _closed_keyframe(packet)
        if not self._chunks or (keyframe and len(self._chunks[-1]) >= CHUNK_PACKETS):
            if self._chunks:
                self._chunks[-1].close()
            self._chunks.append(IvfChunk(self.folder / f"stream-{len(self._chunks):05d}.ivf", self.codec,
                                         len(self.problems)))
        self._chunks[-1].add(packet.data, keyframe)

    def add_unreadable(self, problem: str) -> None:
        """A message whose packet cannot be read at all: it has no frame, and a frame after it that needed it
        shows the damage as the decoder conceals it."""
        self._add(0, problem)

    def ready(self) -> Iterator[tuple[np.ndarray | None, str, str]]:
        """As `frames()`, for the packets added so far whose frames can be decoded now: those before the IVF
        chunk being written (each chunk begins at a keyframe, so nothing in it refers to a later one). Take them
        all before the next `add`: a long recording is decoded as it is read, a chunk's file removed once its
        frames are out. H.265 gives its frames at `frames()` only."""
        if self.codec in IVF_FOURCC:
            yield from self._frames_by_number(self._chunks[-1].first if self._chunks else len(self.problems))

    def frames(self) -> Iterator[tuple[np.ndarray | None, str, str]]:
        """Per added packet not yet given by `ready()`, in the order added: (frame, why it has none, what makes
        it less sure: its pairing by the stamps out of the packets' order, a packet it may refer to lost). The
        frames are decoded one by one as they are taken (those a reordered packet needs ahead are held)."""
        if self.codec in IVF_FOURCC or not self._started:
            if self._chunks:
                self._chunks[-1].close()
            return self._frames_by_number(len(self.problems))
        if self._annex_b is not None:
            self._annex_b.close()
        return self._frames_by_stamp()

    def _no_decoder(self) -> str:
        return (f"OpenCV's FFmpeg decoded no frame of this {self.codec} stream on {self.topic} up to here: a damaged "
                f"keyframe, or a build with no {self.codec} decoder (then convert the recording, or record "
                "image_raw/compressed)")

    def _decode_chunks(self) -> Iterator[tuple[np.ndarray | None, str]]:
        done = 0
        while done < len(self._chunks):  # the list grows as packets are added
            yield from self._chunks[done].decode(self)
            done += 1

    def _frames_by_number(self, until: int) -> Iterator[tuple[np.ndarray | None, str, str]]:
        while self._taken < until:
            problem, note = self.problems[self._taken], self.notes[self._taken]
            self._taken += 1
            if problem:
                yield None, problem, ""
                continue
            frame, problem = next(self._decoded)
            if frame is None and not self.frames_decoded:
                problem = self._no_decoder()
            yield frame, problem, note

    def _frames_by_stamp(self) -> Iterator[tuple[np.ndarray | None, str, str]]:
        decodable = [i for i, problem in enumerate(self.problems) if not problem]
        by_stamp = sorted(decodable, key=lambda i: (self.stamps[i], i))
        rank = {packet: position for position, packet in enumerate(by_stamp)}
        order = {packet: position for position, packet in enumerate(decodable)}
        capture = cv2.VideoCapture(str(self._annex_b.name), cv2.CAP_FFMPEG) if decodable else None
        held: dict[int, np.ndarray] = {}
        decoded = 0
        ended = False
        try:
            for index, problem in enumerate(self.problems):
                if problem:
                    yield None, problem, ""
                    continue
                wanted = rank[index]
                while wanted not in held and not ended:
                    ok, frame = capture.read() if capture is not None and capture.isOpened() else (False, None)
                    if not ok:
                        ended = True
                        break
                    held[decoded] = frame
                    decoded += 1
                if wanted in held:
                    yield held.pop(wanted), "", REORDERED_NOTE if wanted != order[index] else self.notes[index]
                elif decoded == 0:
                    yield None, self._no_decoder(), ""
                else:
                    yield None, (f"the {self.codec} stream decoded {decoded} frames from {len(decodable)} packets "
                                 "(a damaged packet?): the frames cannot be told apart from here on"), ""
        finally:
            if capture is not None:
                capture.release()


class IvfChunk:
    """Packets of one stream from a keyframe on, in an IVF file: each framed with its position in the chunk as its
    timestamp (in a 1/1000 s time base, so that OpenCV gives it back as CAP_PROP_POS_MSEC with its frame).
    Where the decoder stops (a damaged packet), it is started again from the chunk's next keyframe, which these
    codecs' keyframes allow (nothing after one refers to anything before it)."""

    STOPPED = ("the decoder stopped at a damaged packet before this one's frame: decoding resumed at the next "
               "keyframe")
    DROPPED = "the decoder gave no frame for this packet (damaged, or it holds no picture)"

    def __init__(self, path: Path, codec: str, first: int) -> None:
        self.path = path
        self.first = first  # the stream's index of its first packet
        self.fourcc = IVF_FOURCC[codec]
        self.offsets: list[int] = []  # of each position's frame header in the file
        self.keyframes: list[int] = []
        self._restarts: list[Path] = []  # the files decoding was started again from
        self._file = path.open("wb")
        self._file.write(self._header())

    def _header(self) -> bytes:
        return b"DKIF" + struct.pack("<HH4sHHIII", 0, 32, self.fourcc, 0, 0, 1000, 1, 0) + bytes(4)

    def __len__(self) -> int:
        return len(self.offsets)

    def add(self, data: memoryview, keyframe: bool) -> None:
        if keyframe:
            self.keyframes.append(len(self.offsets))
        self.offsets.append(self._file.tell())
        self._file.write(struct.pack("<IQ", len(data), len(self.offsets) - 1))
        self._file.write(data)

    def close(self) -> None:
        self._file.close()

    def remove(self) -> None:
        for path in [self.path, *self._restarts]:
            path.unlink(missing_ok=True)

    def _from(self, first: int) -> Path:
        """The chunk from position `first` (a keyframe) on, renumbered from 0, as a file of its own."""
        path = self.path.with_name(f"{self.path.stem}-from-{first}.ivf")
        self._restarts.append(path)
        with self.path.open("rb") as source, path.open("wb") as target:
            target.write(self._header())
            for position in range(first, len(self.offsets)):
                source.seek(self.offsets[position])
                size, _ = struct.unpack("<IQ", source.read(12))
                target.write(struct.pack("<IQ", size, position - first))
                target.write(source.read(size))
        return path

    def decode(self, stream: VideoPacketStream) -> Iterator[tuple[np.ndarray | None, str]]:
        """Per position in order: its frame, or why it has none; counts the frames in `stream.frames_decoded`
        (where no capture has given a frame, the decoder is not restarted at every keyframe). The chunk's files
        are removed as its last frame is given."""
        held: dict[int, np.ndarray] = {}  # frames the decoder gave ahead of the position asked for
        base, restarted = 0, False
        capture: cv2.VideoCapture | None = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG)
        try:
            for position in range(len(self.offsets)):
                problem = self.DROPPED
                while position not in held and len(held) <= MAX_REORDER:
                    if capture is None or position < base:
                        problem = self.STOPPED
                        break
                    ok, frame = capture.read() if capture.isOpened() else (False, None)
                    if ok:
                        number = base + round(capture.get(cv2.CAP_PROP_POS_MSEC))
                        stream.frames_decoded += 1
                        if position <= number < len(self.offsets):
                            held.setdefault(number, frame)
                        continue
                    capture.release()
                    capture = None
                    later = [key for key in self.keyframes if key > position]
                    if later and (stream.frames_decoded or not restarted):
                        base, restarted = later[0], True
                        capture = cv2.VideoCapture(str(self._from(base)), cv2.CAP_FFMPEG)
                result = (held.pop(position), "") if position in held else (None, problem)
                if position == len(self.offsets) - 1:  # its files go before the last frame is given
                    if capture is not None:
                        capture.release()
                        capture = None
                    self.remove()
                yield result
        finally:
            if capture is not None:
                capture.release()
