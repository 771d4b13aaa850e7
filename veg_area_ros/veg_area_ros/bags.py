"""rosbag2 recording, recovery and reading with the pure-Python `rosbags` library (no ROS here).

Recording writes the serialized (CDR) messages straight into the bag, never deserialized. MCAP is the
default storage (what `ros2 bag record` writes today), sqlite3 on request. A recorder killed without warning
(SIGKILL, power cut) has no MCAP summary and no metadata.yaml: `recover_bag` rebuilds a readable bag from
every complete chunk (the data is flushed to disk chunk by chunk, about 1 MB each), so at most the chunk
being filled is lost. Reading hands image messages over as zero-copy views (veg_area_ros.cdr).
"""

from __future__ import annotations

import contextlib
import functools
import os
import sqlite3
import statistics
import struct
import sys
import tempfile
import time
import zlib
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

import yaml
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag1,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import CompressionMode, StoragePlugin
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from .cdr import (
    FOXGLOVE_COMPRESSED_IMAGE,
    FOXGLOVE_RAW_IMAGE,
    CameraInfoFields,
    CompressedImageFields,
    Header,
    ImageFields,
    ImageMessageError,
    decode_camera_info,
    decode_compressed_image,
    decode_foxglove_compressed_image,
    decode_foxglove_raw_image,
    decode_image,
    decode_string,
    zstd_module,
)
from .files import os_reason, special_file, write_atomic
from .strict_yaml import load_text, read_text
from .video_packets import (
    DECODED_VIDEO_TYPES,
    UNDECODED_VIDEO_TYPES,
    DecodedVideoFrame,
    VideoPacket,
    VideoPacketStream,
    decode_video_packet,
    is_keyframe,
)

if TYPE_CHECKING:
    from .cdr import Buffer

MCAP_MAGIC = b"\x89MCAP0\r\n"
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
SQLITE_COMMIT_SECONDS = 1.0  # sqlite3 bags commit this often: a crash loses at most this much
ROS_DISTRO = "kilted"  # the message definitions the bag's types come from (plain rosbags writes 'rosbags')


@dataclass(frozen=True)
class OfferedQos:
    """What one publisher of a topic offered, as rosbag2 keeps it so that `ros2 bag play` offers it again
    (a latched camera_info stays latched)."""

    reliability: str = "reliable"  # reliable | best_effort
    durability: str = "volatile"  # volatile | transient_local
    history: str = "keep_last"
    depth: int = 10

    def to_rosbags(self) -> Qos:
        never = QosTime(0x7FFFFFFF, 0xFFFFFFFF)  # rosbag2's "infinite" duration
        return Qos(QosHistory[self.history.upper()], self.depth, QosReliability[self.reliability.upper()],
                   QosDurability[self.durability.upper()], never, never, QosLiveliness.AUTOMATIC, never, False)


class BagError(ValueError):
    """A bag that cannot be written, read or recovered; the message says why."""


OUR_MESSAGES = "veg_area_msgs"  # the package whose .msg files are registered with the Kilted types


def our_message_files() -> list[Path]:
    """veg_area_msgs's .msg files: installed (share/veg_area_msgs/msg in an ament prefix: AMENT_PREFIX_PATH, then
    this interpreter's prefix, as `make install` leaves .venv) or, in a source checkout, the repository's."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    for folder in [Path(p, "share", OUR_MESSAGES, "msg") for p in prefixes] + [
            Path(__file__).resolve().parents[2] / OUR_MESSAGES / "msg"]:
        files = sorted(folder.glob("*.msg"))
        if files:
            return files
    return []


@functools.lru_cache(maxsize=1)
def _our_types() -> tuple:
    types: dict = {}
    for path in our_message_files():
        types.update(get_types_from_msg(path.read_text(), f"{OUR_MESSAGES}/msg/{path.stem}"))
    return tuple(types.items())


def typestore(reader: Reader | None = None) -> Typestore:
    """The Kilted message types with veg_area_msgs's registered (a bag of ProjectedArea is written with its
    definition and read back), and, given a reader, any other type the bag defines itself (MCAP schemas)."""
    store = get_typestore(Stores.ROS2_KILTED)
    ours = dict(_our_types())
    if reader is not None:
        # the bag's own definitions first, ours included: a bag recorded before a field was added to one of our
        # messages is read with the definition it was written with
        for connection in reader.connections:
            if connection.msgtype in store.types or not connection.msgdef.data:
                continue
            try:
                if connection.msgdef.format.name == "MSG":
                    store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
                else:
                    store.register(get_types_from_idl(connection.msgdef.data))
            except Exception:  # a definition rosbags cannot parse: that topic alone stays undecodable
                continue
    store.register({name: definition for name, definition in ours.items() if name not in store.types})
    return store


def topic_name_problem(name: str) -> str | None:
    """Why `name` is not a valid ROS 2 topic name (relative, absolute or private), or None: the rules of
    rcl_validate_topic_name (letters, digits, '_' and '/', '~' only first, '{substitutions}', no empty or
    digit-led token, no trailing '/')."""
    if not name:
        return "a topic name cannot be empty"
    body = name[1:] if name.startswith("~") else name
    if "~" in body:
        return f"topic {name!r}: '~' may only start a name"
    if name.startswith("~") and body and not body.startswith("/"):
        return f"topic {name!r}: '~' must be followed by '/'"
    bad = sorted({c for c in body if not (c.isascii() and (c.isalnum() or c in "_/{}"))})
    if bad:
        return f"topic {name!r}: {''.join(bad)!r} not allowed (letters, digits, '_' and '/')"
    if body.endswith("/") and body != "":
        return f"topic {name!r} must not end with '/'"
    if "//" in body:
        return f"topic {name!r}: '//' (an empty part)"
    for token in body.strip("/").split("/"):
        if token and token[0].isdigit():
            return f"topic {name!r}: a part may not start with a digit ({token!r})"
        if token.count("{") != token.count("}"):
            return f"topic {name!r}: unbalanced '{{' '}}'"
    return None


class _CheckedMcapWriter(McapWriter):
    """rosbags' MCAP storage, written as `ros2 bag record` writes MCAP: chunks compressed with zstd, each chunk's
    CRC, the data section's and the summary's CRC (DataEnd and the footer: corruption can be found), each
    message's publish time the sender's where it is given (`publish_time_ns`, else the receive time), and the
    embedded rosbag2 metadata with the real ROS distribution."""

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        super().__init__(path, CompressionMode.STORAGE)  # zstd chunks, as rosbag2's MCAP storage compresses them
        self.publish_time_ns: int | None = None  # the next message's publish time

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        publish = timestamp if self.publish_time_ns is None else self.publish_time_ns
        self.publish_time_ns = None
        chunk = self.chunk
        self.message_start_time = min(timestamp, self.message_start_time)
        self.message_end_time = max(timestamp, self.message_end_time)
        self.channel_stats[connection.id] += 1
        chunk.message_start_time = min(timestamp, chunk.message_start_time)
        chunk.message_end_time = max(timestamp, chunk.message_end_time)
        chunk.msgs[connection.id].append((timestamp, chunk.bio.tell()))
        # Message record: opcode 0x05, length, channel id, sequence, log time, publish time, data
        chunk.bio.write(struct.pack("<BQHIQQ", 0x05, 2 + 4 + 8 + 8 + len(data), connection.id, 0, timestamp, publish))
        chunk.bio.write(data)
        if chunk.bio.tell() > 2**20:
            self.close_chunk()

    def close_chunk(self) -> None:
        crc = zlib.crc32(self.chunk.bio.getbuffer())
        super().close_chunk()
        # the Chunk record just written: opcode, length, start time, end time, uncompressed size, then its CRC
        (chunk_start,) = struct.unpack_from("<Q", self.chunks[-1].getbuffer(), 16)
        end = self.bio.tell()
        self.bio.seek(chunk_start + 1 + 8 + 24)
        self.bio.write(struct.pack("<I", crc))
        self.bio.seek(end)

    def close(self, version: int, metadata: str) -> None:
        super().close(version, _as_ros_writes_it(metadata))
        _write_section_crcs(self.path)


def _write_section_crcs(path: Path) -> None:
    """The data section's CRC (in DataEnd, the record just before the summary) and the summary's (in the
    footer) of a closed MCAP file, computed in blocks and written in place."""
    with path.open("r+b") as file:
        size = file.seek(0, 2)
        footer = size - 8 - (1 + 8 + 20)
        file.seek(footer + 9)
        summary_start, _ = struct.unpack("<QQ", file.read(16))
        data_end = summary_start - (1 + 8 + 4)

        def crc_of(start: int, stop: int) -> int:
            crc, file_offset = 0, file.seek(start)
            while file_offset < stop:
                block = file.read(min(1 << 20, stop - file_offset))
                crc, file_offset = zlib.crc32(block, crc), file_offset + len(block)
            return crc

        data_crc = crc_of(0, data_end)
        file.seek(data_end + 9)
        file.write(struct.pack("<I", data_crc))
        summary_crc = crc_of(summary_start, footer + 9 + 16)
        file.seek(footer + 9 + 16)
        file.write(struct.pack("<I", summary_crc))


class _CheckedWriter(Writer):
    STORAGE_PLUGINS = MappingProxyType({**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: _CheckedMcapWriter})


class BagRecorder:
    """Writes serialized messages of named topics into a new rosbag2 folder."""

    def __init__(self, path: str | Path, storage: str = "mcap"):
        if storage not in STORAGES:
            raise BagError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already; a recording never overwrites a bag")
        self._writer = _CheckedWriter(self.path, version=Writer.VERSION_LATEST, storage_plugin=STORAGES[storage])
        self._writer.open()
        self._types = typestore()
        self._connections: dict[str, object] = {}
        self._chunks_flushed = 0
        self._last_commit = time.monotonic()
        self.counts: dict[str, int] = {}
        self.write_problem: str | None = None  # why messages can no longer be written (then none are tried)
        self.crash_safety_problem = self._check_crash_safety()

    def add_topic(self, topic: str, msgtype: str, offered: list[OfferedQos] = ()) -> None:
        """Register a topic of type `pkg/msg/Name` (its definition comes from ROS 2 Kilted's) with the QoS its
        publishers offered."""
        if topic in self._connections:
            return
        if msgtype not in self._types.types:
            raise BagError(f"message type {msgtype!r} of {topic} is not a ROS 2 Kilted standard type")
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self._types, offered_qos_profiles=[q.to_rosbags() for q in offered])
        self.counts[topic] = 0

    def _check_crash_safety(self) -> str | None:
        """Why a killed recording would lose what was written (the rosbags writer's storage offers no way to push
        it to the file: an MCAP chunk list and file, or a sqlite connection, which are its internals), or None."""
        storage = self._writer.storage
        if (hasattr(storage, "chunks") and hasattr(storage, "bio")) or hasattr(storage, "conn"):
            return None
        return (f"the rosbags writer ({type(storage).__name__}) has neither an MCAP chunk list and file nor a "
                "sqlite connection to flush: a recording that is killed loses what was not closed")

    def write(self, topic: str, timestamp_ns: int, data: bytes | memoryview, publish_ns: int | None = None) -> None:
        """One message received at `timestamp_ns` (its log time), sent at `publish_ns` where the middleware says
        (MCAP's publish time; sqlite3 keeps one time)."""
        if self.write_problem:
            raise BagError(self.write_problem)
        if publish_ns is not None and hasattr(self._writer.storage, "publish_time_ns"):
            self._writer.storage.publish_time_ns = publish_ns
        try:
            self._writer.write(self._connections[topic], timestamp_ns, data)
            self.counts[topic] += 1
            if self.crash_safety_problem:
                return
            storage = self._writer.storage
            if hasattr(storage, "chunks"):
                if len(storage.chunks) != self._chunks_flushed:  # MCAP: a chunk went to the file
                    storage.bio.flush()
                    self._chunks_flushed = len(storage.chunks)
            elif time.monotonic() - self._last_commit > SQLITE_COMMIT_SECONDS:
                storage.conn.commit()
                self._last_commit = time.monotonic()
        except (OSError, sqlite3.Error) as exc:  # a full disk, a removed drive: no later message can be kept
            taken = sum(self.counts.values())
            self.write_problem = (f"{self.path} could not be written ({os_reason(exc)}, a full disk?): recording "
                                  f"stopped after {taken} message{'' if taken == 1 else 's'} were taken; what "
                                  "reached the disk before stays")
            raise BagError(self.write_problem) from exc

    def close(self) -> None:
        """The bag's end (MCAP summary and footer, metadata.yaml). Where it cannot be written (BagError), what
        reached the disk before stays there for `veg-area bag-recover`."""
        try:
            self._writer.close()
            _set_ros_distro(self.path / "metadata.yaml", ROS_DISTRO)
        except (OSError, sqlite3.Error) as exc:
            recover = (f"rebuild a readable bag from it with 'veg-area bag-recover {self.path} NEW_BAG' on a disk "
                       "with space" if any(self.path.glob("*.mcap"))
                       else "the messages committed before are in its .db3 file")
            raise BagError(f"{self.path}: its end could not be written ({os_reason(exc)}): {recover}") from exc



def _as_ros_writes_it(metadata: str) -> str:
    """The rosbag2 metadata embedded in the MCAP as `ros2 bag record` writes it: the real ROS distribution and
    every topic's type hash (RIHS01, from the Kilted type descriptions; the writer leaves it empty there while
    metadata.yaml has it)."""
    information = yaml.safe_load(metadata)  # the bag's information itself, as rosbag2 embeds it
    information["ros_distro"] = ROS_DISTRO
    types = typestore()
    for entry in information.get("topics_with_message_count", []):
        topic = entry["topic_metadata"]
        if not topic.get("type_description_hash") and topic.get("type") in types.types:
            topic["type_description_hash"] = types.hash_rihs01(topic["type"])
    return yaml.safe_dump(information, sort_keys=False).strip()


def _set_ros_distro(metadata: Path, distro: str) -> None:
    """metadata.yaml with the distribution the messages come from, replaced atomically (temp file + rename)."""
    content = load_text(read_text(metadata))
    content["rosbag2_bagfile_information"]["ros_distro"] = distro
    write_atomic(metadata, yaml.safe_dump(content, sort_keys=False))


def _read_record(data: memoryview, offset: int) -> tuple[int, memoryview, int] | None:
    """(opcode, content, next offset) of the MCAP record at `offset`, None if it is cut off."""
    if offset + 9 > len(data):
        return None
    opcode = data[offset]
    (length,) = struct.unpack_from("<Q", data, offset + 1)
    end = offset + 9 + length
    if end > len(data):
        return None
    return opcode, data[offset + 9:end], end


def _string(content: memoryview, offset: int) -> tuple[str, int]:
    (length,) = struct.unpack_from("<I", content, offset)
    return bytes(content[offset + 4:offset + 4 + length]).decode(), offset + 4 + length


@dataclass
class Recovery:
    counts: dict[str, int]  # messages recovered per topic
    dropped: list[str]  # why each damaged chunk or record was left out
    unchecked_chunks: int = 0  # chunks without a CRC (other writers may leave it 0): damage inside cannot be seen


def recover_bag(broken: str | Path, output: str | Path) -> Recovery:
    """A readable copy of an MCAP bag whose recorder died: every message of every complete chunk whose CRC
    matches (and of uncompressed complete records) written through rosbags into `output`. A chunk that is
    damaged (its CRC, its compression or its records) is left out and named in `dropped`."""
    broken = Path(broken)
    if not broken.exists():
        raise BagError(f"{broken}: no such bag")
    files = sorted(broken.glob("*.mcap")) if broken.is_dir() else [broken]
    if not files:
        raise BagError(f"{broken}: no .mcap file to recover")
    special = special_file(files[0])
    if special:
        raise BagError(f"{files[0]}: {special}")
    try:
        data = memoryview(files[0].read_bytes())
    except OSError as exc:
        raise BagError(f"{files[0]}: cannot be read ({exc.strerror or exc})") from exc
    if bytes(data[:8]) != MCAP_MAGIC:
        raise BagError(f"{files[0]}: not an MCAP file (no MCAP magic at its start)")
    schemas: dict[int, tuple[str, str]] = {}
    channels: dict[int, tuple[str, int]] = {}
    messages: list[tuple[int, int, bytes]] = []
    dropped: list[str] = []
    unchecked = [0]

    def record(opcode: int, content: memoryview) -> None:
        if opcode == 0x03:  # schema: id, name, encoding, data
            (schema_id,) = struct.unpack_from("<H", content, 0)
            name, at = _string(content, 2)
            _, at = _string(content, at)
            (length,) = struct.unpack_from("<I", content, at)
            schemas[schema_id] = (name, bytes(content[at + 4:at + 4 + length]).decode())
        elif opcode == 0x04:  # channel: id, schema id, topic, ...
            channel_id, schema_id = struct.unpack_from("<HH", content, 0)
            topic, _ = _string(content, 4)
            channels[channel_id] = (topic, schema_id)
        elif opcode == 0x05:  # message: channel, sequence, log time, publish time, data
            channel_id, _, log_time, publish_time = struct.unpack_from("<HIQQ", content, 0)
            messages.append((channel_id, log_time, publish_time, bytes(content[22:])))

    def chunk(content: memoryview) -> None:
        """A chunk's records, all or none: checked against the chunk's CRC before any is kept."""
        _, _, size, crc = struct.unpack_from("<QQQI", content, 0)
        compression, at = _string(content, 28)
        (length,) = struct.unpack_from("<Q", content, at)
        inner = content[at + 8:at + 8 + length]
        if compression == "zstd":
            inner = memoryview(zstd_module().decompress(bytes(inner)))
        elif compression:
            raise ValueError(f"compression {compression!r} cannot be recovered")
        if len(inner) != size or (crc and zlib.crc32(inner) != crc):
            raise ValueError("its CRC does not match its records")
        unchecked[0] += not crc
        records, offset = [], 0
        while (found := _read_record(inner, offset)) is not None:
            opcode, record_content, offset = found
            records.append((opcode, record_content))
        if offset != len(inner):
            raise ValueError("a record runs past the chunk's end")
        for opcode, record_content in records:
            record(opcode, record_content)

    offset = 8
    while (found := _read_record(data, offset)) is not None:
        opcode, content, next_offset = found
        try:
            chunk(content) if opcode == 0x06 else record(opcode, content)
        except Exception as exc:  # any damage (struct, decode, zstd, CRC) loses this record only, said below
            kind = "chunk" if opcode == 0x06 else f"record 0x{opcode:02x}"
            dropped.append(f"{kind} at byte {offset} dropped: {exc}")
        offset = next_offset
    if not channels:
        raise BagError(f"{files[0]}: no complete chunk: nothing to recover"
                       + (f" ({'; '.join(dropped[:3])})" if dropped else ""))
    recorder = BagRecorder(output, "mcap")
    known = {channel_id: channel for channel_id, channel in channels.items() if channel[1] in schemas}
    for topic, schema_id in known.values():
        recorder.add_topic(topic, schemas[schema_id][0])  # types the recorder could write: Kilted's
    for channel_id, log_time, publish_time, payload in messages:
        if channel_id in known:
            recorder.write(known[channel_id][0], log_time, payload, publish_time)
        else:
            dropped.append(f"a message of channel {channel_id} dropped: its channel or schema was damaged")
    recorder.close()
    return Recovery(dict(recorder.counts), dropped, unchecked[0])


@dataclass
class BagFrame:
    index: int
    timestamp_ns: int  # when the recorder received it
    image: ImageFields | CompressedImageFields | DecodedVideoFrame
    camera_info: CameraInfoFields | None  # the latest camera_info of its camera recorded before this frame
    camera_info_problem: str = ""  # why camera_info is None although one was recorded
    camera_metadata: str | None = None  # the latest camera_info/metadata beside that camera_info, as recorded
    camera_info_note: str = ""  # how its camera_info was paired with it, where not as usual


# a camera's first frames recorded before its first camera_info (the recorder started between the two): held
# until that camera_info comes, up to this many (their pixels are held with them)
EARLY_FRAMES = 8
EARLY_NOTE = ("no camera_info was recorded before this frame (the recording began between an image and its "
              "camera_info): measured with the camera's first one, recorded just after it")


def _open_reader(path: str | Path) -> Reader:
    if not Path(path).exists():
        raise BagError(f"{path}: no such bag (a rosbag2 bag is a folder with metadata.yaml)")
    if not Path(path).is_dir() and Path(path).suffix.lower() == ".bag":  # ROS 1's rosbag record
        from .ros1_bag import Ros1Bag

        try:
            return Ros1Bag(path, typestore())
        except Exception as exc:  # rosbags raises its own error classes for every kind of broken bag
            raise BagError(f"{path}: not a readable ROS 1 bag ({exc})") from exc
    if not Path(path).is_dir() and Path(path).suffix not in (".mcap", ".db3"):
        raise BagError(f"{path}: not a rosbag2 bag (a bag is a folder with metadata.yaml, or its .mcap/.db3 file, "
                       "or ROS 1's .bag)")
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags raises its own error classes for every kind of broken bag
        profile = _mcap_profile(Path(path))
        if profile is not None and profile != "ros2":
            raise BagError(f"{path}: an MCAP file of profile {profile!r}, not a ROS 2 recording (Foxglove's own "
                           "schemas, protobuf or JSON, are not sensor_msgs): record the camera with "
                           "'ros2 bag record' or 'veg-area record'") from exc
        raise BagError(f"{path}: not a readable rosbag2 bag ({exc}); a recording that was killed can be "
                       "rebuilt with 'veg-area bag-recover'") from exc
    return reader


def _mcap_profile(path: Path) -> str | None:
    """The profile an MCAP file's header names ('ros2' for a rosbag2 recording), or None where it is no MCAP."""
    try:
        with path.open("rb") as file:
            head = file.read(8 + 1 + 8 + 4 + 256)
    except OSError:
        return None
    if head[:8] != b"\x89MCAP0\r\n" or head[8:9] != b"\x01":  # the magic, then the Header record
        return None
    (length,) = struct.unpack_from("<I", head, 17)
    return head[21:21 + length].decode("utf-8", "replace") if 21 + length <= len(head) else None


# what a bag's camera frames are recorded as: Image, image_transport's compressed or zstd CompressedImage,
# Foxglove's RawImage and CompressedImage, and inter-frame video packets (`video_packets`: Foxglove's
# CompressedVideo, ffmpeg_image_transport's FFMPEGPacket)
IMAGE_DECODERS = {"sensor_msgs/msg/Image": decode_image, "sensor_msgs/msg/CompressedImage": decode_compressed_image,
                  FOXGLOVE_RAW_IMAGE: decode_foxglove_raw_image,
                  FOXGLOVE_COMPRESSED_IMAGE: decode_foxglove_compressed_image}
IMAGE_TYPES = (*IMAGE_DECODERS, *DECODED_VIDEO_TYPES)
TRANSPORT_SUFFIXES = ("/compressed", "/compressedDepth", "/theora", "/zstd", "/ffmpeg", "/foxglove")


def transport_base(topic: str) -> str:
    """The image topic an image_transport topic carries (/cam/image_raw/compressed -> /cam/image_raw)."""
    return next((topic[: -len(s)] for s in TRANSPORT_SUFFIXES if topic.endswith(s)), topic)


# of one camera's image_transport topics, the one measured when none is named: lossless first, inter-frame last
TRANSPORT_PREFERENCE = ("", "/zstd", "/compressed", "/foxglove", "/ffmpeg")


def _image_connections(reader: Reader, path: str | Path, image_topic: str | None) -> list:
    """The connections of the bag's image topic (sensor_msgs/Image, or CompressedImage as image_transport's
    `compressed` or `zstd` topic records it, or video packets as its `foxglove` or `ffmpeg` topic records them):
    the named one, else the only image topic, else, where every image
    topic is one camera's image_transport topics (`ros2 bag record -a` keeps them all), its raw one (then zstd,
    then compressed, then the video packets: the same frames, lossless first, inter-frame last)."""
    images = [c for c in reader.connections if c.msgtype in IMAGE_TYPES]
    chosen = [c for c in images if image_topic is None or c.topic == image_topic]
    bases = {transport_base(c.topic) for c in chosen}
    if image_topic is None and len(bases) == 1 and len({c.topic for c in chosen}) > 1:
        base = bases.pop()
        best = next((base + suffix for suffix in TRANSPORT_PREFERENCE if any(c.topic == base + suffix
                                                                             for c in chosen)), None)
        chosen = [c for c in chosen if c.topic == best]
    if not images:
        videos = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections
                         if c.msgtype in UNDECODED_VIDEO_TYPES})
        if videos:
            raise BagError(f"{path}: its images are theora video packets ({', '.join(videos)}), which are not "
                           "decoded here: record the camera's image_raw, image_raw/compressed, image_raw/zstd or "
                           "image_raw/foxglove (H.264)")
    if len({c.topic for c in chosen}) != 1:
        raise BagError(f"{path}: pick the image topic (--image-topic); image topics in the bag: "
                       f"{sorted({c.topic for c in images})}")
    return chosen


def sibling_camera_info(image_topic: str) -> str:
    """The camera_info topic that image_transport pairs with an image topic: `camera_info` in the image's
    namespace (/left/image_raw and /left/image_raw/compressed -> /left/camera_info)."""
    namespace = transport_base(image_topic).rsplit("/", 1)[0]
    return f"{namespace}/camera_info"


def _info_connections(reader: Reader, path: str | Path, image_topic: str) -> tuple[list, str]:
    """The camera_info connections for an image topic and, where none can be chosen, why: its sibling
    (`sibling_camera_info`); where the bag has none, its only camera_info topic if there is one (its frame_id is
    then held to the images'); none when the bag recorded no camera_info. Two or more other camera_info topics
    and no sibling: none, and the reason naming them (measuring with a calibration file needs none of them)."""
    infos = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/CameraInfo"]
    sibling = sibling_camera_info(image_topic)
    paired = [c for c in infos if c.topic == sibling]
    if paired or not infos:
        return paired, ""
    if len({c.topic for c in infos}) == 1:
        return infos, ""
    return [], (f"no camera_info beside {image_topic} ({sibling}), and several others "
                f"({', '.join(sorted({c.topic for c in infos}))}): which camera's is meant cannot be told")


def _decode_image(msgtype: str, data: Buffer) -> ImageFields | CompressedImageFields | VideoPacket:
    if msgtype in DECODED_VIDEO_TYPES:
        return decode_video_packet(msgtype, data)
    return IMAGE_DECODERS[msgtype](data)


def _video_frames(path: str | Path, topic: str, folder: str, start: int = 0) -> Iterator[DecodedVideoFrame]:
    """The topic's video packets decoded in recording order (`VideoPacketStream`), one per message, read by a
    reader of their own a keyframe's chunk ahead of the caller's: the frames are decoded as the bag is read,
    not after a pass over the whole recording. Frames before `start` are decoded only from the keyframe
    before the last keyframe up to it (a segment of a long bag does not decode the whole recording before it;
    the keyframe before gives an open GOP's leading pictures what they refer to)."""
    reader = _open_reader(path)
    try:
        stream = VideoPacketStream(folder, topic)
        headers: deque[Header] = deque()

        def taken(results: Iterator[tuple]) -> Iterator[DecodedVideoFrame]:
            for frame, problem, notes in results:
                yield DecodedVideoFrame(headers.popleft(), frame, problem, notes)

        held: list[list] = [[]]  # before `start`: the last two keyframes' packets (or why one cannot be read)
        images = [connection for connection in reader.connections
                  if connection.topic == topic and connection.msgtype in DECODED_VIDEO_TYPES]
        for index, (connection, _, data) in enumerate(reader.messages(connections=images)):
            try:
                packet = decode_video_packet(connection.msgtype, data)
            except ImageMessageError as exc:
                packet, header = str(exc), Header(0, 0, "")
            else:
                header = packet.header
            headers.append(header)
            if index <= start and isinstance(packet, VideoPacket) and is_keyframe(packet):
                if len(held) == 2:
                    for _ in held.pop(0):
                        stream.add_unreadable(BEFORE_SEGMENT)
                held.append([])
            if index < start:
                held[-1].append(packet)
                continue
            for item in [*(item for group in held for item in group), packet]:
                if isinstance(item, str):
                    stream.add_unreadable(item)
                else:
                    stream.add(item)
                yield from taken(stream.ready())
            held = [[]]
        for _ in (item for group in held for item in group):  # the recording ends before `start`
            stream.add_unreadable(BEFORE_SEGMENT)
        yield from taken(stream.frames())
    finally:
        reader.close()


BEFORE_SEGMENT = "not decoded: before the frames asked for and the keyframe they need"


def bag_image_count(path: str | Path, image_topic: str | None = None) -> int:
    return bag_images(path, image_topic)[1]


def bag_images(path: str | Path, image_topic: str | None = None) -> tuple[str, int, list[str]]:
    """The bag's image topic that is read (`_image_connections`), its message count and the bag's other image
    topics (a camera's other transports that `ros2 bag record -a` kept, which are not read)."""
    reader = _open_reader(path)
    try:
        chosen = _image_connections(reader, path, image_topic)
        others = sorted({c.topic for c in reader.connections if c.msgtype in IMAGE_TYPES} - {chosen[0].topic})
        return chosen[0].topic, sum(c.msgcount for c in chosen), others
    finally:
        reader.close()


def bag_camera_info(path: str | Path, image_topic: str | None = None) -> tuple[str, CameraInfoFields] | None:
    """The camera_info topic paired with the bag's image topic and its first message, or None when the bag
    recorded none for it (or none can be told to be its camera's)."""
    reader = _open_reader(path)
    try:
        images = _image_connections(reader, path, image_topic)
        infos, _ = _info_connections(reader, path, images[0].topic)
        if not infos:  # rosbags reads every message for an empty list
            return None
        for connection, _, data in reader.messages(connections=infos[:1]):
            return connection.topic, decode_camera_info(data)
        return None
    finally:
        reader.close()


def iter_bag_frames(path: str | Path, image_topic: str | None = None, start: int = 0) -> Iterator[BagFrame]:
    """The bag's image messages in recording order, each with its camera's camera_info last recorded before it
    (`_info_connections`) and the calibration metadata recorded beside it (`<camera_info>/metadata`, text as
    `calib_io.metadata_message` makes it). Frames recorded before the camera's first camera_info (up to
    `EARLY_FRAMES`) get that one: theirs where its stamp is theirs, else with `EARLY_NOTE`. Without a topic name:
    the only image topic (an error if there are several). An image whose frame_id differs from that
    camera_info's gets none, and the reason. `start`: the first frame the caller takes (the frames before it are
    still given, for their camera_info; of video packets only those from the keyframe it needs are decoded)."""
    reader = _open_reader(path)
    with contextlib.ExitStack() as stack:
        stack.callback(reader.close)
        images = _image_connections(reader, path, image_topic)
        infos, unpaired = _info_connections(reader, path, images[0].topic)
        metadata = [c for c in reader.connections if infos and c.topic == f"{infos[0].topic}/metadata"
                    and c.msgtype == "std_msgs/msg/String"][:1]
        camera_info = camera_metadata = None
        early: list[tuple[int, object]] = []  # (timestamp, image) of frames recorded before any camera_info
        video = None
        if images[0].msgtype in DECODED_VIDEO_TYPES:
            video = _video_frames(path, images[0].topic, stack.enter_context(
                tempfile.TemporaryDirectory(prefix="veg-area-video-")), start)
            stack.callback(video.close)  # before its folder is removed
        index = 0

        def paired(timestamp: int, image: ImageFields | CompressedImageFields | DecodedVideoFrame,
                   info: CameraInfoFields | None, note: str = "") -> BagFrame:
            problem = unpaired
            if info is not None and image.header.frame_id and info.header.frame_id and (
                    image.header.frame_id != info.header.frame_id):
                info, problem, note = None, (f"the camera_info on {infos[0].topic} is frame "
                                             f"{info.header.frame_id!r}, the image on {images[0].topic} frame "
                                             f"{image.header.frame_id!r}: another camera's calibration"), ""
            return BagFrame(index, timestamp, image, info, problem, camera_metadata if info is not None else None,
                            note)

        for connection, timestamp, data in reader.messages(connections=images + infos[:1] + metadata):
            if connection.msgtype == "sensor_msgs/msg/CameraInfo":
                camera_info = decode_camera_info(data)
                for held_timestamp, held in early:  # its own camera_info (the same stamp) or the next one
                    same = held.header.nanoseconds == camera_info.header.nanoseconds
                    yield paired(held_timestamp, held, camera_info, "" if same else EARLY_NOTE)
                    index += 1
                early = []
                continue
            if connection.msgtype == "std_msgs/msg/String":
                with contextlib.suppress(ImageMessageError):  # undecodable: as if not recorded
                    camera_metadata = decode_string(data)
                continue
            image = next(video) if video is not None else _decode_image(connection.msgtype, data)
            if camera_info is None and infos and len(early) < EARLY_FRAMES:
                early.append((timestamp, image))
                continue
            for held_timestamp, held in [*early, (timestamp, image)]:
                yield paired(held_timestamp, held, camera_info)
                index += 1
            early = []
        for held_timestamp, held in early:  # no camera_info came after them either
            yield paired(held_timestamp, held, None)
            index += 1


@dataclass(frozen=True)
class PlayTopic:
    name: str
    msgtype: str
    offered: list[OfferedQos]  # as recorded; empty when the bag does not say

    def replay_qos(self) -> OfferedQos:
        """The QoS to offer on replay, as `ros2 bag play` adapts it: latched if every recorded publisher was,
        best effort if any was, else reliable volatile (depth 10). A bag that does not say (written by other
        tools) gets what ROS offers for the type: sensor data (best effort, depth 5) for sensor_msgs, as camera
        drivers publish images and camera_info, else ROS's default (reliable, volatile, depth 10)."""
        if not self.offered:
            return (OfferedQos("best_effort", "volatile", "keep_last", 5) if self.msgtype.startswith("sensor_msgs/")
                    else OfferedQos())
        return OfferedQos("best_effort" if any(q.reliability == "best_effort" for q in self.offered) else "reliable",
                          "transient_local" if all(q.durability == "transient_local" for q in self.offered)
                          else "volatile", "keep_last", max(q.depth for q in self.offered))


def play_topics(path: str | Path, names: list[str] | None = None) -> list[PlayTopic]:
    """The bag's topics (all, or those named) with their type and recorded offered QoS."""
    reader = _open_reader(path)
    try:
        topics = {}
        present = sorted({connection.topic for connection in reader.connections})
        for connection in reader.connections:
            if names and connection.topic not in names and connection.topic.lstrip("/") not in names:
                continue
            if isinstance(connection.ext, ConnectionExtRosbag1):  # a ROS 1 bag's: TCP, latched or not
                offered = [OfferedQos("reliable", "transient_local", "keep_last", 1)] if connection.ext.latching else []
                topics[connection.topic] = PlayTopic(connection.topic, connection.msgtype, offered)
                continue
            try:
                profiles = connection.ext.offered_qos_profiles
            except AttributeError as exc:  # rosbags' connection record without the field rosbag2 writes
                raise BagError(f"{path}: the offered QoS of {connection.topic} cannot be read ({exc})") from exc
            offered = [OfferedQos(q.reliability.name.lower(), q.durability.name.lower(), q.history.name.lower(),
                                  int(q.depth)) for q in profiles]
            topics[connection.topic] = PlayTopic(connection.topic, connection.msgtype, offered)
    finally:
        reader.close()
    missing = [n for n in names or [] if n not in topics and f"/{n.lstrip('/')}" not in topics]
    if missing:
        raise BagError(f"{path}: no topic {', '.join(missing)} in the bag (it has {', '.join(present)})")
    return list(topics.values())


def play_messages(path: str | Path, topics: list[str]) -> Iterator[tuple[str, int, bytes]]:
    """(topic, recorded time in ns, serialized message) of the named topics in recording order."""
    reader = _open_reader(path)
    try:
        wanted = [c for c in reader.connections if c.topic in topics]
        for connection, timestamp, data in reader.messages(connections=wanted) if wanted else ():
            yield connection.topic, timestamp, bytes(data)
    finally:
        reader.close()


def bag_run(path: str | Path, force_axis: str = "+x", velocity_axis: str = "+x", force_topic: str = "/force",
            velocity_topic: str = "/velocity", area_topic: str = "/projected_area") -> dict:
    """One flume run recorded in a bag: the means of the force along its axis (geometry_msgs/WrenchStamped),
    the velocity (TwistStamped, linear) and Af (projected_area: veg_area_msgs/ProjectedArea, or the Vector3Stamped
    of earlier recordings, x = Af and y = its std), with their sample counts."""
    from .drag import DragError, check_axis, component

    try:
        check_axis(force_axis)
        check_axis(velocity_axis)
    except DragError as exc:
        raise BagError(str(exc)) from exc
    wanted = {"/" + t.lstrip("/"): name for t, name in ((force_topic, "force"), (velocity_topic, "velocity"),
                                                         (area_topic, "area"))}
    reader = _open_reader(path)
    store = typestore(reader)
    samples: dict[str, list[float]] = {"force": [], "velocity": [], "area": []}
    area_std: list[float] = []  # each Af's reported std (y)
    try:
        present = sorted({c.topic for c in reader.connections})
        connections = [c for c in reader.connections if c.topic in wanted]
        for connection, _, data in reader.messages(connections=connections) if connections else ():
            message = store.deserialize_cdr(data, connection.msgtype)
            name = wanted[connection.topic]
            if name == "force":
                samples[name].append(component(message.wrench.force, force_axis))
            elif name == "velocity":
                samples[name].append(component(message.twist.linear, velocity_axis))
            elif hasattr(message, "area_m2"):
                samples[name].append(message.area_m2)
                area_std.append(message.area_std_m2)
            else:
                samples[name].append(message.vector.x)
                area_std.append(message.vector.y)
    except (AttributeError, KeyError) as exc:
        raise BagError(f"{path}: a topic has another message type than expected ({exc})") from exc
    finally:
        reader.close()
    missing = [topic for topic, name in wanted.items() if not samples[name]]
    if missing:
        raise BagError(f"{path}: no messages on {', '.join(missing)} (topics in the bag: {present})")

    def error_of_mean(values: list[float]) -> float:  # the instrument's noise over the run, averaged away
        return statistics.stdev(values) / len(values) ** 0.5 if len(values) > 1 else 0.0

    # Af's std: the frames' reported std, not averaged down (its scale term is common to every frame)
    return {"run": str(path), "velocity_m_s": statistics.fmean(samples["velocity"]),
            "velocity_std_m_s": error_of_mean(samples["velocity"]),
            "force_n": statistics.fmean(samples["force"]), "force_std_n": error_of_mean(samples["force"]),
            "area_m2": statistics.fmean(samples["area"]), "area_std_m2": statistics.fmean(area_std),
            "samples": {name: len(values) for name, values in samples.items()}}


def bag_first_stamp(path: str | Path, image_topic: str | None = None) -> float | None:
    """The header stamp (s) of the bag's first image on its image topic: where its run starts; None if it has
    no image."""
    reader = _open_reader(path)
    try:
        images = _image_connections(reader, path, image_topic)
        for connection, _, data in reader.messages(connections=images):
            return _decode_image(connection.msgtype, data).header.seconds
        return None
    finally:
        reader.close()
