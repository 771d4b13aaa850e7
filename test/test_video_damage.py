"""A damaged inter-frame video (an SD card's bit errors, a file recovered after a battery died): FFmpeg conceals
the damaged blocks with guesses and goes on without an error OpenCV passes up. Every frame whose pixels the
damage changed says so in its row, from the damaged frame up to the next keyframe, and no other frame does (what
the measurement carries from frame to frame, its light levels, can still move later frames' Af by 0.01 %)."""

from __future__ import annotations

import csv
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from helpers import run_cli

from veg_area_ros.calib_io import write_calibration
from veg_area_ros.frames import iter_frames
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content
from veg_area_ros.video_container import Keyframes, boxes, keyframes, movie_header
from veg_area_ros.video_damage import VideoDamage

FRAMES = 40


def _sample_offsets(video: Path) -> list[tuple[int, int]]:
    """(offset, size) of each video sample of an MP4 that OpenCV wrote (one track, one chunk)."""
    moov = movie_header(video)
    stbl = moov
    for name in (b"trak", b"mdia", b"minf", b"stbl"):
        start, end = next((s, e) for kind, s, e in boxes(stbl) if kind == name)
        stbl = stbl[start:end]
    table = {kind: stbl[s:e] for kind, s, e in boxes(stbl)}
    count = struct.unpack_from(">I", table[b"stsz"], 8)[0]
    sizes = struct.unpack_from(f">{count}I", table[b"stsz"], 12)
    chunks, first = struct.unpack_from(">II", table[b"stco"], 4)
    assert chunks == 1
    offsets = first + np.concatenate([[0], np.cumsum(sizes)[:-1]])
    return list(zip(offsets.tolist(), sizes, strict=True))


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    """The cube as an MPEG-4 video (a keyframe every 12 frames), and copies with one P-frame's data and one
    keyframe's data scrambled."""
    folder = tmp_path_factory.mktemp("damage")
    clean = folder / "clean.mp4"
    writer = cv2.VideoWriter(str(clean), cv2.VideoWriter_fourcc(*"mp4v"), 30, ENDOSCOPE.image_size)
    for k in range(FRAMES):
        writer.write(render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=k))
    writer.release()
    keys = keyframes(clean)
    assert keys is not None and keys.frames[:3] == (0, 12, 24) and not keys.reordered
    samples = _sample_offsets(clean)
    rng = np.random.default_rng(3)
    damaged = {}
    for frame in (15, 24):
        data = bytearray(clean.read_bytes())
        offset, size = samples[frame]
        start = offset + size // 3
        data[start:start + size // 3] = rng.integers(0, 256, size // 3, dtype=np.uint8).tobytes()
        damaged[frame] = folder / f"damaged_at_{frame}.mp4"
        damaged[frame].write_bytes(bytes(data))
    write_calibration(folder / "calibration.yaml", ENDOSCOPE)
    (folder / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    return folder, clean, damaged


def _decoded(video: Path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(video))
    frames = []
    while (read := capture.read())[0]:
        frames.append(read[1])
    capture.release()
    return frames


def _rows(folder: Path, video: Path) -> dict[int, dict]:
    csv_path = folder / f"{video.stem}.csv"
    run_cli("measure", str(video), "--calibration", str(folder / "calibration.yaml"), "--targets",
            str(folder / "targets.yaml"), "--threshold", "120", "--csv", str(csv_path), cwd=folder)
    with open(csv_path, newline="") as file:
        return {int(row["frame"].rsplit("#", 1)[1]): row for row in csv.DictReader(file)}


@pytest.mark.parametrize("damaged_frame, runs_to", [(15, 23), (24, 35)])
def test_the_frames_a_damaged_one_reaches_say_so_and_no_other(videos, damaged_frame, runs_to):
    folder, clean, damaged = videos
    before = _rows(folder, clean)
    after = _rows(folder, damaged[damaged_frame])
    assert len(after) == FRAMES and not any("video damaged" in row["warnings"] for row in before.values())
    guessed = {k for k, (a, b) in enumerate(zip(_decoded(clean), _decoded(damaged[damaged_frame]), strict=True))
               if not np.array_equal(a, b)}
    said = {k for k, row in after.items() if "video damaged" in row["warnings"]}
    assert guessed, "the damage must change pixels for this test to show anything"
    assert guessed <= said  # no frame that holds a guessed block is silent
    assert {k for k in guessed if after[k]["area_m2"] != before[k]["area_m2"]}  # and Af moved on some of them
    assert said == set(range(damaged_frame, runs_to + 1))  # from the damaged frame to the next keyframe
    words = after[damaged_frame]["warnings"]
    assert f"error at frame {damaged_frame} (mpeg4: " in words and f"frames {damaged_frame} to {runs_to}" in words


def test_a_segment_that_begins_after_the_damage_in_its_gop_says_it(videos):
    """A split run (`--jobs`, a cluster) seeks to its first frame by decoding from the keyframe before it."""
    _, _, damaged = videos
    frames = list(iter_frames([damaged[15]], frame_range=(18, FRAMES)))
    said = {frame.position: [n for n in frame.notes if n.startswith("video damaged")] for frame in frames}
    assert [k for k, notes in said.items() if notes] == list(range(18, 24))
    assert "error while seeking to frame 18 (mpeg4: " in said[18][0] and "frames 18 to 23" in said[18][0]


def test_damage_reaches_every_later_frame_where_no_keyframe_is_known():
    damage = VideoDamage(None)
    assert damage.note(3, "") == ()
    (note,) = damage.note(4, "[h264 @ 0x55d0c8a1b2c0] error while decoding MB 3 7")
    assert "error at frame 4 (h264: error while decoding MB 3 7)" in note and "every later frame" in note
    assert damage.note(500, "") == (note,)


def test_damage_in_a_reordered_stream_reaches_past_the_keyframe_by_the_reordering():
    damage = VideoDamage(Keyframes((0, 30, 60), reordered=True))
    assert damage.note(10, "[hevc @ 0x1] Could not find ref with POC 7")
    assert damage.note(33, "") and not damage.note(34, "")
    intra_only = VideoDamage(Keyframes(None, reordered=False))
    assert intra_only.note(5, "[mjpeg @ 0x1] overread 8") and not intra_only.note(6, "")
    assert not intra_only.note(9, "[mjpeg @ 0x1] overread 8", seeking=True)  # a frame before 9 alone


def test_a_small_motion_jpeg_videos_corrupt_frame_is_refused_as_a_large_ones(videos):
    """Below 2 MP FFmpeg decodes Motion-JPEG itself; a scrambled scan is refused as the packet path refuses it."""
    folder = videos[0]
    video = folder / "small.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30, ENDOSCOPE.image_size)
    for k in range(12):
        writer.write(render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=k))
    writer.release()
    data = bytearray(video.read_bytes())
    scans = [i for i in range(len(data) - 1) if data[i:i + 2] == b"\xff\xda"]
    start = scans[7] + 3000
    data[start:start + 40] = np.random.default_rng(4).integers(0, 256, 40, dtype=np.uint8).tobytes()
    video.write_bytes(bytes(data))
    csv_path = folder / "small.csv"
    done = run_cli("measure", str(video), "--calibration", str(folder / "calibration.yaml"), "--targets",
                   str(folder / "targets.yaml"), "--threshold", "120", "--csv", str(csv_path), cwd=folder)
    with open(csv_path, newline="") as file:
        rows = {int(row["frame"].rsplit("#", 1)[1]): row for row in csv.DictReader(file)}
    assert done.returncode == 1 and "1 of 12 frames could not be read" in done.stderr
    assert "this frame is corrupt (the decoder reported: mjpeg: " in rows[7]["error"] and not rows[7]["area_m2"]
    assert all(rows[k]["area_m2"] and not rows[k]["error"] for k in rows if k != 7) and len(rows) == 12
    assert not any("video damaged" in row["warnings"] for row in rows.values())
