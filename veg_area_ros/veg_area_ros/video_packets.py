"""Inter-frame video recorded in a bag, one compressed frame per message: Foxglove's CompressedVideo (H.264,
H.265, VP9, AV1; what `foxglove_compressed_video_transport` records) and ffmpeg_image_transport's FFMPEGPacket.

A frame of such a stream needs the frames before it, so the packets are not decoded one by one: they are
written back to back into one raw stream file (Annex B for H.264/H.265, IVF for VP8/VP9/AV1) that OpenCV's
FFmpeg decodes in order. `VideoPacketStream` does that and pairs each decoded frame with its message: packets
before the stream's first keyframe cannot be decoded and are said so; the decoder gives the frames in the order
they were captured, which with B-frames is not the order of the packets, so frames are paired with the messages
in the order of their stamps (the capture times), which is the packets' own order wherever there are no B-frames.

No ROS here: the messages are read from their CDR bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

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
IVF_FOURCC = {"vp8": b"VP80", "vp9": b"VP90", "av1": b"AV01"}
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
    reordered: bool = False  # paired with its frame by its stamp out of the packets' order (B-frames)

    def pixels(self, depth: StreamDepth | None = None, notes: list[str] | None = None) -> np.ndarray:
        if self.frame is None:
            raise ImageMessageError(self.problem)
        if self.reordered and notes is not None:
            notes.append(REORDERED_NOTE)
        return self.frame


REORDERED_NOTE = ("the video stream reorders its frames (B-frames): this frame was paired with its message by the "
                  "stamps, in the order the camera took them")


class VideoPacketStream:
    """A bag topic's video packets decoded in order. `add` every packet in recording order (it is written to a
    raw stream file in `folder`, or counted as undecodable before the first keyframe), then `frames()` pairs
    each added packet with its decoded frame or the reason it has none."""

    def __init__(self, folder: str | Path, topic: str) -> None:
        self.topic = topic
        self.codec: str | None = None
        self.path = Path(folder) / "stream"
        self._file = self.path.open("wb")
        self.stamps: list[int] = []  # per packet: its stamp (ns)
        self.problems: list[str] = []  # per packet: why it has no frame ("" where it has one)
        self._started = False
        self._cra_leading = False  # began at an H.265 CRA: its RASL pictures are not output
        self._ivf_frames = 0

    def add(self, packet: VideoPacket) -> None:
        if self.codec is None:
            self.codec = packet.codec
            if packet.codec in IVF_FOURCC:
                self._file.write(b"DKIF" + struct.pack("<HH4sHHIII", 0, 32, IVF_FOURCC[packet.codec], 0, 0, 1000, 1,
                                                       0) + bytes(4))
        problem = ""
        if packet.codec != self.codec:
            problem = f"its codec is {packet.codec}, the topic's first packet's {self.codec}"
        elif self.codec not in ANNEX_B and self.codec not in IVF_FOURCC:
            problem = f"the codec {self.codec!r} is not one read here (h264, h265/hevc, vp8, vp9, av1)"
        elif self.codec in ANNEX_B and not bytes(packet.data[:4]).startswith((b"\x00\x00\x01", b"\x00\x00\x00\x01")):
            problem = f"its {self.codec} data is not in Annex B form (start codes), as CompressedVideo requires"
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
                problem = "a leading picture of the CRA keyframe the stream begins at, which the decoder skips"
            else:
                self._cra_leading = False
        if not problem:
            if self.codec in IVF_FOURCC:
                self._file.write(struct.pack("<IQ", len(packet.data), self._ivf_frames))
                self._ivf_frames += 1
            self._file.write(packet.data)
        self.stamps.append(packet.header.nanoseconds)
        self.problems.append(problem)

    def add_unreadable(self, problem: str) -> None:
        """A message whose packet cannot be read at all: it has no frame, and a frame after it that needed it
        shows the damage as the decoder conceals it."""
        self.stamps.append(0)
        self.problems.append(problem)

    def frames(self) -> Iterator[tuple[np.ndarray | None, str, bool]]:
        """Per added packet, in the order added: (frame, why it has none, whether it was paired by its stamp
        out of the packets' order). The frames are decoded one by one as they are taken (those a reordered
        packet needs ahead are held)."""
        self._file.close()
        if self.codec in ANNEX_B or self.codec in IVF_FOURCC:  # named as FFmpeg's raw demuxers know it
            suffix = ".ivf" if self.codec in IVF_FOURCC else f".{self.codec}"
            self.path = self.path.rename(self.path.with_suffix(suffix))
        decodable = [i for i, problem in enumerate(self.problems) if not problem]
        by_stamp = sorted(decodable, key=lambda i: (self.stamps[i], i))
        rank = {packet: position for position, packet in enumerate(by_stamp)}
        order = {packet: position for position, packet in enumerate(decodable)}
        capture = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG) if decodable else None
        held: dict[int, np.ndarray] = {}
        decoded = 0
        ended = False
        try:
            for index, problem in enumerate(self.problems):
                if problem:
                    yield None, problem, False
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
                    yield held.pop(wanted), "", wanted != order[index]
                elif decoded == 0:
                    yield None, (f"OpenCV's FFmpeg decoded no frame of this {self.codec} stream on {self.topic} "
                                 f"({len(decodable)} packets from its first keyframe on): its build may have no "
                                 f"{self.codec} decoder; convert the recording, or record image_raw/compressed"), False
                else:
                    yield None, (f"the {self.codec} stream decoded {decoded} frames from {len(decodable)} packets "
                                 "(a damaged packet?): the frames cannot be told apart from here on"), False
        finally:
            if capture is not None:
                capture.release()

