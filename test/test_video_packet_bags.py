"""Bags of inter-frame video packets, as Foxglove's CompressedVideo transport and ffmpeg_image_transport record a
camera: decoded in order, each frame paired with its own message (B-frames, a recording begun between keyframes,
an H.265 stream begun at an open GOP's keyframe), and measured as a video's frames are."""

from __future__ import annotations

import json
import struct
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from helpers import TEST_DATA, run_cli
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from veg_area_ros.bags import iter_bag_frames
from veg_area_ros.cdr import Header
from veg_area_ros.video_packets import (
    CONCEALED_NOTE,
    FFMPEG_PACKET,
    FOXGLOVE_VIDEO,
    VideoPacket,
    VideoPacketStream,
    _nal_types,
    codec_name,
    decode_video_packet,
    is_keyframe,
    ivf_packets,
)

PACKETS = TEST_DATA / "video-packets"
# the two messages as their packages define them (foxglove_msgs, ffmpeg_image_transport_msgs)
DEFINITIONS = {
    FOXGLOVE_VIDEO: "builtin_interfaces/Time timestamp\nstring frame_id\nuint8[] data\nstring format\n",
    FFMPEG_PACKET: ("std_msgs/Header header\nint32 width\nint32 height\nstring encoding\nuint64 pts\nuint8 flags\n"
                    "bool is_bigendian\nuint8[] data\n"),
}
STORE = get_typestore(Stores.ROS2_KILTED)
for _name, _text in DEFINITIONS.items():
    STORE.register(get_types_from_msg(_text, _name))
START_S = 1000


def stored_packets(name: str) -> list[tuple[int, bytes]]:
    """(capture number, bytes) of a stream written by `video-packets/make_packets.py`, in decode order."""
    data, packets, offset = (PACKETS / name).read_bytes(), [], 0
    while offset < len(data):
        number, length = struct.unpack_from("<II", data, offset)
        packets.append((number, data[offset + 8:offset + 8 + length]))
        offset += 8 + length
    return packets


def captured(frame: np.ndarray) -> int:
    """Which capture a decoded bar frame is: its bar covers x = 10 + 8 * number to 8 pixels on."""
    bright = np.flatnonzero(frame[60, :, 1] > 145)
    return round(float(bright.mean() - 13.5) / 8) if bright.size else -1  # -1: no bar (a concealed frame)


def stamp(number: int) -> tuple[int, int]:
    """A 10 Hz camera's stamp of capture `number`."""
    return START_S + number // 10, (number % 10) * 100_000_000


def foxglove(number: int, data: bytes, video_format: str, frame_id: str = "camera"):
    sec, nanosec = stamp(number)
    return STORE.types[FOXGLOVE_VIDEO](
        timestamp=STORE.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame_id,
        data=np.frombuffer(data, np.uint8), format=video_format)


def ffmpeg(number: int, data: bytes, encoding: str, key: bool, frame_id: str = "camera"):
    sec, nanosec = stamp(number)
    header = STORE.types["std_msgs/msg/Header"](stamp=STORE.types["builtin_interfaces/msg/Time"](
        sec=sec, nanosec=nanosec), frame_id=frame_id)
    return STORE.types[FFMPEG_PACKET](header=header, width=160, height=120, encoding=encoding, pts=number,
                                      flags=int(key), is_bigendian=False, data=np.frombuffer(data, np.uint8))


def write_video_bag(path: Path, topic: str, msgtype: str, messages: list, extra: list = (),
                    storage: StoragePlugin = StoragePlugin.SQLITE3) -> None:
    """A bag as `ros2 bag record` writes it: the packets received in decode order, 1 ms apart."""
    with Writer(path, version=Writer.VERSION_LATEST, storage_plugin=storage) as writer:
        video = writer.add_connection(topic, msgtype, typestore=STORE)
        others = [(writer.add_connection(t, m, typestore=STORE), m, ms) for t, m, ms in extra]
        for k, message in enumerate(messages):
            for connection, other_type, other_messages in others:
                if k < len(other_messages):
                    writer.write(connection, (START_S + k) * 10**9, STORE.serialize_cdr(other_messages[k], other_type))
            writer.write(video, (START_S + k) * 10**9 + 1_000_000, STORE.serialize_cdr(message, msgtype))


def test_codec_names_from_foxglove_formats_and_ffmpeg_encodings():
    assert [codec_name(t) for t in ("h264", "h265", "vp9", "av1", "hevc;yuv420p;bgr8;bgr8", "libx264",
                                    "h264_nvenc", "hevc_vaapi", "libx265", "libvpx-vp9", "mjpeg")] == [
        "h264", "hevc", "vp9", "av1", "hevc", "h264", "h264", "hevc", "hevc", "vp9", "mjpeg"]


def test_the_packets_fields_read_as_rosbags_serializes_them():
    """The hand-read CDR of both messages against rosbags' own serializer."""
    number, data = stored_packets("h264_no_b.bin")[0]
    packet = decode_video_packet(FOXGLOVE_VIDEO, STORE.serialize_cdr(foxglove(number + 3, data, "h264", "left"),
                                                                     FOXGLOVE_VIDEO))
    assert (packet.header.sec, packet.header.nanosec, packet.header.frame_id) == (*stamp(3), "left")
    assert packet.codec == "h264" and bytes(packet.data) == data and packet.keyframe_flag is None
    packet = decode_video_packet(FFMPEG_PACKET, STORE.serialize_cdr(ffmpeg(5, data, "h264;yuv420p;bgr8;bgr8",
                                                                           True, "right"), FFMPEG_PACKET))
    assert (packet.header.sec, packet.header.nanosec, packet.header.frame_id) == (*stamp(5), "right")
    assert packet.codec == "h264" and bytes(packet.data) == data and packet.keyframe_flag is True


def camera_packet(number: int, data: bytes, codec: str, stamped: bool = True) -> VideoPacket:
    """Capture `number`'s packet as the camera stamps it (or stamp 0, a driver that stamps nothing)."""
    return VideoPacket(Header(*stamp(number if stamped else 0), "camera"), codec, memoryview(data))


def decoded(name: str, codec: str, first: int = 0, packets: list[tuple[int, bytes]] | None = None,
            stamped: bool = True) -> list[tuple[int | None, str, str]]:
    """The stream's packets from the `first`-th on, each stamped with its capture time (or all alike), as
    (capture number the decoded frame shows, why it has none, its note), per packet in decode order."""
    with tempfile.TemporaryDirectory() as folder:
        stream = VideoPacketStream(folder, "/camera/image_raw/foxglove")
        for number, data in (stored_packets(name) if packets is None else packets)[first:]:
            stream.add(camera_packet(number, data, codec, stamped))
        return [(None if frame is None else captured(frame), problem, note)
                for frame, problem, note in stream.frames()]


@pytest.mark.parametrize("name, codec", [("h264_no_b.bin", "h264"), ("h264_b.bin", "h264"),
                                         ("h264_open_gop.bin", "h264"), ("hevc_open_gop.bin", "hevc")])
def test_each_packet_gets_the_frame_it_carries_also_with_b_frames(name, codec):
    """With B-frames the decoder gives the frames in capture order, not the packets': each packet's frame is
    the one it carries (they come back with their packets' numbers), and nothing needs saying."""
    numbers = [number for number, _ in stored_packets(name)]
    results = decoded(name, codec)
    assert [shown for shown, _, _ in results] == numbers
    assert all(problem == "" and notes == () for _, problem, notes in results)


@pytest.mark.parametrize("name, codec", [("h264_b.bin", "h264"), ("hevc_open_gop.bin", "hevc")])
def test_frames_are_paired_by_the_decoders_numbers_even_where_the_stamps_say_nothing(name, codec):
    """A camera driver that stamps nothing (every stamp 0): the B-frame stream's frames still each reach the
    packet that carries them, where pairing by the stamps would give them in the packets' order."""
    numbers = [number for number, _ in stored_packets(name)]
    assert numbers != sorted(numbers)
    assert [shown for shown, _, _ in decoded(name, codec, stamped=False)] == numbers


def test_an_h265_keyframe_the_decoder_stops_at_costs_the_frames_up_to_the_next_keyframe():
    """Its open GOP's keyframe damaged, the H.265 decoder stops: the rows up to the next keyframe say why and
    decoding resumes there (its transport stream copied from that packet on), each frame on its own packet."""
    packets = stored_packets("hevc_open_gop.bin")
    twice = packets + [(number + len(packets), data) for number, data in packets]
    damaged = next(k for k, (_, data) in enumerate(packets) if k and is_keyframe(
        VideoPacket(None, "hevc", memoryview(data))))
    twice[damaged] = (twice[damaged][0], twice[damaged][1][:6] + bytes(len(twice[damaged][1]) - 6))
    results = decoded("", "hevc", packets=twice)
    lost = [k for k, (shown, _, _) in enumerate(results) if shown is None]
    assert damaged in lost and all(k < len(packets) for k in lost)
    assert all("decoder stopped at a damaged packet" in results[k][1] for k in lost)
    kept = [k for k in range(len(twice)) if k not in lost]
    assert [results[k][0] for k in kept] == [twice[k][0] % len(packets) for k in kept]
    assert kept[-len(packets):] == list(range(len(packets), len(twice)))


@pytest.mark.parametrize("copies", [1, 4])
def test_an_h265_packet_the_decoder_drops_costs_its_own_rows_not_the_frames_after(copies):
    """A damaged H.265 packet (its slice data zeros): the decoder gives no frame for it, or for those that refer to
    it, and goes on; those rows say so and every other packet keeps its own frame (paired by the stamps' order,
    every later frame moved onto the message before it, and only the last row said that something was off). Four
    copies of the stream: a missing frame is given up once the decoder has given 16 after it, not at the end."""
    packets = [(number + len(stored_packets("hevc_open_gop.bin")) * copy, data) for copy in range(copies)
               for number, data in stored_packets("hevc_open_gop.bin")]
    damaged = 5
    packets[damaged] = (packets[damaged][0], packets[damaged][1][:6] + bytes(len(packets[damaged][1]) - 6))
    with tempfile.TemporaryDirectory() as folder:
        stream = VideoPacketStream(folder, "/camera")
        for number, data in packets:
            stream.add(camera_packet(number, data, "hevc"))
        results, decoded_by = [], []  # the frames the decoder had given when each row came
        for frame, problem, note in stream.frames():
            results.append((None if frame is None else captured(frame), problem, note))
            decoded_by.append(stream.frames_decoded)
    lost = [k for k, (shown, _, _) in enumerate(results) if shown is None]
    assert damaged in lost and len(lost) < 4
    assert all("gave no frame for this packet" in results[k][1] for k in lost)
    assert decoded_by[damaged] <= damaged + 16 + 3  # not held until the end: at most 16 frames after it
    kept = [k for k in range(len(packets)) if k not in lost]
    assert [results[k][0] for k in kept] == [packets[k][0] % 12 for k in kept]


@pytest.mark.parametrize("name", ["h264_no_b.bin", "h264_b.bin"])
def test_a_packet_without_a_picture_costs_its_own_row_alone(name):
    """A packet that holds no picture (here only an access unit delimiter where a frame was) is said so on its
    own row, and not given to OpenCV's decoder (which stops at it). Every other packet keeps its own frame (a
    missing frame shifted every later frame onto the next message without a word); those up to the next
    keyframe may refer to the lost one, and say so."""
    packets = stored_packets(name)
    keyframes = [k for k, (_, data) in enumerate(packets) if is_keyframe(VideoPacket(None, "h264",
                                                                                      memoryview(data)))]
    lost = 4
    resumed = next(key for key in keyframes if key > lost)
    packets[lost] = (packets[lost][0], b"\x00\x00\x00\x01\x09\xf0")
    results = decoded(name, "h264", packets=packets)
    assert results[lost][0] is None and "holds no picture" in results[lost][1]
    assert all(shown is not None for k, (shown, _, _) in enumerate(results) if k != lost)
    assert [CONCEALED_NOTE in notes for _, _, notes in results] == [lost < k < resumed for k in range(len(packets))]
    exact = [k for k in range(len(packets)) if k < lost or k >= resumed]
    assert [results[k][0] for k in exact] == [packets[k][0] for k in exact]
    if name == "h264_b.bin":  # nothing refers to the lost B-frame: the others are their own, not shifted
        assert [shown for k, (shown, _, _) in enumerate(results) if k != lost] == [
            number for k, (number, _) in enumerate(packets) if k != lost]


def test_after_a_lost_packet_the_frames_say_so_up_to_a_closed_keyframe_or_the_second_open_one():
    """x264's open GOPs: after a lost packet the next keyframe, an open GOP's, does not end the doubt (its leading
    pictures may refer to the GOP with the loss); the open keyframe after it does, and so does an IDR."""
    packets = stored_packets("h264_open_gop.bin")
    keyframes = [k for k, (_, data) in enumerate(packets) if is_keyframe(VideoPacket(None, "h264", memoryview(data)))]
    assert len(keyframes) == 3 and all(5 not in _nal_types("h264", packets[k][1]) for k in keyframes[1:])
    lost = list(packets)
    lost[1] = (lost[1][0], b"\x00\x00\x00\x01\x09\xf0")
    notes = [note for _, _, note in decoded("", "h264", packets=lost)]
    assert [CONCEALED_NOTE in said for said in notes] == [1 < k < keyframes[2] for k in range(len(packets))]
    twice = packets + [(number + len(packets), data) for number, data in packets]
    twice[keyframes[2] + 1] = (twice[keyframes[2] + 1][0], b"\x00\x00\x00\x01\x09\xf0")
    notes = [note for _, _, note in decoded("", "h264", packets=twice)]
    assert [CONCEALED_NOTE in said for said in notes] == [keyframes[2] + 1 < k < len(packets)
                                                          for k in range(len(twice))]


@pytest.mark.parametrize("name", ["h264_no_b.bin", "h264_b.bin"])
def test_a_damaged_packet_that_stops_the_decoder_loses_its_frames_up_to_the_next_keyframe_only(name):
    """A packet whose slice data is zeros stops OpenCV's decoder (before, it cost an H.264 stream every frame):
    its rows up to the next keyframe say why, and decoding resumes there, each frame on its own packet."""
    packets = stored_packets(name)
    keyframes = [k for k, (_, data) in enumerate(packets) if is_keyframe(VideoPacket(None, "h264",
                                                                                      memoryview(data)))]
    damaged = 4
    resumed = next(key for key in keyframes if key > damaged)
    packets[damaged] = (packets[damaged][0], packets[damaged][1][:5] + bytes(len(packets[damaged][1]) - 5))
    results = decoded(name, "h264", packets=packets)
    lost = [k for k, (shown, _, _) in enumerate(results) if shown is None]
    assert damaged in lost and all(damaged - 3 <= k < resumed for k in lost)
    assert all("decoder stopped at a damaged packet" in results[k][1] for k in lost)
    assert [results[k][0] for k in range(len(packets)) if k not in lost] == [
        packets[k][0] for k in range(len(packets)) if k not in lost]
    assert results[resumed][0] == packets[resumed][0]


def _scrambled(data: bytes, seed: int = 1) -> bytes:
    """A packet whose second half is noise: its header and first slices intact, so the decoder decodes it, reports
    the error and fills the damaged blocks with guesses (zeros instead stop it: the test above)."""
    rng = np.random.default_rng(seed)
    cut = len(data) // 2
    return data[:cut] + rng.integers(0, 256, len(data) - cut).astype(np.uint8).tobytes()


@pytest.mark.parametrize("name, codec, damaged", [("h264_no_b.bin", "h264", 2), ("h264_no_b.bin", "h264", 5),
                                                  ("h264_b.bin", "h264", 3), ("hevc_open_gop.bin", "hevc", 5)])
def test_damage_the_decoder_conceals_is_said_on_the_frames_that_carry_it_up_to_the_keyframe_that_clears_it(
        name, codec, damaged):
    """A packet damaged inside its slices is decoded with guesses and a frame comes out as if nothing happened
    (before: no row said a word). The decoder's report is now said on the frames from the damaged packet up to
    the keyframe that clears it (a closed one; an open GOP's second), never before the damage nor on a frame the
    decoder had already given; without B-frames exactly there, with them from at most the frames it holds back.
    The same stream undamaged says nothing."""
    packets = stored_packets(name)
    assert all(notes == () for _, _, notes in decoded(name, codec, packets=packets))
    keyframes = [k for k, (_, data) in enumerate(packets) if is_keyframe(VideoPacket(None, codec, memoryview(data)))]
    open_gops = codec == "hevc"
    clears = ([key for key in keyframes if key > damaged][1:2] if open_gops
              else [key for key in keyframes if key > damaged][:1]) or [len(packets)]
    packets[damaged] = (packets[damaged][0], _scrambled(packets[damaged][1]))
    results = decoded(name, codec, packets=packets)
    said = [k for k, (shown, _, notes) in enumerate(results)
            if any(note.startswith("video damaged: the decoder reported an error") for note in notes)]
    assert said and said == [k for k in range(said[0], clears[0]) if results[k][0] is not None], (said, clears)
    assert damaged in said or results[damaged][0] is None
    reorder = 0 if name == "h264_no_b.bin" else 2
    assert damaged - reorder <= said[0] <= damaged, said
    note = next(note for note in results[said[0]][2] if note.startswith("video damaged"))
    assert f"({codec}: " in note and "look at the overlay" in note


@pytest.mark.parametrize("name, codec", [("h264_b.bin", "h264"), ("h264_open_gop.bin", "h264"),
                                         ("hevc_open_gop.bin", "hevc")])
def test_a_long_stream_is_decoded_as_it_is_read_in_chunks_begun_at_keyframes_with_the_same_frames(monkeypatch, name,
                                                                                                   codec):
    """The stream files hold CHUNK_PACKETS packets at least, each begun at a keyframe (an open GOP's given the GOP
    before it first, for its leading pictures), and a chunk's frames are given (`ready`) as soon as the next chunk
    begins, its file then removed: made small here, a long recording's rows come while it is read, with never
    more than two chunks on disk, and the same frames as one file gives."""
    import veg_area_ros.video_packets as video_packets

    packets = stored_packets(name)
    four = packets * 4
    whole = decoded("", codec, packets=four)
    keyframes = [k for k, (_, data) in enumerate(four) if is_keyframe(VideoPacket(None, codec, memoryview(data)))]
    monkeypatch.setattr(video_packets, "CHUNK_PACKETS", 1)  # a chunk at every keyframe
    with tempfile.TemporaryDirectory() as folder:
        stream = VideoPacketStream(folder, "/camera")
        results, ready_at, files = [], [], []
        for k, (number, data) in enumerate(four):
            stream.add(camera_packet(number, data, codec))
            files.append(len(list(Path(folder).glob("stream-*"))))
            taken = [(captured(frame), problem, note) for frame, problem, note in stream.ready()]
            ready_at += [k] * len(taken)
            results += taken
        results += [(captured(frame), problem, note) for frame, problem, note in stream.frames()]
        assert not list(Path(folder).glob("stream-*"))
    assert results == whole and [shown for shown, _, _ in whole] == [number for number, _ in packets] * 4
    assert max(files) == 2
    assert ready_at == [min(key for key in keyframes if key > k) for k in range(keyframes[-1])]


def test_a_recording_begun_between_keyframes_decodes_from_the_next_keyframe():
    """`ros2 bag record` started while the camera streamed: the packets before the first keyframe cannot be
    decoded (they were silently dropped by the decoder, shifting every later frame onto the wrong message)."""
    packets = stored_packets("h264_b.bin")
    keyframe = next(k for k, (_, data) in enumerate(packets) if k and is_keyframe(
        VideoPacket(None, "h264", memoryview(data))))
    results = decoded("h264_b.bin", "h264", first=2)
    assert all(shown is None and "before the stream's first keyframe" in problem
               for shown, problem, _ in results[:keyframe - 2])
    assert [shown for shown, _, _ in results[keyframe - 2:]] == [number for number, _ in packets[keyframe:]]


def test_an_h264_stream_begun_between_keyframes_of_open_gops_decodes_from_the_recovery_point():
    """x264's open GOPs: the keyframes after the first are I-frames with a recovery point, not IDRs (each was
    taken for an inter-frame, and a recording begun between them decoded nothing). Begun there, the frames from the
    recovery point on are each on their own packet; its leading B-frames refer to the frames before it and say so."""
    packets = stored_packets("h264_open_gop.bin")
    keyframes = [k for k, (_, data) in enumerate(packets) if is_keyframe(VideoPacket(None, "h264",
                                                                                      memoryview(data)))]
    assert len(keyframes) == 3 and 5 not in _nal_types("h264", packets[keyframes[1]][1])  # not an IDR
    recovery = keyframes[1]
    results = decoded("h264_open_gop.bin", "h264", first=2)
    for k, (shown, problem, _) in enumerate(results, start=2):
        if k < recovery:
            assert shown is None and "before the stream's first keyframe" in problem
        elif packets[k][0] < packets[recovery][0]:
            assert shown is None and "leading picture of the open GOP's keyframe" in problem
        else:
            assert shown == packets[k][0] and problem == ""
    assert sum(shown is not None for shown, _, _ in results) == len(packets) - packets[recovery][0]


def test_an_h265_stream_begun_at_an_open_gops_keyframe_skips_its_leading_pictures():
    """An H.265 CRA keyframe's leading (RASL) pictures refer to frames before it: begun there, the decoder drops
    them, and they are said so, the frames after them still each on its own packet."""
    packets = stored_packets("hevc_open_gop.bin")
    cra = next(k for k, (_, data) in enumerate(packets) if k and is_keyframe(
        VideoPacket(None, "hevc", memoryview(data))))
    results = decoded("hevc_open_gop.bin", "hevc", first=cra)
    leading = [k for k, (number, _) in enumerate(packets[cra:]) if number < packets[cra][0]]
    assert leading, "the stored stream has leading pictures after its CRA"
    for k, (shown, problem, _) in enumerate(results):
        if k in leading:
            assert shown is None and "leading picture" in problem
        else:
            assert shown == packets[cra + k][0] and problem == ""


def test_a_stream_that_cannot_be_decoded_says_why():
    data = stored_packets("h264_no_b.bin")[0][1]
    with tempfile.TemporaryDirectory() as folder:
        stream = VideoPacketStream(folder, "/cam/foxglove")
        stream.add(VideoPacket(Header(1, 0, ""), "m/jpeg", memoryview(data)))
        stream.add(VideoPacket(Header(2, 0, ""), "h264", memoryview(data)))
        problems = [problem for _, problem, _ in stream.frames()]
    assert "'m/jpeg' is not one read here" in problems[0] and "its codec is h264" in problems[1]
    with tempfile.TemporaryDirectory() as folder:
        stream = VideoPacketStream(folder, "/cam/foxglove")
        stream.add(VideoPacket(Header(1, 0, ""), "h264", memoryview(struct.pack(">I", len(data)) + data[4:])))
        assert "not in Annex B form" in next(stream.frames())[1]
    with tempfile.TemporaryDirectory() as folder:  # a keyframe the decoder cannot read: no frame at all
        stream = VideoPacketStream(folder, "/cam/foxglove")
        stream.add(VideoPacket(Header(1, 0, ""), "h264", memoryview(b"\x00\x00\x01\x65" + bytes(64))))
        assert "decoded no frame of this h264 stream" in next(stream.frames())[1]


def test_an_ffmpeg_image_transport_bag_is_read_in_capture_order_with_its_camera_info():
    """FFMPEGPacket (its flags say the keyframes) with B-frames: every frame paired with its own stamp (by the
    decoder's own numbers: no frame needs a note on its pairing), the camera_info recorded beside it."""
    from veg_area_ros.frames import iter_bag

    packets = stored_packets("h264_b.bin")
    info = STORE.types["sensor_msgs/msg/CameraInfo"](
        header=STORE.types["std_msgs/msg/Header"](stamp=STORE.types["builtin_interfaces/msg/Time"](
            sec=START_S, nanosec=0), frame_id="camera"), height=120, width=160, distortion_model="plumb_bob",
        d=np.zeros(5), k=np.array([150.0, 0, 80, 0, 150, 60, 0, 0, 1]), r=np.eye(3).ravel(),
        p=np.array([150.0, 0, 80, 0, 0, 150, 60, 0, 0, 0, 1, 0]), binning_x=0, binning_y=0,
        roi=STORE.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                            do_rectify=False))
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / "ffmpeg"
        write_video_bag(bag, "/camera/image_raw/ffmpeg", FFMPEG_PACKET,
                        [ffmpeg(number, data, "libx264", is_keyframe(VideoPacket(None, "h264", memoryview(data))))
                         for number, data in packets], extra=[("/camera/camera_info", "sensor_msgs/msg/CameraInfo",
                                                               [info])])
        frames = list(iter_bag(bag))
        assert len(list(iter_bag_frames(bag))) == len(packets)
    assert [captured(f.image) for f in frames] == [number for number, _ in packets]
    assert [f.time_s for f in frames] == [pytest.approx(s + ns / 1e9) for s, ns in (stamp(n) for n, _ in packets)]
    assert all(f.camera_info is not None for f in frames)
    assert not any("reorders its frames (B-frames)" in note for f in frames for note in f.notes)


def test_a_bags_concealed_damage_reaches_the_frames_notes(tmp_path):
    """Read from a bag (`iter_bag`, what `veg-area measure` reads), a damaged packet's concealed frames carry the
    decoder's report in their notes (the rows' warnings), the frames before it and after the keyframe do not."""
    from veg_area_ros.frames import iter_bag

    packets = stored_packets("h264_no_b.bin")
    damaged = 2
    packets[damaged] = (packets[damaged][0], _scrambled(packets[damaged][1]))
    write_video_bag(tmp_path / "bag", "/camera/image_raw/foxglove", FOXGLOVE_VIDEO,
                    [foxglove(number, data, "h264") for number, data in packets])
    frames = list(iter_bag(tmp_path / "bag"))
    assert len(frames) == len(packets) and all(f.image is not None for f in frames)
    keyframes = [k for k, (_, data) in enumerate(packets) if is_keyframe(VideoPacket(None, "h264", memoryview(data)))]
    clears = next(key for key in keyframes if key > damaged)
    assert [any(note.startswith("video damaged") for note in f.notes) for f in frames] == [
        damaged <= k < clears for k in range(len(packets))]


def test_a_foxglove_vp9_bag_is_measured_as_the_same_video_file(tmp_path):
    """A camera recorded through Foxglove's CompressedVideo transport (VP9, encoded here by OpenCV's FFmpeg):
    `veg-area measure` finds the topic, measures every frame with the camera_info
    recorded beside it, and each frame's Af is the Af of the same frame decoded from the video file."""
    from veg_area_ros.camera_info import camera_info_fields
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content

    frames = [render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=k) for k in range(4)]
    video = tmp_path / "cube.ivf"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"VP90"), 10, (640, 480))
    assert writer.isOpened(), "OpenCV's FFmpeg writes VP9"
    for frame in frames:
        writer.write(frame)
    writer.release()
    packets = ivf_packets(video.read_bytes())
    assert len(packets) == len(frames)
    fields = camera_info_fields(ENDOSCOPE)
    info = STORE.types["sensor_msgs/msg/CameraInfo"](
        header=STORE.types["std_msgs/msg/Header"](stamp=STORE.types["builtin_interfaces/msg/Time"](
            sec=START_S, nanosec=0), frame_id="camera"), height=480, width=640,
        distortion_model=fields["distortion_model"], d=np.array(fields["d"], float), k=np.array(fields["k"], float),
        r=np.array(fields["r"], float), p=np.array(fields["p"], float), binning_x=0, binning_y=0,
        roi=STORE.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                            do_rectify=False))
    bag = tmp_path / "foxglove_bag"
    write_video_bag(bag, "/camera/image_raw/foxglove", FOXGLOVE_VIDEO,
                    [foxglove(k, data, "vp9") for k, data in enumerate(packets)],
                    extra=[("/camera/camera_info", "sensor_msgs/msg/CameraInfo", [info])])
    capture = cv2.VideoCapture(str(video), cv2.CAP_FFMPEG)
    folder = tmp_path / "decoded"
    folder.mkdir()
    for k in range(len(frames)):
        ok, frame = capture.read()
        assert ok
        cv2.imwrite(str(folder / f"frame{k}.png"), frame)
    capture.release()
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    from veg_area_ros.calib_io import write_calibration

    write_calibration(tmp_path / "camera.yaml", ENDOSCOPE, "camera", {"medium": "air"})
    results = {}
    for name, source, calibration in [("bag", bag, "bag"), ("files", folder, str(tmp_path / "camera.yaml"))]:
        done = run_cli("measure", str(source), "--targets", str(tmp_path / "targets.yaml"), "--threshold", "120",
                       "--calibration", calibration, "--json", "--csv", str(tmp_path / f"{name}.csv"), cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        results[name] = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert [r["area_m2"] for r in results["bag"]] == [r["area_m2"] for r in results["files"]]
    assert len(results["bag"]) == len(frames)
    assert [r["time_s"] for r in results["bag"]] == [pytest.approx(START_S + k / 10) for k in range(len(frames))]
    assert abs(results["bag"][0]["area_m2"] / cube_scene().true_area_m2 - 1) < 0.01


def test_an_av1_stream_is_decoded_where_opencv_can_and_else_each_row_says_why():
    """AV1 (Foxglove's fourth format): its keyframes are those with a sequence header; OpenCV's pip wheel has no
    AV1 decoder, so each packet's row says that, where a build that has one gives each packet its frame."""
    packets = stored_packets("av1.bin")
    keyframes = [k for k, (_, data) in enumerate(packets) if is_keyframe(VideoPacket(None, "av1", memoryview(data)))]
    assert keyframes == [0, 6]  # written with a keyframe every 6 frames
    results = decoded("av1.bin", "av1")
    if results[0][0] is None:
        assert all(shown is None and "decoded no frame of this av1 stream" in problem for shown, problem, _ in results)
    else:
        assert [shown for shown, _, _ in results] == [number for number, _ in packets]


def test_of_one_cameras_transports_the_video_packets_come_last(tmp_path):
    """`ros2 bag record -a` beside a camera that publishes image_raw/compressed and image_raw/foxglove: the JPEG
    frames are read (each frame on its own), the video topic named as recorded and not read; named, it is read."""
    from veg_area_ros.bags import bag_images

    packets = stored_packets("h264_no_b.bin")
    compressed = [STORE.types["sensor_msgs/msg/CompressedImage"](
        header=STORE.types["std_msgs/msg/Header"](stamp=STORE.types["builtin_interfaces/msg/Time"](
            sec=stamp(n)[0], nanosec=stamp(n)[1]), frame_id="camera"), format="jpeg",
        data=np.frombuffer(cv2.imencode(".jpg", np.full((120, 160), 90, np.uint8))[1].tobytes(), np.uint8))
        for n, _ in packets]
    bag = tmp_path / "all"
    write_video_bag(bag, "/camera/image_raw/foxglove", FOXGLOVE_VIDEO, [foxglove(n, d, "h264") for n, d in packets],
                    extra=[("/camera/image_raw/compressed", "sensor_msgs/msg/CompressedImage", compressed)])
    assert bag_images(bag) == ("/camera/image_raw/compressed", len(packets), ["/camera/image_raw/foxglove"])
    named = list(iter_bag_frames(bag, "/camera/image_raw/foxglove"))
    assert [captured(f.image.pixels()) for f in named] == [n for n, _ in packets]


@pytest.mark.parametrize("name, codec, storage", [("h264_b.bin", "h264", StoragePlugin.SQLITE3),
                                                  ("h264_open_gop.bin", "h264", StoragePlugin.MCAP),
                                                  ("hevc_open_gop.bin", "hevc", StoragePlugin.MCAP)])
def test_a_segment_of_a_video_bag_decodes_from_the_keyframes_it_needs_and_gives_the_same_frames(tmp_path, name,
                                                                                                  codec, storage):
    """`--jobs` and a cluster measure a long bag in segments: each decoded the whole recording before its own
    frames (quadratic in the bag's length). From each possible first frame, the frames from there on are the
    whole decode's, and only the two keyframes' packets before it are decoded (an open GOP's leading pictures
    refer to the one before)."""
    packets = stored_packets(name)
    twice = packets + [(number + len(packets), data) for number, data in packets]
    bag = tmp_path / "twice"
    write_video_bag(bag, "/camera/image_raw/foxglove", FOXGLOVE_VIDEO, [foxglove(n, d, codec) for n, d in twice],
                    storage=storage)
    whole = [f.image.pixels() for f in iter_bag_frames(bag)]
    keyframes = [k for k, (_, data) in enumerate(twice) if is_keyframe(VideoPacket(None, codec, memoryview(data)))]
    for start in range(len(twice)):
        frames = list(iter_bag_frames(bag, start=start))
        assert len(frames) == len(twice)
        for k in range(start, len(twice)):
            assert np.array_equal(frames[k].image.pixels(), whole[k]), (start, k)
        before = [key for key in keyframes if key <= start]
        first_decoded = before[-2] if len(before) >= 2 else 0
        assert all("before the frames asked for" in frames[k].image.problem for k in range(first_decoded)), start
