"""Reading a bag of video packets against decoding the same video file: a camera recorded through Foxglove's
CompressedVideo transport (VP9, 640x480, the cube with 3 DN of fresh noise each frame, as OpenCV's FFmpeg
encodes it; encoding is most of the bench's time), its frames taken with `bags.iter_bag_frames` (packets read
from the bag, written into numbered stream files, decoded, paired with their messages) beside OpenCV decoding
the same IVF file in the same run, in both storages; and the file decoded with one thread, as the bag's packets
are (FFmpeg's words about a damaged packet are then printed while that packet is decoded: `decoder_messages`).
Also the most the frames' temporary folder held while the bag was read, against the topic's packets: the stream
files are removed a chunk at a time.

    .venv/bin/python bench/video_bag_speed.py [--frames 600] [--runs 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "veg_area_ros"))

from rosbags.rosbag2 import Writer  # noqa: E402
from rosbags.rosbag2.enums import StoragePlugin  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from veg_area_ros.bags import iter_bag_frames  # noqa: E402
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene  # noqa: E402
from veg_area_ros.video_damage import one_thread_capture  # noqa: E402
from veg_area_ros.video_packets import FOXGLOVE_VIDEO, VideoPacket, is_keyframe, ivf_packets  # noqa: E402

STORE = get_typestore(Stores.ROS2_KILTED)
STORE.register(get_types_from_msg("builtin_interfaces/Time timestamp\nstring frame_id\nuint8[] data\nstring format\n",
                                  FOXGLOVE_VIDEO))


def write_video(path: Path, frames: int) -> None:
    clean = render_scene(ENDOSCOPE, cube_scene(), 0.7, noise_sigma=0.0).astype(float)
    rng = np.random.default_rng(3)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"VP90"), 30, (640, 480))
    if not writer.isOpened():
        raise SystemExit("OpenCV's FFmpeg here writes no VP9")
    for _ in range(frames):
        writer.write(np.clip(clean + rng.normal(0.0, 3.0, clean.shape), 0, 255).astype(np.uint8))
    writer.release()


def write_bag(path: Path, packets: list[bytes], storage: StoragePlugin) -> None:
    time_type = STORE.types["builtin_interfaces/msg/Time"]
    with Writer(path, version=Writer.VERSION_LATEST, storage_plugin=storage) as writer:
        connection = writer.add_connection("/camera/image_raw/foxglove", FOXGLOVE_VIDEO, typestore=STORE)
        for k, data in enumerate(packets):
            stamp_ns = 10**12 + k * 33_333_333
            message = STORE.types[FOXGLOVE_VIDEO](timestamp=time_type(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                                                  frame_id="camera", data=np.frombuffer(data, np.uint8), format="vp9")
            writer.write(connection, stamp_ns + 1_000_000, STORE.serialize_cdr(message, FOXGLOVE_VIDEO))


def decode_file(path: Path, one_thread: bool = False) -> int:
    capture = (one_thread_capture(str(path), cv2.CAP_FFMPEG) if one_thread
               else cv2.VideoCapture(str(path), cv2.CAP_FFMPEG))
    count = 0
    while capture.read()[0]:
        count += 1
    capture.release()
    return count


def read_bag(bag: Path) -> int:
    """Frames read."""
    count = 0
    for frame in iter_bag_frames(bag):
        frame.image.pixels()
        count += 1
    return count


def most_held(bag: Path, scratch: Path) -> int:
    """The most bytes the frames' temporary folder held after any frame (a pass of its own: looking at the
    folder after every frame is not part of reading the bag, and is not timed)."""
    most = 0
    for frame in iter_bag_frames(bag):
        frame.image.pixels()
        most = max(most, sum(f.stat().st_size for folder in scratch.glob("veg-area-video-*")
                             for f in folder.iterdir()))
    return most


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=600)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        video = root / "cube.ivf"
        write_video(video, args.frames)
        packets = ivf_packets(video.read_bytes())
        topic_bytes = sum(len(p) for p in packets)
        scratch = root / "tmp"
        scratch.mkdir()
        os.environ["TMPDIR"] = str(scratch)
        tempfile.tempdir = None  # read TMPDIR again
        keyframes = sum(is_keyframe(VideoPacket(None, "vp9", memoryview(p))) for p in packets)
        print(f"{len(packets)} VP9 packets ({keyframes} keyframes), 640x480, {topic_bytes / 1e6:.1f} MB; each figure "
              f"the median of {args.runs} runs")
        print(f"{'storage':>8} {'file decode s':>14} {'1 thread s':>11} {'bag read s':>11} {'ratio':>6} "
              f"{'to 1 thread':>12}  {'most TMPDIR held':>17}")
        for storage in (StoragePlugin.MCAP, StoragePlugin.SQLITE3):
            bag = root / f"bag_{storage.name.lower()}"
            write_bag(bag, packets, storage)
            file_s, single_s, bag_s = [], [], []
            for _ in range(args.runs):
                started = time.perf_counter()
                decoded = decode_file(video)
                file_s.append(time.perf_counter() - started)
                started = time.perf_counter()
                decode_file(video, one_thread=True)
                single_s.append(time.perf_counter() - started)
                started = time.perf_counter()
                count = read_bag(bag)
                bag_s.append(time.perf_counter() - started)
                if count != decoded or count != len(packets):
                    raise SystemExit(f"{storage.name}: {count} frames from the bag, {decoded} from the file")
            most = most_held(bag, scratch)
            file_median, bag_median = statistics.median(file_s), statistics.median(bag_s)
            single_median = statistics.median(single_s)
            print(f"{storage.name.lower():>8} {file_median:14.2f} {single_median:11.2f} {bag_median:11.2f} "
                  f"{bag_median / file_median:6.2f} {bag_median / single_median:12.2f}  "
                  f"{most / 1e6:8.1f} MB ({100 * most / topic_bytes:.0f} % of the topic)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
