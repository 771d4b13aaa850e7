"""Inter-frame video recorded in a bag, one compressed frame per message: Foxglove's CompressedVideo (H.264,
H.265, VP9, AV1; what `foxglove_compressed_video_transport` records) and ffmpeg_image_transport's FFMPEGPacket.

A frame of such a stream needs the frames before it, so the packets are not decoded one by one: they are
written back to back into stream files that OpenCV's FFmpeg decodes in order, and `VideoPacketStream` pairs each
decoded frame with its message. The files number the packets (IVF files; H.265 in MPEG transport streams; each
packet's timestamp its number), and the decoder hands each frame back with its own packet's number: exact with
B-frames, without stamps, and where the decoder drops or stops at a damaged packet. Damage the decoder conceals
(it reports an error and fills the blocks with guesses) is said on the frames from there up to the keyframe that
clears it (`decoder_messages`, as a video file's). Packets before the stream's first keyframe cannot be decoded
and are said so.

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
from .cdr import Buffer, CdrReader, Header, ImageMessageError
from .decoder_messages import FFMPEG_MESSAGE, with_decoder_messages
from .video_damage import decoder_words, one_thread_capture

FOXGLOVE_VIDEO = "foxglove_msgs/msg/CompressedVideo"
FFMPEG_PACKET = "ffmpeg_image_transport_msgs/msg/FFMPEGPacket"
DECODED_VIDEO_TYPES = (FOXGLOVE_VIDEO, FFMPEG_PACKET)
# theora_image_transport's packets are Ogg packets whose stream headers are sent once to each subscriber
UNDECODED_VIDEO_TYPES = ("theora_image_transport/msg/Packet",)
ANNEX_B = ("h264", "hevc")
# the files the packets are written to: IVF, but FFmpeg's IVF reader takes no H.265, and an H.264 transport stream
# of fewer than 7 frames is not opened (FFmpeg guesses H.264's reordering from 7 decoded frames)
IVF_FOURCC = {"h264": b"H264", "vp8": b"VP80", "vp9": b"VP90", "av1": b"AV01"}
TS_STREAM_TYPES = {"hevc": 0x24}
CHUNK_PACKETS = 240  # a stream file holds this many packets at least, up to the next keyframe
GOP_KEPT = 1000  # an open GOP's keyframe begins a chunk where the GOP before it, given first, is no longer
MAX_REORDER = 16  # H.264 and H.265 hold back at most 16 frames to reorder them: one not given by then is dropped
TS_PMT_PID, TS_VIDEO_PID = 0x1000, 0x100
AV_PKT_FLAG_KEY = 1  # FFMPEGPacket.flags: libavcodec's packet flags
H264_RECOVERY_POINT = 6  # the SEI payload type that marks where decoding can begin without an IDR


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


def decode_video_packet(msgtype: str, buffer: Buffer) -> VideoPacket:
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
        reader.unpack("Q")  # pts: the stream files number the packets themselves (`PacketChunk`)
        flags, _ = reader.unpack("BB")  # flags, is_bigendian
        return VideoPacket(header, codec_name(encoding), reader.octets(), bool(flags & AV_PKT_FLAG_KEY))
    raise ImageMessageError(f"{msgtype} is not a video packet read here")


def _nal_units(data: bytes) -> Iterator[tuple[int, int]]:
    """Where each NAL unit of Annex B data lies: (its first byte, after its 00 00 01 start code; the next start
    code or the end)."""
    start = data.find(b"\x00\x00\x01")
    while 0 <= start < len(data) - 3:
        end = data.find(b"\x00\x00\x01", start + 3)
        yield start + 3, len(data) if end < 0 else end
        start = end


def _nal_types(codec: str, data: bytes) -> list[int]:
    """The NAL unit types of Annex B data (H.264: the low 5 bits of the unit's first byte; H.265: 6 bits after
    its first)."""
    return [data[first] & 0x1F if codec == "h264" else (data[first] >> 1) & 0x3F for first, _ in _nal_units(data)]


def _h264_sei_payload_types(data: bytes) -> list[int]:
    """The payload types of the SEI messages in H.264 Annex B data (each SEI NAL unit's emulation prevention
    bytes removed)."""
    types = []
    for first, end in _nal_units(data):
        if data[first] & 0x1F == 6:
            body = data[first + 1:end].replace(b"\x00\x00\x03", b"\x00\x00")
            offset = 0
            while offset < len(body) and body[offset:].rstrip(b"\x00") != b"\x80":  # up to the trailing bits
                fields = []
                for _ in range(2):  # the payload's type, then its size: 255 for each 0xFF byte, then the last
                    value = 0
                    while offset < len(body) and body[offset] == 0xFF:
                        value, offset = value + 255, offset + 1
                    if offset >= len(body):
                        return types
                    fields.append(value + body[offset])
                    offset += 1
                types.append(fields[0])
                offset += fields[1]
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
    or a recovery point (H.264: an open GOP's I-frame, as x264's open-gop writes it), an IRAP picture (H.265: BLA,
    IDR, CRA), a sequence header (AV1), a key frame (VP8, VP9)."""
    if packet.keyframe_flag is not None:
        return packet.keyframe_flag
    data = bytes(packet.data)
    if packet.codec == "h264":
        types = _nal_types("h264", data)
        return 5 in types or (6 in types and H264_RECOVERY_POINT in _h264_sei_payload_types(data))
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
    """A keyframe that nothing after it refers past (an H.264 IDR, an H.265 IDR or BLA; a VP8, VP9 or AV1
    keyframe), so that decoding can start again there without losing a frame: an H.264 I-frame flagged as a
    keyframe in an open GOP, an H.265 CRA, are not."""
    if packet.codec == "h264":
        return 5 in _nal_types("h264", bytes(packet.data))
    if packet.codec == "hevc":  # an IDR or BLA (a CRA's leading pictures refer to the frames before it)
        return any(16 <= kind <= 20 for kind in _nal_types("hevc", bytes(packet.data)))
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
    notes: tuple[str, ...] = ()  # what makes the frame less sure (CONCEALED_NOTE, `concealed_damage_note`)

    def pixels(self, depth: StreamDepth | None = None, notes: list[str] | None = None) -> np.ndarray:
        if self.frame is None:
            raise ImageMessageError(self.problem)
        if notes is not None:
            notes.extend(self.notes)
        return self.frame


LEADING_SKIPPED = "a leading picture of the CRA keyframe the stream begins at, which the decoder skips"
CONCEALED_NOTE = ("a packet of the video stream that this frame may refer to has no frame: where it does, the "
                  "decoder filled in what it lacked")


def concealed_damage_note(said: str) -> str:
    """What a frame says that was decoded after the decoder reported damage it concealed, before the keyframe
    that clears it."""
    return (f"video damaged: the decoder reported an error ({decoder_words(said)}) in a packet this frame is or "
            "may refer to, and filled the damaged blocks with guesses from other frames (up to the next keyframe), "
            "so Af may be off: look at the overlay")


class VideoPacketStream:
    """A bag topic's video packets decoded in order. `add` every packet in recording order (it is written to a
    stream file in `folder`, or counted as undecodable before the first keyframe) and take what `ready()` gives
    after each; then `frames()` gives the rest: each added packet's decoded frame or the reason it has none, in
    the order added. The files are `PacketChunk`s: the pairing is exact, B-frames too, and a packet the decoder
    gives no frame for is that packet's row alone."""

    def __init__(self, folder: str | Path, topic: str) -> None:
        self.topic = topic
        self.codec: str | None = None
        self.folder = Path(folder)
        self.problems: list[str] = []  # per packet: why it has no frame ("" where it has one)
        self.frames_decoded = 0
        self._started = False
        self._cra_leading = False  # began at an H.265 CRA: its RASL pictures are not output
        self._chunks: list[PacketChunk] = []
        # the packets from the last keyframe on (None past GOP_KEPT): a chunk begun at an open GOP's
        # keyframe is given them first, for its leading pictures to refer to
        self._gop: list[tuple[bytes, bool, bool]] | None = None
        self._decoded = self._decode_chunks()
        self._taken = 0  # the packets whose results have been given
        self.notes: list[str] = []  # per packet: CONCEALED_NOTE where it may refer to a lost packet
        # keyframes still to come before the frames can no longer refer to a lost packet: a closed one clears it,
        # an open GOP's the second (the first one's leading pictures may refer to the lost packet's GOP)
        self._keyframes_to_clear = 0

    def add(self, packet: VideoPacket) -> None:
        if self.codec is None:
            self.codec = packet.codec
        problem = ""
        if packet.codec != self.codec:
            problem = f"its codec is {packet.codec}, the topic's first packet's {self.codec}"
        elif self.codec not in IVF_FOURCC and self.codec not in TS_STREAM_TYPES:
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
                self._add(LEADING_SKIPPED, lost=False)  # no later picture refers to it
                return
            self._cra_leading = False
        if not problem:
            keyframe, closed = is_keyframe(packet), _closed_keyframe(packet)
            if closed:
                self._keyframes_to_clear = 0
            elif keyframe:
                self._keyframes_to_clear = max(0, self._keyframes_to_clear - 1)
            self._write(packet, keyframe, closed)
        self._add(problem)

    def _add(self, problem: str, lost: bool = True) -> None:
        self.notes.append(CONCEALED_NOTE if self._keyframes_to_clear and not problem else "")
        if problem and lost and self._started:
            self._keyframes_to_clear = 2
        self.problems.append(problem)

    def _write(self, packet: VideoPacket, keyframe: bool, closed: bool) -> None:
        if not self._chunks or (len(self._chunks[-1]) >= CHUNK_PACKETS and (
                closed or (keyframe and self._gop is not None))):
            if self._chunks:
                self._chunks[-1].close()
            self._chunks.append(PacketChunk(self.folder / f"stream-{len(self._chunks):05d}", self.codec,
                                            len(self.problems), [] if closed or not self._chunks else self._gop))
        if keyframe or closed:
            self._gop = []
        if self._gop is not None and len(self._gop) < GOP_KEPT:
            self._gop.append((bytes(packet.data), keyframe, closed))
        else:
            self._gop = None
        self._chunks[-1].add(packet.data, keyframe, closed)

    def add_unreadable(self, problem: str) -> None:
        """A message whose packet cannot be read at all: it has no frame, and the frames after it up to the next
        keyframe say that they may refer to it."""
        self._add(problem)

    def ready(self) -> Iterator[tuple[np.ndarray | None, str, tuple[str, ...]]]:
        """As `frames()`, for the packets added so far whose frames can be decoded now: those before the chunk
        being written (each chunk begins at a keyframe, an open GOP's given the GOP before it). Take them all before
        the next `add`: a long recording is decoded as it is read, a chunk's file removed once its frames are out."""
        return self._frames_by_number(self._chunks[-1].first if self._chunks else len(self.problems))

    def frames(self) -> Iterator[tuple[np.ndarray | None, str, tuple[str, ...]]]:
        """Per added packet not yet given by `ready()`, in the order added: (frame, why it has none, what makes
        it less sure: a packet before it that it may refer to is lost, damage the decoder concealed). The frames
        are decoded one by one as they are taken (those the decoder gives ahead of a reordered packet are held)."""
        if self._chunks:
            self._chunks[-1].close()
        return self._frames_by_number(len(self.problems))

    def _no_decoder(self) -> str:
        return (f"OpenCV's FFmpeg decoded no frame of this {self.codec} stream on {self.topic} up to here: a damaged "
                f"keyframe, or a build with no {self.codec} decoder (then convert the recording, or record "
                "image_raw/compressed)")

    def _decode_chunks(self) -> Iterator[tuple[np.ndarray | None, str, str]]:
        done = 0
        while done < len(self._chunks):  # the list grows as packets are added
            yield from self._chunks[done].decode(self)
            done += 1

    def _frames_by_number(self, until: int) -> Iterator[tuple[np.ndarray | None, str, tuple[str, ...]]]:
        while self._taken < until:
            problem, note = self.problems[self._taken], self.notes[self._taken]
            self._taken += 1
            if problem:
                yield None, problem, ()
                continue
            frame, problem, damage = next(self._decoded)
            if frame is None and not self.frames_decoded:
                problem = self._no_decoder()
            yield frame, problem, tuple(text for text in (note, damage) if text)


def ivf_packets(data: bytes) -> list[bytes]:
    """The frames of an IVF file (its 32-byte header, then each frame's 12-byte header and bytes), as a recorder
    of a VP8/VP9/AV1 camera would send them one per message."""
    packets, offset = [], 32
    while offset + 12 <= len(data):
        (length,) = struct.unpack_from("<I", data, offset)
        packets.append(data[offset + 12:offset + 12 + length])
        offset += 12 + length
    return packets


def _mpeg_crc32(data: bytes) -> int:
    """CRC-32/MPEG-2, the checksum of a transport stream's tables (zlib's CRC-32 is the reflected one)."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte << 24
        for _ in range(8):
            crc = ((crc << 1) ^ 0x04C11DB7 if crc & 0x80000000 else crc << 1) & 0xFFFFFFFF
    return crc


def _ts_packets(pid: int, payload: bytes, counter: int) -> tuple[bytes, int]:
    """`payload` (a table or a PES packet, begun in the first) as 188-byte transport stream packets, the last
    filled out by an adaptation field; and the continuity counter after them."""
    out = bytearray()
    for start in range(0, max(len(payload), 1), 184):
        chunk = payload[start:start + 184]
        stuffing = 184 - len(chunk)
        adaptation = b"" if not stuffing else b"\x00" if stuffing == 1 else bytes(
            [stuffing - 1, 0]) + b"\xff" * (stuffing - 2)
        out += bytes([0x47, (0x40 if not start else 0) | pid >> 8, pid & 0xFF,
                      (0x30 if adaptation else 0x10) | counter & 0xF]) + adaptation + chunk
        counter += 1
    return bytes(out), counter


def _ts_table(table_id: int, body: bytes) -> bytes:
    """A transport stream table section (PAT, PMT), with its pointer field and checksum."""
    length = len(body) + 9  # the five bytes after the length, the body, the CRC
    section = bytes([table_id, 0xB0 | length >> 8, length & 0xFF]) + b"\x00\x01\xc1\x00\x00" + body
    return b"\x00" + section + struct.pack(">I", _mpeg_crc32(section))


class PacketChunk:
    """Packets of one stream from a keyframe on, in a file that numbers them: an IVF file (H.264, VP8, VP9, AV1:
    its position as the frame's timestamp in a 1/1000 s time base) or an MPEG transport stream (H.265: each packet
    a PES whose PTS is its position x 90, a millisecond). OpenCV gives the number back as CAP_PROP_POS_MSEC with
    the frame it decodes from that packet. Where the decoder stops (a damaged packet), it is started again
    from the chunk's next keyframe (its own file from there on, numbered from there)."""

    STOPPED = ("the decoder stopped at a damaged packet before this one's frame: decoding resumed at the next "
               "keyframe")
    DROPPED = "the decoder gave no frame for this packet (damaged, or it refers to a damaged one)"
    LEADING = ("a leading picture of the open GOP's keyframe decoding began at: it refers to frames before that "
               "keyframe, which were not decoded")

    def __init__(self, path: Path, codec: str, first: int, prefix: list[tuple[bytes, bool, bool]] = ()) -> None:
        self.ts_stream_type = TS_STREAM_TYPES.get(codec)
        self.path = path.with_suffix(".ts" if self.ts_stream_type else ".ivf")
        self.fourcc = IVF_FOURCC.get(codec, b"")
        self.first = first  # the stream's index of its first packet
        self.offsets: list[int] = []  # of each position's framing in the file
        self.keyframes: list[int] = []
        self.closed: set[int] = set()  # the keyframes nothing after refers past (`_closed_keyframe`)
        self._restarts: list[Path] = []  # the files decoding was started again from
        self._counter = 0  # the transport stream's continuity counter
        self._file = self.path.open("wb")
        self._file.write(self._header())
        for data, keyframe, closed in prefix:
            self.add(data, keyframe, closed)
        self.skip = len(prefix)  # the previous GOP's packets, decoded only for the chunk's first frames

    def _header(self) -> bytes:
        if self.ts_stream_type is None:
            return b"DKIF" + struct.pack("<HH4sHHIII", 0, 32, self.fourcc, 0, 0, 1000, 1, 0) + bytes(4)
        pat, _ = _ts_packets(0, _ts_table(0x00, struct.pack(">HH", 1, 0xE000 | TS_PMT_PID)), 0)
        pmt, _ = _ts_packets(TS_PMT_PID, _ts_table(0x02, struct.pack(
            ">HHBHH", 0xE000 | TS_VIDEO_PID, 0xF000, self.ts_stream_type, 0xE000 | TS_VIDEO_PID, 0xF000)), 0)
        return pat + pmt

    def __len__(self) -> int:
        return len(self.offsets) - self.skip

    def add(self, data: memoryview, keyframe: bool, closed: bool = False) -> None:
        position = len(self.offsets)
        if keyframe or closed:
            self.keyframes.append(position)
        if closed:
            self.closed.add(position)
        self.offsets.append(self._file.tell())
        if self.ts_stream_type is None:
            self._file.write(struct.pack("<IQ", len(data), position))
            self._file.write(data)
            return
        pts = 90 * position
        pts_field = bytes([0x21 | (pts >> 29) & 0x0E, (pts >> 22) & 0xFF, 0x01 | (pts >> 14) & 0xFE,
                           (pts >> 7) & 0xFF, 0x01 | (pts << 1) & 0xFE])
        framed, self._counter = _ts_packets(TS_VIDEO_PID, b"\x00\x00\x01\xe0\x00\x00\x80\x80\x05" + pts_field
                                            + bytes(data), self._counter)
        self._file.write(framed)

    def close(self) -> None:
        self._file.close()

    def remove(self) -> None:
        for path in [self.path, *self._restarts]:
            path.unlink(missing_ok=True)

    def _clearing_keyframe(self, last: int) -> int | None:
        """The first position past a damaged packet at `last` or before from which no frame refers to it: a
        closed keyframe, or the second open GOP's keyframe (the first one's leading pictures may refer to the GOP
        before); None: not in this chunk."""
        opened = 0
        for key in self.keyframes:
            if key <= last:
                continue
            opened += key not in self.closed
            if key in self.closed or opened == 2:
                return key
        return None

    def _from(self, first: int) -> Path:
        """The chunk from position `first` (a keyframe) on, as a file of its own whose numbers, as the decoder
        gives them, count from there: an IVF file's renumbered from 0 (copied as they were, OpenCV gave no frame
        of it), a transport stream's copied as they are (FFmpeg gives each PTS less the first one's)."""
        path = self.path.with_name(f"{self.path.stem}-from-{first}{self.path.suffix}")
        self._restarts.append(path)
        with self.path.open("rb") as source, path.open("wb") as target:
            target.write(self._header())
            source.seek(self.offsets[first])
            if self.ts_stream_type is not None:
                while block := source.read(1 << 20):
                    target.write(block)
                return path
            for position in range(first, len(self.offsets)):
                size, _ = struct.unpack("<IQ", source.read(12))
                target.write(struct.pack("<IQ", size, position - first))
                target.write(source.read(size))
        return path

    def decode(self, stream: VideoPacketStream) -> Iterator[tuple[np.ndarray | None, str, str]]:
        """Per position in order: its frame, or why it has none, and what the decoder reported of damage it
        concealed in this frame or one it may refer to ('' where nothing); counts the frames in
        `stream.frames_decoded` (where no capture has given a frame, the decoder is not restarted at every
        keyframe). The chunk's files are removed as its last frame is given."""
        held: dict[int, np.ndarray] = {}  # frames the decoder gave ahead of the position asked for
        base, restarted = 0, False
        reached = -1  # the highest number the decoder has given
        lag = 0  # how far the decoder has given a frame behind the highest number it gave before (B-frames)
        # what the decoder reported, the first position it may reach and the position that clears it
        damage: tuple[str, int, int | None] | None = None
        capture: cv2.VideoCapture | None = one_thread_capture(str(self.path), cv2.CAP_FFMPEG)
        try:
            for position in range(self.skip, len(self.offsets)):
                problem = self.DROPPED
                while position not in held and len(held) <= MAX_REORDER:
                    if position < base:
                        problem = self.STOPPED
                        break
                    if capture is None:
                        break
                    # a decoder that stops is said by the rows it stops; one that conceals, by its words
                    (ok, frame), said = (with_decoder_messages(capture.read, FFMPEG_MESSAGE.match)
                                         if capture.isOpened() else ((False, None), ""))
                    if ok:
                        number = base + round(capture.get(cv2.CAP_PROP_POS_MSEC))
                        stream.frames_decoded += 1
                        lag = max(lag, reached - number)
                        if said:
                            # the packet it decoded in this read follows every number it gave before, and lies
                            # at most as far ahead of them as the frames it holds back to reorder
                            first = max(reached, base - 1) + 1
                            clears = self._clearing_keyframe(first + lag)
                            if damage is not None:  # one still reaching frames: its words, the later clearing
                                said, first = damage[0], damage[1]
                                clears = None if clears is None or damage[2] is None else max(clears, damage[2])
                            damage = said, first, clears
                        reached = max(reached, number)
                        if position <= number < len(self.offsets):
                            held.setdefault(number, frame)
                        continue
                    capture.release()
                    capture = None
                    # stopped short of a keyframe (else it went to the end, dropping what it gave no frame for)
                    later = [key for key in self.keyframes if key > max(position, reached)]
                    if later and (stream.frames_decoded or not restarted):
                        base, restarted = later[0], True
                        capture = one_thread_capture(str(self._from(base)), cv2.CAP_FFMPEG)
                if problem == self.DROPPED and base not in self.closed and not any(
                        base < key <= position for key in self.keyframes):
                    problem = self.LEADING
                if damage is not None and damage[2] is not None and position >= damage[2]:
                    damage = None
                concealed = damage is not None and position >= damage[1]
                result = ((held.pop(position), "", concealed_damage_note(damage[0]) if concealed else "")
                          if position in held else (None, problem, ""))
                if position == len(self.offsets) - 1:  # its files go before the last frame is given
                    if capture is not None:
                        capture.release()
                        capture = None
                    self.remove()
                yield result
        finally:
            if capture is not None:
                capture.release()
