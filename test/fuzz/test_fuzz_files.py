"""Files: a corrupt frame is reported, not measured; a user's output is never replaced by an error-only one;
files get the umask's mode; a killed writer's temp files go; bag-recover names what it dropped."""

from __future__ import annotations

import os
import shutil
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from veg_area_ros.bags import BagError, BagRecorder, recover_bag
from veg_area_ros.calib_io import write_calibration
from veg_area_ros.cdr import encode_image
from veg_area_ros.cli import main as veg_area
from veg_area_ros.frames import read_image
from veg_area_ros.sim.synthetic import (
    ENDOSCOPE,
    cube_scene,
    render_scene,
    scene_targets_content,
)


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """The true endoscope's calibration, the scene's targets, and the cube in air as a PNG and a JPEG."""
    folder = tmp_path_factory.mktemp("files")
    write_calibration(folder / "camera.yaml", ENDOSCOPE, "endoscope", {"medium": "air"})
    (folder / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7)
    cv2.imwrite(str(folder / "cube.png"), frame)
    cv2.imwrite(str(folder / "cube.jpg"), frame, [cv2.IMWRITE_JPEG_QUALITY, 95])
    return folder


def scrambled_jpeg(good: bytes, seed: int, length: int) -> bytes:
    data = bytearray(good)
    rng = np.random.default_rng(seed)
    start = int(rng.integers(len(data) // 4, len(data) // 2))
    data[start:start + length] = rng.integers(0, 256, length, dtype=np.uint8).tobytes()
    return bytes(data)


def measure(workspace: Path, *inputs: str, extra: tuple[str, ...] = ()) -> int:
    return veg_area(["measure", *inputs, "--calibration", str(workspace / "camera.yaml"),
                     "--targets", str(workspace / "targets.yaml"), "--threshold", "120", *extra])


def test_a_scrambled_jpeg_is_reported_corrupt_not_measured(workspace, tmp_path, capsys):
    good = (workspace / "cube.jpg").read_bytes()
    folder = tmp_path / "frames"
    folder.mkdir()
    shutil.copy(workspace / "cube.jpg", folder / "a_good.jpg")
    (folder / "b_scrambled.jpg").write_bytes(scrambled_jpeg(good, 0, 2000))
    code = measure(workspace, str(folder), extra=("--csv", str(tmp_path / "areas.csv")))
    err = capsys.readouterr().err
    # a frame lost to damage: the good one measured and kept, the run exits 1 and names the lost one
    assert code == 1 and "b_scrambled.jpg" in err and "corrupt JPEG" in err and "1 of 2 frames could not be read" in err
    rows = (tmp_path / "areas.csv").read_text().splitlines()
    assert len(rows) == 3 and "corrupt JPEG" in rows[2] and rows[2].split(",")[4] == ""  # no area for it


@pytest.mark.parametrize(("length", "least_caught"), [(16, 0.55), (64, 0.80), (300, 0.95), (2000, 1.0)])
def test_scrambles_are_caught(workspace, tmp_path, length, least_caught):
    """Scrambled runs at 100 places each, all of which OpenCV alone decodes without an error: refused by the
    marker structure or the decoder's own warning. The limit: a short scramble that the entropy decoder
    swallows without a marker and without a warning (no restart markers, no end-of-data mismatch libjpeg
    reports through OpenCV) decodes as a silently different picture; measured 61 % caught at 16 bytes,
    85 % at 64, 98 % at 300, 100 % at 2 kB."""
    good = (workspace / "cube.jpg").read_bytes()
    caught = 0
    for seed in range(100):
        path = tmp_path / f"s{seed}.jpg"
        path.write_bytes(scrambled_jpeg(good, seed, length))
        caught += bool(read_image(path)[1])
    assert caught / 100 >= least_caught


def test_real_jpegs_are_not_called_corrupt(workspace, tmp_path):
    frame = cv2.imread(str(workspace / "cube.png"))
    for name, params in {"baseline": [], "progressive": [cv2.IMWRITE_JPEG_PROGRESSIVE, 1],
                         "restarts": [cv2.IMWRITE_JPEG_RST_INTERVAL, 3], "q30": [cv2.IMWRITE_JPEG_QUALITY, 30],
                         "grey": []}.items():
        image = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if name == "grey" else frame
        cv2.imwrite(str(tmp_path / f"{name}.jpg"), image, params)
        decoded, problem = read_image(tmp_path / f"{name}.jpg")
        assert problem == "" and decoded.shape[:2] == frame.shape[:2], name
    for real in sorted((Path(__file__).parents[1] / "data").rglob("*.jpg")):
        assert read_image(real)[1] == "", real


def test_grey_decoding_refuses_what_colour_decoding_refuses_and_reads_the_same_picture(workspace, tmp_path):
    """`veg-area calibrate` decodes its photos in grey (a JPEG's colour skipped): a damaged file must be refused
    there exactly as in colour, and a good one read as the colour picture's grey."""
    good = (workspace / "cube.jpg").read_bytes()
    refused = 0
    for length in (16, 64, 300):
        for seed in range(40):
            path = tmp_path / f"s{length}_{seed}.jpg"
            path.write_bytes(scrambled_jpeg(good, seed, length))
            colour, grey = read_image(path)[1], read_image(path, grey=True)[1]
            assert grey == colour, path.name
            refused += bool(grey)
    assert refused >= 60  # the comparison covered refusals, not only clean reads
    # tinted as a flume's water tints it, so that a channel taken for the grey would show (26 DN off)
    frame = (cv2.imread(str(workspace / "cube.png")) * np.array([1.0, 0.85, 0.55])).astype(np.uint8)
    for name, params in {"baseline": [], "progressive": [cv2.IMWRITE_JPEG_PROGRESSIVE, 1],
                         "restarts": [cv2.IMWRITE_JPEG_RST_INTERVAL, 3]}.items():
        cv2.imwrite(str(tmp_path / f"{name}.jpg"), frame, params)
        colour, grey = read_image(tmp_path / f"{name}.jpg")[0], read_image(tmp_path / f"{name}.jpg", grey=True)[0]
        difference = np.abs(grey.astype(int) - cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY).astype(int))
        assert grey.ndim == 2 and difference.mean() < 0.25, name  # a few DN only where the colour changes
    cv2.imwrite(str(tmp_path / "cube.png"), frame)
    lossless = read_image(tmp_path / "cube.png", grey=True)[0].astype(int)
    assert np.abs(lossless - cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)).max() <= 1  # OpenCV's own rounding


def test_an_existing_csv_is_kept_when_nothing_is_measured(workspace, tmp_path, capsys):
    csv_path = tmp_path / "areas.csv"
    csv_path.write_text("frame,area_m2\nyesterday,0.0105\n")
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640, 3), 200, np.uint8))  # no targets in it
    assert measure(workspace, str(blank), extra=("--csv", str(csv_path))) == 1
    assert csv_path.read_text() == "frame,area_m2\nyesterday,0.0105\n"
    assert f"the existing {csv_path} is kept" in capsys.readouterr().err


@pytest.mark.parametrize("umask", [0o022, 0o002, 0o077])
def test_written_files_take_their_mode_from_the_umask(tmp_path, umask):
    previous = os.umask(umask)
    try:
        write_calibration(tmp_path / "camera.yaml", ENDOSCOPE)
    finally:
        os.umask(previous)
    assert (tmp_path / "camera.yaml").stat().st_mode & 0o777 == 0o666 & ~umask


def test_a_killed_writers_temp_file_is_removed_by_the_next_write(tmp_path):
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    orphan = tmp_path / f".camera.yaml.{int(dead.stdout)}.abc123.tmp"
    orphan.write_text("half a file")
    live = tmp_path / f".camera.yaml.{os.getppid()}.def456.tmp"  # a running writer's: left alone
    live.write_text("being written")
    write_calibration(tmp_path / "camera.yaml", ENDOSCOPE)
    assert not orphan.exists() and live.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["camera.yaml", live.name])


def _bag(folder: Path, frames: int = 6) -> Path:
    recorder = BagRecorder(folder / "bag", "mcap")
    recorder.add_topic("/image_raw", "sensor_msgs/msg/Image")
    rng = np.random.default_rng(0)
    for k in range(frames):
        recorder.write("/image_raw", 1000 + k, encode_image(rng.integers(0, 256, (480, 640, 3), np.uint8), k, 0, "c"))
    recorder.close()
    return next((folder / "bag").glob("*.mcap"))


def _chunks(data: bytes) -> list[tuple[int, int]]:
    """(offset, length) of every chunk record."""
    found, offset = [], 8
    while offset + 9 <= len(data):
        opcode, (length,) = data[offset], struct.unpack_from("<Q", data, offset + 1)
        if opcode == 0x06:
            found.append((offset, length))
        offset += 9 + length
    return found


def test_bag_recover_drops_a_chunk_whose_crc_fails_and_says_so(tmp_path, capsys):
    """Our recorder stores chunk CRCs, as ros2 bag's MCAP writer does (plain rosbags stores none): 64 flipped
    bytes lose that chunk, named on stderr, instead of one image silently different."""
    data = bytearray(_bag(tmp_path).read_bytes())
    chunks = _chunks(bytes(data))
    assert len(chunks) >= 3
    assert all(struct.unpack_from("<I", data, offset + 9 + 24)[0] for offset, _ in chunks)  # every CRC written
    offset, length = chunks[1]
    middle = offset + length // 2
    data[middle:middle + 64] = bytes(255 - b for b in data[middle:middle + 64])
    (tmp_path / "flipped.mcap").write_bytes(bytes(data))
    assert veg_area(["bag-recover", str(tmp_path / "flipped.mcap"), str(tmp_path / "out")]) == 0
    captured = capsys.readouterr()
    assert f"chunk at byte {offset} dropped" in captured.err
    recovered = recover_bag(tmp_path / "flipped.mcap", tmp_path / "out2")
    assert 0 < recovered.counts["/image_raw"] < 6 and recovered.unchecked_chunks == 0


def test_bag_recover_says_when_chunks_carry_no_crc(tmp_path, capsys):
    """A bag from a writer that leaves the chunk CRCs 0 (plain rosbags): recovered, and said that damage inside
    its chunks cannot be seen."""
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin

    from veg_area_ros.bags import typestore

    with Writer(tmp_path / "plain", version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection("/image_raw", "sensor_msgs/msg/Image", typestore=typestore())
        for k in range(3):
            writer.write(connection, 1000 + k, encode_image(np.full((48, 64, 3), k, np.uint8), k, 0, "c"))
    mcap = next((tmp_path / "plain").glob("*.mcap"))
    assert veg_area(["bag-recover", str(mcap), str(tmp_path / "out")]) == 0
    assert "carry no CRC" in capsys.readouterr().err


@pytest.mark.parametrize("damage", ["missing", "header", "empty", "folder without mcap"])
def test_bag_recover_refuses_what_it_cannot_read(tmp_path, capsys, damage):
    mcap = _bag(tmp_path)
    if damage == "missing":
        target = tmp_path / "nowhere.mcap"
    elif damage == "header":
        data = bytearray(mcap.read_bytes())
        data[:16] = b"\x00" * 16
        target = tmp_path / "mangled.mcap"
        target.write_bytes(bytes(data))
    elif damage == "empty":
        target = tmp_path / "empty.mcap"
        target.write_bytes(b"")
    else:
        target = tmp_path / "folder"
        target.mkdir()
    assert veg_area(["bag-recover", str(target), str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("veg-area bag-recover: ") and "Traceback" not in err
    with pytest.raises(BagError):
        recover_bag(target, tmp_path / "out3")
