"""Frame sources of the camera node: end of file, unreadable frames, loops, globs, bad sources."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from veg_area_ros.sim.synthetic import CUBE_SIDE_M
from veg_area_ros.sources import FileSource, SourceError, SyntheticSource, open_source


def test_folder_ends_loops_and_reports_unreadable_frames(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((16, 24, 3), np.uint8))
    (tmp_path / "b.png").write_bytes(b"not an image")
    source = open_source(str(tmp_path))
    assert isinstance(source, FileSource) and source.read().shape == (16, 24, 3)
    with pytest.raises(SourceError, match=r"b\.png"):
        source.read()
    assert source.read() is None  # the end, cleanly
    looping = open_source(str(tmp_path / "*.png"), loop=True)
    assert looping.read() is not None
    with pytest.raises(SourceError):
        looping.read()
    assert looping.read() is not None  # started over


def test_a_looped_still_is_decoded_once(tmp_path):
    still = tmp_path / "still.png"
    cv2.imwrite(str(still), np.full((16, 24, 3), 7, np.uint8))
    source = open_source(str(still), loop=True)
    first = source.read()
    still.write_bytes(b"replaced by something unreadable")  # not read again: the decoded frame is replayed
    assert all(np.array_equal(source.read(), first) for _ in range(3))
    once = open_source(str(tmp_path / "still.png"))
    with pytest.raises(SourceError):  # not looped: read as it is now
        once.read()


def test_video_end_and_loop(tmp_path):
    path = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 5, (32, 24))
    for k in range(3):
        writer.write(np.full((24, 32, 3), 40 * k, np.uint8))
    writer.release()
    once = open_source(str(path))
    assert isinstance(once, FileSource)
    assert [once.read() is not None for _ in range(4)] == [True, True, True, False]
    looping = open_source(str(path), loop=True)
    assert all(looping.read() is not None for _ in range(7))


def test_a_real_video_file_plays_to_its_end_and_loops():
    """OpenCV's Megamind.avi (../shared/data/video): every frame, its size, then the end; looping restarts it."""
    from helpers import shared

    path = str(shared("video/Megamind.avi"))
    expected = int(cv2.VideoCapture(path).get(cv2.CAP_PROP_FRAME_COUNT))
    source = open_source(path)
    frames = []
    while (frame := source.read()) is not None:
        frames.append(frame.shape)
    assert len(frames) == expected > 100 and set(frames) == {(528, 720, 3)}
    looping = open_source(path, loop=True)
    first = looping.read()
    for _ in range(expected - 1):
        looping.read()
    assert np.array_equal(looping.read(), first)  # the first frame again


def test_bad_sources_say_why(tmp_path):
    with pytest.raises(SourceError, match="not 'synthetic'"):
        open_source(str(tmp_path / "nothing*.png"))
    with pytest.raises(SourceError, match="synthetic scene"):
        SyntheticSource("teapot")


@pytest.mark.parametrize("settings, said", [
    (dict(source="synthetic", width=1280, height=720), "image_width/image_height applies only to a device"),
    (dict(source="synthetic", loop=True), "loop applies only to files"),
    (dict(source="0", synthetic_scene="cube"), "synthetic_scene applies only to the synthetic camera"),
    (dict(source="/dev/video3", loop=True, synthetic_medium="air"),
     "loop applies only to files (videos, folders, bags); synthetic_medium applies only to the synthetic camera"),
    (dict(source="run3.mp4", width=640), "is files (videos, folders, bags): image_width/image_height applies only"),
])
def test_a_setting_the_source_has_no_use_for_is_refused(settings, said):
    """The camera node's size for a video, its synthetic scene for a device, looping a device: ignored without a
    word before (a device opened at its own size while the launch file asked for 1280x720 went unnoticed)."""
    source = settings.pop("source")
    with pytest.raises(SourceError, match=re.escape(said)):
        open_source(source, **settings)


def test_synthetic_source_shows_board_views_then_the_cube():
    source = SyntheticSource("board_then_cube", "water", board_passes=1)
    first = source.read()
    assert first.shape == (480, 640, 3)
    source.index = source.board_frames  # skip the rest of the board views
    cube = source.read()
    assert cube.shape == (480, 640, 3) and not np.array_equal(cube, first)
    assert source.true_area_m2 == pytest.approx(CUBE_SIDE_M**2, rel=1e-6)


def test_a_bag_is_a_source_like_the_command_lines_input(tmp_path):
    """Files reach the camera node through the command line's reader: a recorded bag's images play too."""
    from veg_area_ros.bags import BagRecorder
    from veg_area_ros.cdr import encode_image

    recorder = BagRecorder(tmp_path / "run", "mcap")
    recorder.add_topic("/image_raw", "sensor_msgs/msg/Image")
    for k in range(2):
        recorder.write("/image_raw", k + 1, encode_image(np.full((24, 32, 3), 50 * k, np.uint8), k, 0, "camera"))
    recorder.close()
    source = open_source(str(tmp_path / "run"))
    frames = [source.read() for _ in range(3)]
    assert [f is None for f in frames] == [False, False, True]
    assert [int(f[0, 0, 0]) for f in frames[:2]] == [0, 50]


def test_a_folder_of_a_scientific_cameras_16_bit_files_says_the_depth_once(tmp_path):
    """The camera node publishes 8-bit frames: a 12-bit camera's 16-bit files are read at their depth (the same
    grey levels as the 8-bit frame they hold) and the assumed depth is kept for the node to log, once per kind."""
    frame = np.random.default_rng(0).integers(0, 256, (48, 64, 3)).astype(np.uint8)
    for k in range(3):
        cv2.imwrite(str(tmp_path / f"f{k}.png"), frame.astype(np.uint16) << 4)
    source = open_source(str(tmp_path))
    assert all(np.array_equal(source.read(), frame) for _ in range(3))
    assert len(source.notes) == 1 and source.notes[0].startswith("f0.png: 16-bit image read as 12-bit data")
    assert source.notes[0].endswith("(the published frames are 8-bit)")


def test_files_a_folder_source_passes_over_are_said_as_they_are(tmp_path):
    """A Mac's `._` files beside the frames are passed over and said; the note was logged with "(the published
    frames are 8-bit)", which is about a 16-bit file's depth alone."""
    frame = np.random.default_rng(0).integers(0, 256, (48, 64, 3)).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "f0.png"), frame)
    (tmp_path / "._f0.png").write_bytes(b"\x00\x05\x16\x07\x00\x02\x00\x00Mac OS X        ")
    source = open_source(str(tmp_path))
    assert np.array_equal(source.read(), frame) and source.read() is None
    assert source.notes == [f"{tmp_path}: 1 hidden file not read (._f0.png; `._` files are a Mac's metadata beside "
                            "each file)"]
