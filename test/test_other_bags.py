"""Bags as other tools write them, written here by `rosbags` (the library behind the rosbag2 format `ros2 bag
record` writes, independent of this package's recorder): two cameras in one bag, each image topic paired with
its own camera_info as image_transport pairs them (whatever order the bag lists them in, mcap and sqlite3
alike); image_transport's `compressed` topics (sensor_msgs/CompressedImage, JPEG) measured as the same JPEG
files are; and a calibration file of another camera than the bag's camera_info said in the results."""

from __future__ import annotations

import dataclasses
import json
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from helpers import TEST_DATA, run_cli
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.typesys import Stores, get_typestore

from veg_area_ros.bags import sibling_camera_info
from veg_area_ros.calib_io import write_calibration
from veg_area_ros.camera_info import camera_info_fields
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content

TYPES = get_typestore(Stores.ROS2_KILTED)
STORAGE = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
RIGHT = dataclasses.replace(ENDOSCOPE, c=560.0, xp=314.0, k1=-0.22, k2=0.05)  # another endoscope
FRAMES = 3


def _header(k: int, frame_id: str):
    return TYPES.types["std_msgs/msg/Header"](stamp=TYPES.types["builtin_interfaces/msg/Time"](sec=100 + k, nanosec=0),
                                              frame_id=frame_id)


def _info(camera, k: int, frame_id: str):
    fields = camera_info_fields(camera)
    return TYPES.types["sensor_msgs/msg/CameraInfo"](
        header=_header(k, frame_id), height=camera.height, width=camera.width,
        distortion_model=fields["distortion_model"], d=np.array(fields["d"], float), k=np.array(fields["k"], float),
        r=np.array(fields["r"], float), p=np.array(fields["p"], float), binning_x=0, binning_y=0,
        roi=TYPES.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                            do_rectify=False))


def _image(frame: np.ndarray, k: int, frame_id: str):
    return TYPES.types["sensor_msgs/msg/Image"](header=_header(k, frame_id), height=frame.shape[0],
                                                width=frame.shape[1], encoding="bgr8", is_bigendian=0,
                                                step=3 * frame.shape[1], data=frame.ravel())


def _compressed(jpeg: bytes, k: int, frame_id: str):
    return TYPES.types["sensor_msgs/msg/CompressedImage"](header=_header(k, frame_id),
                                                          format="bgr8; jpeg compressed bgr8",
                                                          data=np.frombuffer(jpeg, np.uint8))


def write_bag(path: Path, storage: str, topics: list[tuple[str, str, list]], compression: str = "none",
              first: int = 0) -> None:
    """A bag of (topic, msgtype, messages) in that connection order, the messages interleaved by index from
    `first`; `compression` as `ros2 bag record --compression-mode file|message` (zstd) writes it."""
    writer = Writer(path, version=Writer.VERSION_LATEST, storage_plugin=STORAGE[storage])
    if compression != "none":
        writer.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
    with writer:
        connections = [(writer.add_connection(topic, msgtype, typestore=TYPES), msgtype, messages)
                       for topic, msgtype, messages in topics]
        for k in range(max(len(messages) for *_, messages in topics)):
            for slot, (connection, msgtype, messages) in enumerate(connections):
                if k < len(messages):
                    writer.write(connection, (100 + first + k) * 10**9 + slot,
                                 TYPES.serialize_cdr(messages[k], msgtype))


@pytest.fixture(scope="module")
def scenes():
    """The cube seen by the left endoscope and by the right one (another lens)."""
    return {name: [render_scene(camera, cube_scene(), 0.7, seed=k) for k in range(FRAMES)]
            for name, camera in (("left", ENDOSCOPE), ("right", RIGHT))}


@pytest.fixture
def workspace(tmp_path):
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    return tmp_path


def _measure(workspace: Path, source: Path, *options: str) -> tuple[list[dict], object]:
    done = run_cli("measure", str(source), "--targets", str(workspace / "targets.yaml"), "--threshold", "120",
                   "--json", "--csv", str(workspace / f"{source.stem}.csv"), *options, cwd=workspace)
    rows = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    return rows, done


def test_the_sibling_camera_info_is_image_transports():
    assert sibling_camera_info("/left/image_raw") == "/left/camera_info"
    assert sibling_camera_info("/left/image_raw/compressed") == "/left/camera_info"
    assert sibling_camera_info("/robot/cam/image_rect") == "/robot/cam/camera_info"
    assert sibling_camera_info("/image_raw") == "/camera_info"


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize("right_first", [True, False])
def test_two_cameras_in_one_bag_each_measured_with_its_own_camera_info(workspace, scenes, storage, right_first):
    """The right camera's camera_info listed first measured the left images with it (Af +1.1 %, no word)."""
    cameras = {"left": ENDOSCOPE, "right": RIGHT}
    topics = []
    for name in (("right", "left") if right_first else ("left", "right")):
        topics.append((f"/{name}/camera_info", "sensor_msgs/msg/CameraInfo",
                       [_info(cameras[name], k, f"{name}_optical") for k in range(FRAMES)]))
    for name in ("left", "right"):
        topics.append((f"/{name}/image_raw", "sensor_msgs/msg/Image",
                       [_image(frame, k, f"{name}_optical") for k, frame in enumerate(scenes[name])]))
    bag = workspace / f"stereo_{storage}"
    write_bag(bag, storage, topics)
    truth = cube_scene().true_area_m2
    for name in ("left", "right"):
        rows, done = _measure(workspace, bag, "--calibration", "bag", "--image-topic", f"/{name}/image_raw")
        assert done.returncode == 0, done.stderr
        assert len(rows) == FRAMES and all(not row.get("error") for row in rows), rows
        errors = [row["area_m2"] / truth - 1 for row in rows]
        assert max(abs(e) for e in errors) < 0.003, (name, errors)


def test_a_camera_info_of_another_frame_is_not_used(workspace, scenes):
    """The only camera_info in the bag is not the image's sibling and names another frame_id: each frame is
    refused with both names, never measured with it."""
    bag = workspace / "mismatch"
    write_bag(bag, "mcap", [
        ("/right/camera_info", "sensor_msgs/msg/CameraInfo", [_info(RIGHT, k, "right_optical") for k in range(FRAMES)]),
        ("/left/image_raw", "sensor_msgs/msg/Image",
         [_image(frame, k, "left_optical") for k, frame in enumerate(scenes["left"])])])
    rows, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode != 0
    assert len(rows) == FRAMES and all("'right_optical'" in row["error"] and "'left_optical'" in row["error"]
                                       for row in rows), rows


def test_several_camera_infos_and_no_sibling_are_refused_naming_them(workspace, scenes):
    bag = workspace / "ambiguous"
    write_bag(bag, "mcap", [
        ("/a/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, 0, "")]),
        ("/b/camera_info", "sensor_msgs/msg/CameraInfo", [_info(RIGHT, 0, "")]),
        ("/cam/image_raw", "sensor_msgs/msg/Image", [_image(scenes["left"][0], 0, "")])])
    _, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode != 0
    assert "/a/camera_info, /b/camera_info" in done.stderr and "/cam/camera_info" in done.stderr
    write_calibration(workspace / "cam.yaml", ENDOSCOPE, "cam", {"medium": "air"})  # a file needs none of them
    rows, done = _measure(workspace, bag, "--calibration", str(workspace / "cam.yaml"))
    assert done.returncode == 0 and len(rows) == 1 and not rows[0].get("error"), done.stderr


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_compressed_images_give_the_jpeg_files_af(workspace, scenes, storage):
    """image_transport's `compressed` topic (JPEG): found without naming it, and each frame's Af equals the Af
    of the same JPEG written as a file and measured with the same calibration."""
    jpegs = [cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 85])[1].tobytes() for frame in scenes["left"]]
    bag = workspace / f"compressed_{storage}"
    write_bag(bag, storage, [
        ("/left/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in range(FRAMES)]),
        ("/left/image_raw/compressed", "sensor_msgs/msg/CompressedImage",
         [_compressed(jpeg, k, "left") for k, jpeg in enumerate(jpegs)])])
    folder = workspace / "jpegs"
    folder.mkdir()
    for k, jpeg in enumerate(jpegs):
        (folder / f"frame{k}.jpg").write_bytes(jpeg)
    write_calibration(workspace / "left.yaml", ENDOSCOPE, "left", {"medium": "air"})
    from_bag, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode == 0, done.stderr
    from_files, done = _measure(workspace, folder, "--calibration", str(workspace / "left.yaml"))
    assert done.returncode == 0, done.stderr
    assert [r["area_m2"] for r in from_bag] == [r["area_m2"] for r in from_files]
    assert abs(from_bag[0]["area_m2"] / cube_scene().true_area_m2 - 1) < 0.005


def test_a_corrupt_jpeg_in_a_compressed_topic_is_refused_not_measured(workspace, scenes):
    """A compressed frame whose JPEG scan is scrambled (a damaged bag, a lossy link) decoded into a grey smear
    with a warning on stderr only and was measured (its Af off by tens of percent), although the same JPEG as a
    file is refused. Its row now says why, the other frames are measured as before."""
    from veg_area_ros.frames import decode_image_file

    jpegs = [cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 85])[1].tobytes() for frame in scenes["left"]]
    damaged = bytearray(jpegs[1])
    middle = len(damaged) // 2
    damaged[middle:middle + 300] = np.random.default_rng(1).integers(0, 256, 300, dtype=np.uint8).tobytes()
    assert cv2.imdecode(np.frombuffer(bytes(damaged), np.uint8), cv2.IMREAD_COLOR) is not None  # decodes, wrong
    assert decode_image_file(bytes(damaged))[1].startswith("is a ")  # refused as a file (truncated or corrupt)
    jpegs[1] = bytes(damaged)
    bag = workspace / "damaged"
    write_bag(bag, "mcap", [
        ("/left/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in range(FRAMES)]),
        ("/left/image_raw/compressed", "sensor_msgs/msg/CompressedImage",
         [_compressed(jpeg, k, "left") for k, jpeg in enumerate(jpegs)])])
    rows, done = _measure(workspace, bag, "--calibration", "bag")
    assert len(rows) == FRAMES, done.stderr
    assert "is a corrupt JPEG" in rows[1]["error"] and rows[1].get("area_m2") in (None, ""), rows[1]
    assert all(not row.get("error") and abs(row["area_m2"] / cube_scene().true_area_m2 - 1) < 0.005
               for k, row in enumerate(rows) if k != 1), rows


def _zstd(frame: np.ndarray, k: int, frame_id: str):
    """image_transport's zstd plugin's message: its header (height, width, is_bigendian, step, encoding) and the
    zstd frame of the bgr8 rows."""
    from backports import zstd

    height, width = frame.shape[:2]
    data = struct.pack("<IIBII", height, width, 0, 3 * width, 4) + b"bgr8" + zstd.compress(frame.tobytes(), 3)
    return TYPES.types["sensor_msgs/msg/CompressedImage"](header=_header(k, frame_id), format="zstd",
                                                          data=np.frombuffer(data, np.uint8))


def test_a_bag_of_one_cameras_every_transport_measures_its_raw_frames(workspace, scenes):
    """`ros2 bag record -a` beside an image_transport camera keeps image_raw, image_raw/compressed and
    image_raw/zstd, the same frames three times: it was "pick the image topic". The raw topic is measured (the
    lossless zstd one measures the same Af), and the run says which and what it left; two cameras' topics still
    need --image-topic."""
    frames = scenes["left"]
    jpegs = [cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 85])[1].tobytes() for frame in frames]
    bag = workspace / "record_all"
    camera = [
        ("/cam/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "cam") for k in range(FRAMES)]),
        ("/cam/image_raw/compressed", "sensor_msgs/msg/CompressedImage",
         [_compressed(jpeg, k, "cam") for k, jpeg in enumerate(jpegs)]),
        ("/cam/image_raw/zstd", "sensor_msgs/msg/CompressedImage", [_zstd(f, k, "cam") for k, f in enumerate(frames)]),
        ("/cam/image_raw", "sensor_msgs/msg/Image", [_image(f, k, "cam") for k, f in enumerate(frames)])]
    write_bag(bag, "mcap", camera)
    rows, said = {}, {}
    for name, options in [("chosen", ()), ("raw", ("--image-topic", "/cam/image_raw")),
                          ("zstd", ("--image-topic", "/cam/image_raw/zstd")),
                          ("jpeg", ("--image-topic", "/cam/image_raw/compressed"))]:
        measured, done = _measure(workspace, bag, "--calibration", "bag", *options)
        assert done.returncode == 0, done.stderr
        rows[name], said[name] = [row["area_m2"] for row in measured], done.stdout + done.stderr
    assert ("record_all: measuring /cam/image_raw" in said["chosen"]
            and "also recorded and not read: /cam/image_raw/compressed, /cam/image_raw/zstd" in said["chosen"])
    assert "also recorded" not in said["raw"]  # named: no choice was made
    assert rows["chosen"] == rows["raw"] == rows["zstd"] and len(rows["raw"]) == FRAMES
    assert rows["jpeg"] != rows["raw"]  # JPEG's loss shows: the raw topic was the one measured
    two = workspace / "two_cameras_all"
    write_bag(two, "mcap", [*camera, ("/other/image_raw", "sensor_msgs/msg/Image",
                                      [_image(f, k, "other") for k, f in enumerate(frames)])])
    _, done = _measure(workspace, two, "--calibration", "bag")
    assert done.returncode != 0 and "pick the image topic (--image-topic)" in done.stderr, done.stderr


def _split(bag: Path, storage: str, parts: list[list[tuple[str, str, list]]], first: list[int]) -> None:
    """A bag split into several files as `ros2 bag record --max-bag-size` leaves it: one metadata.yaml that
    lists every file, each file a bag of its own part of the messages."""
    suffix = {"mcap": "mcap", "sqlite3": "db3"}[storage]
    bag.mkdir()
    infos = []
    for number, (topics, start) in enumerate(zip(parts, first, strict=True)):
        part = bag.parent / f"{bag.name}_part{number}"
        write_bag(part, storage, topics, first=start)
        (part / f"{part.name}.{suffix}").rename(bag / f"{bag.name}_{number}.{suffix}")
        infos.append(yaml.safe_load((part / "metadata.yaml").read_text())["rosbag2_bagfile_information"])
    merged = infos[0]
    merged["relative_file_paths"] = [f"{bag.name}_{k}.{suffix}" for k in range(len(parts))]
    merged["files"] = [{**info["files"][0], "path": f"{bag.name}_{k}.{suffix}"} for k, info in enumerate(infos)]
    merged["message_count"] = sum(info["message_count"] for info in infos)
    for k, topic in enumerate(merged["topics_with_message_count"]):
        topic["message_count"] = sum(info["topics_with_message_count"][k]["message_count"] for info in infos)
    (bag / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": merged}))


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_compressed_and_split_bags_as_ros2_bag_record_writes_them(workspace, scenes, storage):
    """`ros2 bag record --compression-mode file|message --compression-format zstd` (a .mcap.zstd or .db3.zstd
    file, or each message compressed) and `--max-bag-size` (the recording split over several files): each
    gives the plain bag's rows."""
    def topics(first: int, count: int) -> list[tuple[str, str, list]]:
        ks = range(first, first + count)
        return [("/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in ks]),
                ("/image_raw", "sensor_msgs/msg/Image", [_image(scenes["left"][k], k, "left") for k in ks])]

    bags = {}
    for compression in ("none", "file", "message"):
        bags[compression] = workspace / f"{storage}_{compression}"
        write_bag(bags[compression], storage, topics(0, FRAMES), compression)
    bags["split"] = workspace / f"{storage}_split"
    _split(bags["split"], storage, [topics(0, 2), topics(2, FRAMES - 2)], [0, 2])
    assert any(path.suffix == ".zstd" for path in bags["file"].iterdir())
    rows = {}
    for name, bag in bags.items():
        found, done = _measure(workspace, bag, "--calibration", "bag")
        assert done.returncode == 0, (name, done.stderr)
        rows[name] = [(row["frame"].rsplit("#", 1)[1], row["area_m2"]) for row in found]
    assert len(rows["none"]) == FRAMES
    assert rows["file"] == rows["message"] == rows["split"] == rows["none"]


def _encoded(frame: np.ndarray, encoding: str) -> tuple[np.ndarray, int]:
    """A BGR frame as a camera driver publishes it in `encoding`: (the message's bytes, its step)."""
    height, width = frame.shape[:2]
    if encoding == "rgba8":
        return cv2.cvtColor(frame, cv2.COLOR_BGR2RGBA), 4 * width
    if encoding.startswith("bayer_"):  # the raw mosaic: each pixel keeps one colour, as the sensor saw it
        pattern, mosaic = encoding[6:10], np.zeros((height, width), np.uint8)
        for (dy, dx), colour in zip(((0, 0), (0, 1), (1, 0), (1, 1)), pattern, strict=True):
            mosaic[dy::2, dx::2] = frame[dy::2, dx::2, "bgr".index(colour)]
        return mosaic, width
    # yuv422_yuy2: BT.601 video range, Y0 U Y1 V, the chroma shared by a pixel pair
    b, g, r = (frame[..., i].astype(float) for i in range(3))
    luma = 16 + (65.481 * r + 128.553 * g + 24.966 * b) / 255
    u = (128 + (-37.797 * r - 74.203 * g + 112 * b) / 255).reshape(height, width // 2, 2).mean(axis=2)
    v = (128 + (112 * r - 93.786 * g - 18.214 * b) / 255).reshape(height, width // 2, 2).mean(axis=2)
    packed = np.zeros((height, width, 2))
    packed[..., 0], packed[:, 0::2, 1], packed[:, 1::2, 1] = luma, u, v
    return np.clip(np.round(packed), 0, 255).astype(np.uint8), 2 * width


def test_camera_drivers_encodings_are_measured_as_their_colour_frames(workspace, scenes):
    """Camera drivers publish what their sensor gives: a raw Bayer mosaic (machine-vision cameras), YUV 4:2:2
    (webcams), RGBA. Each was refused ("encoding 'bayer_rggb8' is not supported"); each is converted to colour
    as cv_bridge converts it: RGBA gives the colour bag's Af exactly, a mosaic or YUV within a tenth of a percent
    (the demosaicing and the shared chroma soften an edge), and a mosaic read with the wrong pattern is not."""
    areas = {}
    for encoding in ("bgr8", "rgba8", "bayer_rggb8", "bayer_gbrg8", "yuv422_yuy2"):
        messages = []
        for k, frame in enumerate(scenes["left"]):
            data, step = (frame, 3 * frame.shape[1]) if encoding == "bgr8" else _encoded(frame, encoding)
            messages.append(TYPES.types["sensor_msgs/msg/Image"](
                header=_header(k, "left"), height=frame.shape[0], width=frame.shape[1], encoding=encoding,
                is_bigendian=0, step=step, data=data.ravel()))
        bag = workspace / encoding
        write_bag(bag, "mcap", [
            ("/left/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in range(FRAMES)]),
            ("/left/image_raw", "sensor_msgs/msg/Image", messages)])
        rows, done = _measure(workspace, bag, "--calibration", "bag")
        assert done.returncode == 0 and len(rows) == FRAMES, done.stderr
        areas[encoding] = np.array([r["area_m2"] for r in rows])
    assert list(areas["rgba8"]) == list(areas["bgr8"])
    for encoding in ("bayer_rggb8", "bayer_gbrg8", "yuv422_yuy2"):
        assert np.abs(areas[encoding] / areas["bgr8"] - 1).max() < 1e-3, (encoding, areas[encoding] / areas["bgr8"])
    # the patterns are told apart (the cube is grey): a colour ramp made as RGGB, read as each pattern
    from veg_area_ros.cdr import frame_pixels
    rows, columns = np.mgrid[0:64, 0:80]
    colour = cv2.GaussianBlur(np.dstack([3 * columns, 4 * rows, 128 + 0 * rows]).astype(np.uint8), (0, 0), 2)
    for pattern in ("rggb", "bggr", "gbrg", "grbg"):
        mosaic, step = _encoded(colour, f"bayer_{pattern}8")
        errors = {read: np.abs(frame_pixels(mosaic.tobytes(), 64, 80, f"bayer_{read}8", step)[4:-4, 4:-4]
                               .astype(int) - colour[4:-4, 4:-4]).mean() for read in ("rggb", "bggr", "gbrg", "grbg")}
        assert errors[pattern] < 1 and min(e for read, e in errors.items() if read != pattern) > 10, errors


def _twelve_bits(frame: np.ndarray, seed: int) -> np.ndarray:
    """A frame as a 12-bit sensor gives it in 16 bits: its 8-bit levels with four low bits of noise below."""
    low = np.random.default_rng(seed).integers(0, 16, frame.shape, dtype=np.uint16)
    return (frame.astype(np.uint16) << 4) | low


def test_a_machine_vision_cameras_16_bit_frames_are_measured_as_its_8_bit_ones(workspace, scenes):
    """Machine-vision drivers publish a 10-16-bit sensor's levels as mono16, bgr16 (big-endian too) or a 16-bit
    Bayer mosaic, and image_transport compresses mono16 as a 16-bit PNG: each was refused ("16-bit and float
    images are not measured"). A 12-bit sensor's frames are read at 12 bits, as its 8-bit frames would be (the
    same Af exactly; the mosaic within a tenth of a percent), and each row says the depth it assumed."""
    greys = [cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) for frame in scenes["left"]]

    def raw(encoding: str, data: np.ndarray, step: int, k: int, bigendian: int = 0):
        return TYPES.types["sensor_msgs/msg/Image"](
            header=_header(k, "left"), height=480, width=640, encoding=encoding, is_bigendian=bigendian, step=step,
            data=np.frombuffer(data.tobytes(), np.uint8))

    def png16(grey: np.ndarray, k: int):
        return TYPES.types["sensor_msgs/msg/CompressedImage"](
            header=_header(k, "left"), format="mono16; png compressed mono16",
            data=np.frombuffer(cv2.imencode(".png", _twelve_bits(grey, k))[1].tobytes(), np.uint8))

    bags = {
        "bgr8": ("sensor_msgs/msg/Image", [_image(f, k, "left") for k, f in enumerate(scenes["left"])]),
        "mono8": ("sensor_msgs/msg/Image", [raw("mono8", g, 640, k) for k, g in enumerate(greys)]),
        "mono16": ("sensor_msgs/msg/Image", [raw("mono16", _twelve_bits(g, k), 1280, k) for k, g in enumerate(greys)]),
        "bgr16_big_endian": ("sensor_msgs/msg/Image", [
            raw("bgr16", _twelve_bits(f, k).astype(">u2"), 3840, k, bigendian=1)
            for k, f in enumerate(scenes["left"])]),
        "bayer_rggb16": ("sensor_msgs/msg/Image", [
            raw("bayer_rggb16", _twelve_bits(_encoded(f, "bayer_rggb8")[0], k), 1280, k)
            for k, f in enumerate(scenes["left"])]),
        "mono16_png": ("sensor_msgs/msg/CompressedImage", [png16(g, k) for k, g in enumerate(greys)]),
    }
    areas, warnings = {}, {}
    for name, (msgtype, messages) in bags.items():
        topic = "/left/image_raw/compressed" if msgtype.endswith("CompressedImage") else "/left/image_raw"
        bag = workspace / name
        write_bag(bag, "mcap", [
            ("/left/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in range(FRAMES)]),
            (topic, msgtype, messages)])
        rows, done = _measure(workspace, bag, "--calibration", "bag")
        assert done.returncode == 0 and len(rows) == FRAMES, (name, done.stderr)
        areas[name] = np.array([r["area_m2"] for r in rows])
        warnings[name] = [" ".join(r["warnings"]) for r in rows]
    assert list(areas["mono16"]) == list(areas["mono8"]) == list(areas["mono16_png"])
    assert list(areas["bgr16_big_endian"]) == list(areas["bgr8"])
    assert np.abs(areas["bayer_rggb16"] / areas["bgr8"] - 1).max() < 1e-3, areas["bayer_rggb16"] / areas["bgr8"]
    for name in ("mono16", "bgr16_big_endian", "bayer_rggb16", "mono16_png"):
        assert all("read as 12-bit data" in text for text in warnings[name]), (name, warnings[name])
    assert not any("bit data" in text for text in warnings["bgr8"] + warnings["mono8"])


def test_a_ros1_bag_is_measured_as_the_same_frames_in_a_rosbag2_bag(workspace, scenes):
    """A lab's older recordings are ROS 1 bags (`rosbag record`, written here by rosbags' rosbag1 writer): they
    were "neither an image nor a video". Read as rosbags-convert converts them (the header's seq dropped,
    CameraInfo's D K R P), each frame gives the rosbag2 bag's Af exactly, with the bag's camera_info; a flume
    run's force, velocity and Af topics in ROS 1 bags give vogel the same runs as rosbag2 bags."""
    from rosbags.rosbag1 import Writer as Ros1Writer

    ros1 = get_typestore(Stores.ROS1_NOETIC)
    kinds = ros1.types
    fields = camera_info_fields(ENDOSCOPE)

    def header(k: int):
        return kinds["std_msgs/msg/Header"](seq=k, stamp=kinds["builtin_interfaces/msg/Time"](sec=100 + k, nanosec=0),
                                            frame_id="left")

    bag = workspace / "left.bag"
    with Ros1Writer(bag) as writer:
        info = writer.add_connection("/left/camera_info", "sensor_msgs/msg/CameraInfo", typestore=ros1)
        image = writer.add_connection("/left/image_raw", "sensor_msgs/msg/Image", typestore=ros1)
        for k, frame in enumerate(scenes["left"]):
            writer.write(info, (100 + k) * 10**9, ros1.serialize_ros1(kinds["sensor_msgs/msg/CameraInfo"](
                header=header(k), height=480, width=640, distortion_model=fields["distortion_model"],
                D=np.array(fields["d"], float), K=np.array(fields["k"], float), R=np.array(fields["r"], float),
                P=np.array(fields["p"], float), binning_x=0, binning_y=0,
                roi=kinds["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                              do_rectify=False)), "sensor_msgs/msg/CameraInfo"))
            writer.write(image, (100 + k) * 10**9 + 1, ros1.serialize_ros1(kinds["sensor_msgs/msg/Image"](
                header=header(k), height=480, width=640, encoding="bgr8", is_bigendian=0, step=1920,
                data=frame.ravel()), "sensor_msgs/msg/Image"))
    two = workspace / "left_ros2"
    write_bag(two, "mcap", [
        ("/left/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in range(FRAMES)]),
        ("/left/image_raw", "sensor_msgs/msg/Image", [_image(f, k, "left") for k, f in enumerate(scenes["left"])])])
    from_ros1, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode == 0 and len(from_ros1) == FRAMES, done.stderr
    from_ros2, done = _measure(workspace, two, "--calibration", "bag")
    assert [r["area_m2"] for r in from_ros1] == [r["area_m2"] for r in from_ros2]
    assert [(r["stamp_sec"], r["frame"]) for r in from_ros1] == [(100 + k, f"left.bag#{k}") for k in range(FRAMES)]
    from veg_area_ros.bags import play_messages, play_topics  # `veg-area play` replays it as ROS 2 messages

    assert {t.name: t.replay_qos().reliability for t in play_topics(bag)} == {"/left/camera_info": "best_effort",
                                                                           "/left/image_raw": "best_effort"}
    replayed = [data for topic, _, data in play_messages(bag, ["/left/image_raw"])]
    assert replayed == [TYPES.serialize_cdr(_image(f, k, "left"), "sensor_msgs/msg/Image").tobytes()
                        for k, f in enumerate(scenes["left"])]

    runs = []
    for run, velocity in enumerate((0.1, 0.2, 0.3, 0.45)):
        area = 0.02 * velocity ** -0.3
        force = 0.5 * 998.2 * velocity**2 * area * 1.1 * velocity ** -0.2
        runs.append(workspace / f"run{run}.bag")
        vector = kinds["geometry_msgs/msg/Vector3"]
        with Ros1Writer(runs[-1]) as writer:
            topics = {name: writer.add_connection(f"/{name}", msgtype, typestore=ros1) for name, msgtype in (
                ("force", "geometry_msgs/msg/WrenchStamped"), ("velocity", "geometry_msgs/msg/TwistStamped"),
                ("projected_area", "geometry_msgs/msg/Vector3Stamped"))}
            for k in range(20):
                messages = {
                    "force": kinds["geometry_msgs/msg/WrenchStamped"](header=header(k), wrench=kinds[
                        "geometry_msgs/msg/Wrench"](force=vector(x=force, y=0.0, z=0.0), torque=vector(x=0.0, y=0.0,
                                                                                                       z=0.0))),
                    "velocity": kinds["geometry_msgs/msg/TwistStamped"](header=header(k), twist=kinds[
                        "geometry_msgs/msg/Twist"](linear=vector(x=velocity, y=0.0, z=0.0),
                                                   angular=vector(x=0.0, y=0.0, z=0.0))),
                    "projected_area": kinds["geometry_msgs/msg/Vector3Stamped"](
                        header=header(k), vector=vector(x=area, y=0.01 * area, z=0.0))}
                for name, message in messages.items():
                    writer.write(topics[name], (100 + k) * 10**9, ros1.serialize_ros1(message, message.__msgtype__))
    done = run_cli("vogel", *map(str, runs), "--json", "--plot", str(workspace / "v.png"))
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["exponent"] == pytest.approx(-0.5, abs=1e-9)


def test_a_calibration_file_of_another_camera_is_said_in_each_result(workspace, scenes):
    """The bag's camera_info is the right endoscope's, the file the left one's: each result says so (Af was
    -8 % without a word); the right camera's own file is silent."""
    bag = workspace / "right"
    write_bag(bag, "mcap", [
        ("/right/camera_info", "sensor_msgs/msg/CameraInfo", [_info(RIGHT, k, "right") for k in range(FRAMES)]),
        ("/right/image_raw", "sensor_msgs/msg/Image",
         [_image(frame, k, "right") for k, frame in enumerate(scenes["right"])])])
    write_calibration(workspace / "left.yaml", ENDOSCOPE, "left", {"medium": "air"})
    write_calibration(workspace / "right.yaml", RIGHT, "right", {"medium": "air"})
    wrong, done = _measure(workspace, bag, "--calibration", str(workspace / "left.yaml"))
    assert done.returncode == 0, done.stderr
    assert all(any(w.startswith("calibration of another camera") and "560.0 px" in w for w in row["warnings"])
               for row in wrong), wrong
    right, done = _measure(workspace, bag, "--calibration", str(workspace / "right.yaml"))
    assert done.returncode == 0, done.stderr
    assert not any(w.startswith("calibration of another camera") for row in right for w in row["warnings"])


@pytest.mark.timeout(300)
def test_a_bag_without_qos_metadata_replays_completely_into_a_recorder(tmp_path):
    """A bag written by other tools says nothing of its publishers' QoS: `veg-area play` offers what ROS offers
    for the type (sensor data for sensor_msgs) and waits until every replayed topic has a subscriber, so a
    `veg-area record` started beside it records every message (before: "12 messages replayed", the recorder
    closed with 0 and exit 0)."""
    from ros_harness import run_scenario
    from rosbags.rosbag2 import Reader

    from veg_area_ros.bags import play_topics

    bag = tmp_path / "foreign"
    frames = [np.full((24, 32, 3), 40 * k, np.uint8) for k in range(6)]
    write_bag(bag, "mcap", [
        ("/cam/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "cam") for k in range(6)]),
        ("/cam/image_raw", "sensor_msgs/msg/Image", [_image(frame, k, "cam") for k, frame in enumerate(frames)])])
    topics = play_topics(bag)
    assert all(not t.offered for t in topics)  # nothing recorded of the publishers' QoS
    assert {t.replay_qos().reliability for t in topics} == {"best_effort"}
    result = run_scenario("replay_into_recorder", tmp_path, timeout=200, bag=str(bag),
                          topics=["/cam/image_raw", "/cam/camera_info"], duration=25.0,
                          output=str(tmp_path / "recorded"))
    assert result["player_exit"] == 0, result["player_stderr"]
    assert result["recorder_exit"] == 0, result["recorder_stderr"]
    with Reader(tmp_path / "recorded") as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts == {"/cam/image_raw": 6, "/cam/camera_info": 6}, (counts, result["stamps"], result["player_stderr"],
                                                                   result["recorder_stderr"])


@pytest.mark.timeout(300)
def test_a_recorder_that_got_nothing_of_a_topic_says_so_and_fails(tmp_path):
    """A topic on the graph whose publisher never publishes: the recorder saw it and subscribed, received
    nothing, says which topic, and exits 1 (it closed with 0 messages and exit 0)."""
    from ros_harness import run_scenario

    result = run_scenario("replay_into_recorder", tmp_path, timeout=200, topics=["/cam/camera_info"],
                          duration=8.0, output=str(tmp_path / "recorded"), silent=True)
    assert result["recorder_exit"] == 1, result["recorder_stderr"]
    assert "no message recorded of /cam/camera_info" in result["recorder_stderr"], result["recorder_stderr"]


@pytest.mark.timeout(300)
def test_the_area_node_measures_image_transports_compressed_topic_and_the_recorder_keeps_it(tmp_path):
    """A driver publishing JPEG on image_raw/compressed: the area node started with image_transport:=compressed
    measures it, each Af the core's on the same JPEG decoded as a file is; the record node keeps the topic as
    CompressedImage (the JPEG bytes as published, not decoded), and the bag it wrote measures to the same Af."""
    from ros_harness import run_scenario
    from rosbags.rosbag2 import Reader

    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.classify import Classifier
    from veg_area_ros.sim.synthetic import scene_targets

    result = run_scenario("compressed_driver", tmp_path, seconds=12.0)
    assert len(result["areas"]) >= 5, result["log"]
    assert result["calibration_frames_looked"] >= 3, result["log"]  # the calibration node takes them too
    assert result["console_camera"].get("size") == "640x480", result["console_camera"]  # and the console shows them
    frame = cv2.imdecode(np.array(result["jpeg"], np.uint8), cv2.IMREAD_COLOR)
    core = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120)).measure(frame)
    assert all(abs(area / core.area_m2 - 1) <= core.weight_error_bound for area in result["areas"]), (
        result["areas"], core.area_m2)

    assert result["recorder_exit"] == 0, result["log"]
    bag = tmp_path / "recorded"
    with Reader(bag) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        jpegs = [TYPES.deserialize_cdr(data, "sensor_msgs/msg/CompressedImage").data.tobytes()
                 for connection, _, data in reader.messages() if connection.topic.endswith("/compressed")]
    assert types == {"/image_raw/compressed": "sensor_msgs/msg/CompressedImage",
                     "/camera_info": "sensor_msgs/msg/CameraInfo"}, types
    assert len(jpegs) >= 5 and set(jpegs) == {bytes(result["jpeg"])}, len(jpegs)
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    rows, done = _measure(tmp_path, bag, "--calibration", "bag")
    assert done.returncode == 0, done.stderr
    assert len(rows) == len(jpegs)
    # the recorder may match the image topic before camera_info: up to EARLY_FRAMES frames before the first
    # camera_info are measured with it (and say so), more are said as not measured, never measured without it
    first = next(k for k, row in enumerate(rows) if "area_m2" in row)
    assert all("no camera_info recorded before this frame" in row["error"] for row in rows[:first]), rows[:first]
    measured = rows[first:]
    assert len(measured) >= 5 and all("area_m2" in row for row in measured), rows
    assert all(abs(row["area_m2"] / core.area_m2 - 1) <= core.weight_error_bound for row in measured), (
        [row["area_m2"] for row in measured], core.area_m2)


def test_the_area_node_measures_image_transports_zstd_topic_losslessly_and_its_bag_too(tmp_path):
    """image_transport's zstd plugin (lossless, ROS 2 Jazzy on) on image_raw/zstd: the area node started with
    image_transport:=zstd measures each frame exactly as the core measures the raw frame (the calibration node
    takes them as well), and the bag the record node wrote of that topic measures to the same Af (it was "cannot
    be decoded")."""
    from ros_harness import run_scenario

    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.classify import Classifier
    from veg_area_ros.sim.synthetic import scene_targets

    result = run_scenario("compressed_driver", tmp_path, seconds=12.0, transport="zstd")
    assert len(result["areas"]) >= 5, result["log"]
    assert result["calibration_frames_looked"] >= 3, result["log"]  # the calibration node takes them too
    assert result["console_camera"].get("size") == "640x480", result["console_camera"]  # and the console shows them
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7)
    core = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120)).measure(frame)
    assert all(abs(area / core.area_m2 - 1) <= core.weight_error_bound for area in result["areas"]), (
        result["areas"], core.area_m2)
    assert result["recorder_exit"] == 0, result["log"]
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    rows, done = _measure(tmp_path, tmp_path / "recorded", "--calibration", "bag")
    assert done.returncode == 0, done.stderr
    measured = [row for row in rows if "area_m2" in row]
    assert len(measured) >= 5 and all(row["area_m2"] == measured[0]["area_m2"] for row in measured), rows
    assert abs(measured[0]["area_m2"] / core.area_m2 - 1) <= core.weight_error_bound, (measured[0], core.area_m2)


def test_calibrate_takes_one_camera_of_a_stereo_pairs_bag(workspace):
    """A calibration session recorded as a bag of both cameras of a stereo pair (OpenCV's real left and right
    photos): calibrate ended in a Traceback saying to pick --image-topic, an option it did not have. Now it is
    refused before any work naming the topics, and --image-topic picks a camera: its fit is the same photos'
    from a folder. --image-topic without a bag is refused."""
    left = sorted((TEST_DATA / "opencv-left").glob("*.jpg"))
    right = sorted((TEST_DATA / "opencv-right").glob("*.jpg"))
    bag = workspace / "stereo_session"
    write_bag(bag, "sqlite3", [
        ("/left/image_raw", "sensor_msgs/msg/Image",
         [_image(cv2.imread(str(p)), k, "left") for k, p in enumerate(left)]),
        ("/right/image_raw", "sensor_msgs/msg/Image",
         [_image(cv2.imread(str(p)), k, "right") for k, p in enumerate(right)])])
    board = ("--board", "chessboard:9x6:0.025", "--medium", "air", "--json")
    done = run_cli("calibrate", str(bag), *board, "-o", str(workspace / "pair.yaml"), cwd=workspace)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert "['/left/image_raw', '/right/image_raw']" in done.stderr.splitlines()[-1], done.stderr
    assert not (workspace / "pair.yaml").exists()
    fits = {}
    for name, source, options in [("bag", bag, ("--image-topic", "/right/image_raw")),
                                  ("folder", TEST_DATA / "opencv-right", ())]:
        done = run_cli("calibrate", str(source), *board, *options, "-o", str(workspace / f"{name}.yaml"),
                       cwd=workspace)
        assert done.returncode == 0, done.stderr
        fits[name] = json.loads(done.stdout)
    assert fits["bag"]["views_used"] == fits["folder"]["views_used"] >= 10
    for key in ("fx", "fy", "cx", "cy", "dist"):
        assert fits["bag"][key] == pytest.approx(fits["folder"][key], rel=1e-6, abs=1e-9), key
    done = run_cli("calibrate", str(TEST_DATA / "opencv-right"), *board, "--image-topic", "/right/image_raw", "-o",
                   str(workspace / "no_bag.yaml"), cwd=workspace)
    assert done.returncode == 2 and "the inputs hold no bag" in done.stderr, done.stderr


def test_calibrate_samples_a_long_bag_as_a_video_and_measure_refuses_video_step_on_it(workspace):
    """A calibration session's bag, the board held in each of 13 poses (OpenCV's real photos, 15 frames each):
    every frame was searched (a 3-minute session at 30 Hz is 5400 board searches), and a slowly moving board
    gave a view wherever it had moved 1 % of the diagonal, views many and correlated as a video's would be
    unsampled. Now a bag is sampled as a video is (about 60 frames, one in each run at a varying place): of 195
    frames 65 are searched, the same 13 poses as the photos, the same fit. `measure --video-step` on a bag, which
    ignored it, is refused."""
    photos = sorted((TEST_DATA / "opencv-left").glob("*.jpg"))
    held = [_image(cv2.imread(str(p)), k, "cam") for k, p in enumerate(photos) for _ in range(15)]
    bag = workspace / "session"
    write_bag(bag, "mcap", [("/cam/image_raw", "sensor_msgs/msg/Image", held)])
    board = ("--board", "chessboard:9x6:0.025", "--medium", "air", "--json")
    fits = {}
    for name, source in [("bag", bag), ("photos", TEST_DATA / "opencv-left")]:
        done = run_cli("calibrate", str(source), *board, "-o", str(workspace / f"{name}.yaml"), cwd=workspace)
        assert done.returncode == 0, done.stderr
        fits[name] = (json.loads(done.stdout), done.stderr)
    assert "65 frames: 13 views" in fits["bag"][1], fits["bag"][1]
    assert fits["bag"][0]["views_used"] == fits["photos"][0]["views_used"] == 13
    for key in ("fx", "fy", "cx", "cy", "dist"):
        assert fits["bag"][0][key] == pytest.approx(fits["photos"][0][key], rel=1e-6, abs=1e-9), key
    (workspace / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    _, done = _measure(workspace, bag, "--calibration", "none", "--video-step", "3")
    assert done.returncode == 2 and "the inputs are bags (every frame of a bag is measured" in done.stderr, (
        done.stderr)


def test_a_bag_of_video_packets_only_says_so_and_what_to_record(workspace):
    """theora_image_transport's packets (Ogg packets whose stream headers go once to each subscriber) are not
    decoded here (H.264 through ffmpeg_image_transport or Foxglove are: test_video_packet_bags). It said "image
    topics in the bag: []"; now it names the video topic and what to record instead."""
    from rosbags.typesys import get_types_from_msg

    store = get_typestore(Stores.ROS2_KILTED)
    store.register(get_types_from_msg("std_msgs/Header header\nuint8[] data\nint32 b_o_s\nint32 e_o_s\n"
                                      "int64 granulepos\nint64 packetno\n", "theora_image_transport/msg/Packet"))
    Packet = store.types["theora_image_transport/msg/Packet"]
    bag = workspace / "theora"
    with Writer(bag, version=Writer.VERSION_LATEST) as writer:
        connection = writer.add_connection("/camera/image_raw/theora", "theora_image_transport/msg/Packet",
                                           typestore=store)
        for k in range(3):
            packet = Packet(header=_header(k, "camera"), data=np.zeros(16, np.uint8), b_o_s=int(k == 0), e_o_s=0,
                            granulepos=k, packetno=k)
            writer.write(connection, (100 + k) * 10**9,
                         store.serialize_cdr(packet, "theora_image_transport/msg/Packet"))
    _, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert ("video packets (/camera/image_raw/theora (theora_image_transport/msg/Packet))"
            in done.stderr.splitlines()[-1]), done.stderr
    assert "image_raw/zstd" in done.stderr.splitlines()[-1]


def test_a_zstd_image_that_claims_other_rows_is_refused_naming_it():
    """zstd_image_transport's header says the rows' size: a frame whose rows inflate past it (a bomb, or another
    image's header) or fall short is refused with the reason, never decoded as far as it goes."""
    from backports import zstd

    from veg_area_ros.cdr import ImageMessageError, decode_compressed_image, encode_compressed_image

    frame = np.arange(48 * 64 * 3, dtype=np.uint8).reshape(48, 64, 3)

    def message(height: int, rows: bytes) -> bytes:
        data = struct.pack("<IIBII", height, 64, 0, 192, 4) + b"bgr8" + zstd.compress(rows, 3)
        return encode_compressed_image(data, "zstd", 1, 0, "camera")

    assert np.array_equal(decode_compressed_image(message(48, frame.tobytes())).pixels(), frame)
    for height, rows, said in [(40, frame.tobytes(), "hold more bytes, not its 192 x 40"),
                               (48, frame.tobytes()[:-192], "hold 9024 bytes, not its 192 x 48"),
                               (48, bytes(10**8), "hold more bytes")]:
        with pytest.raises(ImageMessageError, match=said):
            decode_compressed_image(message(height, rows)).pixels()


@pytest.mark.timeout(300)
def test_the_area_node_measures_a_16_bit_cameras_frames_and_says_the_depth(tmp_path):
    """A machine-vision driver's mono16 frames of a 12-bit sensor: the area node measures each as the core
    measures its 8-bit frame (the same Af), and each result's warnings say the depth it read them at; a frame
    the driver left unstamped says its result cannot be paired by time (it was silent)."""
    from ros_harness import run_scenario

    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.classify import Classifier
    from veg_area_ros.sim.synthetic import scene_targets

    result = run_scenario("mono16_driver", tmp_path, seconds=40.0)  # ends once 2 of each kind came
    stamps = [stamp for *_, stamp in result["results"]]
    assert sum(s == 0 for s in stamps) >= 2 and sum(s != 0 for s in stamps) >= 2, (stamps, result["log"])
    grey = np.array(result["grey"], np.uint8).reshape(480, 640)
    core = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier()).measure(grey)
    for area, warnings, stamp in result["results"]:
        assert area == pytest.approx(core.area_m2, rel=1e-12), (area, core.area_m2)
        assert any("read as 12-bit data" in warning for warning in warnings), warnings
        assert any(w.startswith("header stamp 0") for w in warnings) == (stamp == 0), (stamp, warnings)


def test_our_mcap_is_written_as_ros2_bag_record_writes_it(tmp_path):
    """Read by the `mcap` library (independent of rosbags and of this package) with CRC validation: every chunk
    zstd-compressed with its CRC, the data section's and the summary's CRC as the MCAP spec defines them (each
    recomputed here), publish times as given, the embedded rosbag2 metadata with the real distribution; a
    flipped byte is found."""
    import struct
    import zlib

    from mcap.reader import make_reader
    from mcap.stream_reader import StreamReader

    from veg_area_ros.bags import ROS_DISTRO, BagRecorder
    from veg_area_ros.cdr import encode_image

    recorder = BagRecorder(tmp_path / "bag")
    recorder.add_topic("/image_raw", "sensor_msgs/msg/Image")
    rng = np.random.default_rng(0)
    clean = render_scene(ENDOSCOPE, cube_scene(), 0.7, noise_sigma=0.0)
    for k in range(20):
        noisy = np.clip(clean + rng.normal(0, 3, clean.shape), 0, 255).astype(np.uint8)
        recorder.write("/image_raw", (k + 1) * 10**8, encode_image(noisy, 0, k, "cam"), publish_ns=(k + 1) * 10**8 - 7)
    recorder.close()
    path = next((tmp_path / "bag").glob("*.mcap"))
    with path.open("rb") as file:
        reader = make_reader(file, validate_crcs=True)
        summary = reader.get_summary()
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        times = [(m.log_time, m.publish_time) for _, _, m in reader.iter_messages()]
        metadata = [m.metadata["serialized_metadata"] for m in reader.iter_metadata()]
    assert times == [((k + 1) * 10**8, (k + 1) * 10**8 - 7) for k in range(20)]
    assert f"ros_distro: {ROS_DISTRO}" in metadata[0]
    # every topic's type hash, as ros2 bag record writes it (it was empty in the embedded metadata)
    embedded = yaml.safe_load(metadata[0])["topics_with_message_count"]
    assert embedded and all(t["topic_metadata"]["type_description_hash"] == TYPES.hash_rihs01(
        t["topic_metadata"]["type"]) for t in embedded), embedded
    records = list(StreamReader(path.open("rb"), validate_crcs=True).records)
    data_end = next(r for r in records if type(r).__name__ == "DataEnd")
    footer = next(r for r in records if type(r).__name__ == "Footer")
    data = path.read_bytes()
    assert data_end.data_section_crc == zlib.crc32(data[:footer.summary_start - 13])
    footer_at = len(data) - 8 - 29
    assert struct.unpack_from("<QQI", data, footer_at + 9) == (footer.summary_start, footer.summary_offset_start,
                                                               footer.summary_crc)
    assert footer.summary_crc == zlib.crc32(data[footer.summary_start:footer_at + 9 + 16])
    raw = 20 * clean.nbytes
    assert len(data) < 0.7 * raw, (len(data), raw)  # 3 DN of noise: about 0.54 of the raw frames
    flipped = bytearray(data)
    flipped[len(data) // 3] ^= 0xFF
    with pytest.raises(Exception, match=r"(?i)crc|compress|zstd|frame"):
        list(StreamReader(__import__("io").BytesIO(bytes(flipped)), validate_crcs=True).records)


def test_start_and_end_times_count_from_the_bags_first_image(workspace, scenes):
    """--start-time/--end-time are seconds after the bag's first image (they were epoch stamps, unlike what the
    docs said); an absolute stamp is unix:SECONDS or an ISO time; a range that holds no frame says both."""
    write_calibration(workspace / "left.yaml", ENDOSCOPE)
    bag = workspace / "timed"  # images stamped 100, 101, 102 s
    write_bag(bag, "mcap", [("/image_raw", "sensor_msgs/msg/Image",
                             [_image(frame, k, "cam") for k, frame in enumerate(scenes["left"])])])
    calibration = ("--calibration", str(workspace / "left.yaml"))
    for options, stamps in ((("--start-time", "1", "--end-time", "1.5"), [101]),
                            (("--start-time", "unix:101.5"), [102]),
                            (("--end-time", "1970-01-01T00:01:41Z"), [100, 101])):
        rows, done = _measure(workspace, bag, *calibration, *options)
        assert done.returncode == 0, done.stderr
        assert [row["stamp_sec"] for row in rows] == stamps, (options, rows)
    rows, done = _measure(workspace, bag, *calibration, "--start-time", "5")
    assert done.returncode == 1
    assert "no frame lies between --start-time 5 s and --end-time inf s (the frames lie 0.000 to 2.000 s after " \
           "their bag's first image, stamped 100.000 to 102.000 s)" in done.stderr


def test_the_af_plot_runs_in_seconds_from_the_first_frame():
    """A bag's Af(t) had an epoch axis (+1.7962316e9); now seconds since its first frame, the start as a date in
    the title; frames without time are numbered."""
    from veg_area_ros.cli.measure_job import series_axis

    rows = [{"time_s": 1796231648.811 + k / 10, "stamp_sec": 1796231648 + k // 10} for k in range(3)]
    times, title, label = series_axis(rows, "run")
    assert times == pytest.approx([0.0, 0.1, 0.2]) and label == "time since the first frame [s]"
    assert title == "Projected area, run, from 2026-12-02T17:14:08.811+00:00"
    assert series_axis([{"time_s": None}] * 2, "x") == ([0, 1], "Projected area, x", "frame")


def test_a_runs_last_line_is_its_mean_with_its_uncertainty_and_what_was_not_measured(workspace, scenes):
    """A single input ends with its mean Af ± the uncertainty of that mean (not the frame-to-frame sd, which is
    named as such), frames measured of read, and the frames not measured by reason (they left the summary's
    columns empty: here the first image is another camera's, by its frame_id)."""
    bag = workspace / "other_first"
    write_bag(bag, "mcap", [("/camera_info", "sensor_msgs/msg/CameraInfo",
                             [_info(ENDOSCOPE, k, "cam") for k in range(FRAMES)]),
                            ("/image_raw", "sensor_msgs/msg/Image",
                             [_image(frame, k, "cam" if k else "other") for k, frame in enumerate(scenes["left"])])])
    rows, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode == 0, done.stderr
    measured = [row["area_m2"] for row in rows if "area_m2" in row]
    assert len(measured) == FRAMES - 1
    line = next(line for line in done.stderr.splitlines() if line.startswith("Af = "))
    assert f"mean of {FRAMES - 1} of {FRAMES} frames and its uncertainty; frame-to-frame sd" in line
    assert "not measured: the camera_info on /camera_info is frame 'cam', the image on /image_raw frame" in line
    assert line.endswith(": 1 frame"), line
    mean, uncertainty = (float(v) for v in line[len("Af = "):].split(" m²")[0].split(" ± "))
    assert mean == pytest.approx(np.mean(measured), rel=1e-5)
    assert uncertainty > 10 * np.std(measured, ddof=1) / np.sqrt(len(measured))  # the shared terms, once


def test_playing_a_topic_the_bag_lacks_names_the_topics_it_has(workspace, scenes):
    """`veg-area play bag --topics /nope` said "(it has )": the topics listed were the ones asked for."""
    bag = workspace / "one_topic"
    write_bag(bag, "mcap", [("/image_raw", "sensor_msgs/msg/Image", [_image(scenes["left"][0], 0, "cam")])])
    done = run_cli("play", str(bag), "--topics", "/nope")
    assert done.returncode == 1 and "no topic /nope in the bag (it has /image_raw)" in done.stderr, done.stderr


@pytest.mark.parametrize("whose", ["this camera's", "another camera's", "none"])
def test_a_bags_recorded_calibration_metadata_gives_the_tone_curve(workspace, scenes, whose):
    """A bag that recorded camera_info/metadata beside camera_info (the nodes publish it; record it with the
    other topics) is measured with `--calibration bag` as the live area node measured it: the tone curve the
    metadata records, when it is this camera_info's calibration's, and said."""
    from veg_area_ros.calib_io import metadata_message

    recorded = {"medium": "air", "tone_curve": "srgb", "tone_curve_evidence": "judged on 12 views"}
    topics = [("/left/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in range(FRAMES)]),
              ("/left/image_raw", "sensor_msgs/msg/Image",
               [_image(frame, k, "left") for k, frame in enumerate(scenes["left"])])]
    if whose != "none":
        text = metadata_message(ENDOSCOPE if whose == "this camera's" else RIGHT, recorded)
        topics.insert(1, ("/left/camera_info/metadata", "std_msgs/msg/String", [TYPES.types["std_msgs/msg/String"](
            data=text)]))
    bag = workspace / "with_metadata"
    write_bag(bag, "mcap", topics)
    rows, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode == 0 and len(rows) == FRAMES, done.stderr
    wanted = "srgb" if whose == "this camera's" else "linear"
    assert {row["tone_curve"] for row in rows} == {wanted}, rows
    assert ("as the bag's camera_info/metadata records it (judged on 12 views)" in done.stderr) == (wanted == "srgb")


def test_a_bags_recorded_tone_curve_is_said_not_to_apply_to_the_green_index(workspace, scenes):
    """As for a calibration file: the excess-green index is read as it is, and the run says why it does not
    take the curve the bag's metadata records."""
    from veg_area_ros.calib_io import metadata_message

    text = metadata_message(ENDOSCOPE, {"medium": "air", "tone_curve": "srgb"})
    bag = workspace / "green"
    write_bag(bag, "mcap", [
        ("/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in range(FRAMES)]),
        ("/camera_info/metadata", "std_msgs/msg/String", [TYPES.types["std_msgs/msg/String"](data=text)]),
        ("/image_raw", "sensor_msgs/msg/Image", [_image(frame, k, "left") for k, frame in enumerate(scenes["left"])])])
    _, done = _measure(workspace, bag, "--calibration", "bag", "--object", "green")  # the grey cube: no object
    assert "the bag's camera_info/metadata records srgb, which does not apply to --object green" in done.stderr
    assert "as the bag's camera_info/metadata records it" not in done.stderr


@pytest.mark.parametrize("server", ["camera", "calibration"])
@pytest.mark.parametrize("tone_curve", ["srgb", "linear"])
def test_an_area_node_given_camera_info_reads_the_calibrations_tone_curve(tmp_path, server, tone_curve):
    """camera_info has no field for what a calibration file records beside the lens (the tone curve judged on
    its views, the medium, the distance): the node serving it publishes that on camera_info/metadata, and an
    area node with tone_curve auto and no calibration_file reads its frames with the curve the file records,
    as `veg-area measure` given the file does (it read them as grey levels before, whatever the file said). The
    file's edge trend with exposure comes the same way, and its covariance."""
    from ros_harness import run_scenario

    result = run_scenario("metadata", tmp_path, server=server, tone_curve=tone_curve, seconds=90.0)
    curves = result["tone_curves"]
    assert len(curves) >= 10, result["log"]
    first = curves.index(tone_curve)  # a frame measured before the metadata came is read as grey levels
    assert set(curves[first:]) == {tone_curve} and len(curves) - first >= 5, curves
    # the file's edge trend, learned under linear, comes along: the frames read as grey levels have their edges
    # moved back by it at their white level; those read through srgb say why it was not applied
    trends = result["edge_trends"]
    came = next(k for k, trend in enumerate(trends) if trend is not None)  # before the metadata: none
    assert len(trends) - came >= 5 and None not in trends[came:], trends
    for trend in trends[came:]:
        if tone_curve == "linear":
            assert trend["applied"] and trend["offset_px"] < 0 and trend["area_m2"] > 0, trend
        else:
            assert not trend["applied"] and "learned under the linear tone curve" in trend["reason"], trend
    # and the calibration's covariance: a term of the std from then on (none before)
    stds = result["calibration_stds"]
    assert all(std > 0 for std in stds[came:]) and all(std == 0 for std in stds[:came]), stds


def test_an_area_node_given_a_background_frame_counts_when_the_served_calibration_reads_better_counted(tmp_path):
    """area_mode auto with a background_file (which evens the light for the shares only), and a calibration
    served on camera_info whose metadata says its views read better counted: the node measured nothing when the
    metadata came first (the calibration was 'not applied' for good) and kept the shares against the
    calibration's evidence when it came after. It now counts, as it does for a calibration_file at start, and
    its log says the background frame was left out and why."""
    from ros_harness import run_scenario

    result = run_scenario("metadata", tmp_path, server="calibration", tone_curve="linear", area_mode="count",
                          background=True, seconds=90.0)
    modes = result["area_modes"]
    assert len(modes) >= 10, result["log"]
    first = modes.index("count")  # a frame measured before the metadata came reads the shares
    assert set(modes[first:]) == {"count"} and len(modes) - first >= 5, modes
    lines = [line for line in result["whole_log"].splitlines() if "parameter background_file:" in line]
    assert lines and "counts whole pixels here" in lines[0], result["log"]
    assert "not applied" not in result["whole_log"], result["log"]


def test_an_area_node_given_levels_counts_when_the_served_calibration_reads_better_counted(tmp_path):
    """The same with the levels parameter (the shares' object and background levels, which counting does not
    read): the node counts, says the levels were left out and why, and sets the parameter back to [0.0]."""
    from ros_harness import run_scenario

    result = run_scenario("metadata", tmp_path, server="calibration", tone_curve="linear", area_mode="count",
                          levels=True, seconds=90.0)
    modes = result["area_modes"]
    assert len(modes) >= 10, result["log"]
    first = modes.index("count")
    assert set(modes[first:]) == {"count"} and len(modes) - first >= 5, modes
    lines = [line for line in result["whole_log"].splitlines() if "parameter levels:" in line]
    assert lines and "counts whole pixels here" in lines[0] and "set back to [0.0]" in lines[0], result["log"]
    assert "not applied" not in result["whole_log"], result["log"]


def test_a_driver_that_does_not_stamp_its_images_is_timed_by_the_bag_and_says_so(workspace, scenes):
    """A camera driver that leaves header.stamp at 0: every row was at time 0 (a flat Af(t), no pairing with the
    flume's instruments); each frame is timed by when the bag received it, and its row says why."""
    zero = TYPES.types["std_msgs/msg/Header"](stamp=TYPES.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                                              frame_id="left")
    infos, images = [], []
    for k, frame in enumerate(scenes["left"]):
        infos.append(dataclasses.replace(_info(ENDOSCOPE, k, "left"), header=zero))
        images.append(dataclasses.replace(_image(frame, k, "left"), header=zero))
    bag = workspace / "unstamped"
    write_bag(bag, "mcap", [("/camera_info", "sensor_msgs/msg/CameraInfo", infos),
                            ("/image_raw", "sensor_msgs/msg/Image", images)])
    rows, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode == 0 and len(rows) == FRAMES, done.stderr
    received = [(100 + k) * 10**9 + 1 for k in range(FRAMES)]  # write_bag's receive times of the images
    assert [row["time_s"] for row in rows] == pytest.approx([t / 1e9 for t in received])
    assert all(any(w.startswith("header stamp 0") for w in row["warnings"]) for row in rows)
    stamped, done = _measure(workspace, _stamped_copy(workspace, scenes), "--calibration", "bag")
    assert not any(w.startswith("header stamp 0") for row in stamped for w in row["warnings"])


def _stamped_copy(workspace: Path, scenes) -> Path:
    bag = workspace / "stamped"
    write_bag(bag, "mcap", [
        ("/camera_info", "sensor_msgs/msg/CameraInfo", [_info(ENDOSCOPE, k, "left") for k in range(FRAMES)]),
        ("/image_raw", "sensor_msgs/msg/Image", [_image(f, k, "left") for k, f in enumerate(scenes["left"])])])
    return bag


def test_an_mcap_that_is_not_a_ros2_recording_is_named_as_such(workspace):
    """Foxglove's recorder writes MCAP with its own schemas (JSON or protobuf, no sensor_msgs): it was "not a
    readable rosbag2 bag (Profile is not ros2.)" with advice to rebuild a killed recording."""
    from mcap.writer import Writer as McapWriter

    path = workspace / "foxglove.mcap"
    with path.open("wb") as file:
        writer = McapWriter(file)
        writer.start(profile="", library="foxglove-recorder")
        schema = writer.register_schema(name="foxglove.RawImage", encoding="jsonschema", data=b'{"type": "object"}')
        channel = writer.register_channel(topic="/camera/image", message_encoding="json", schema_id=schema)
        writer.add_message(channel_id=channel, log_time=1, publish_time=1, data=b'{"width": 2}')
        writer.finish()
    rows, done = _measure(workspace, path, "--calibration", "none")
    assert done.returncode == 1 and not rows
    assert "an MCAP file of profile '', not a ROS 2 recording" in done.stderr, done.stderr
    assert "bag-recover" not in done.stderr


def test_frames_recorded_before_the_first_camera_info_are_measured_with_it_and_say_so(workspace, scenes):
    """`ros2 bag record` started between a driver's image and its camera_info: the first frames came before
    any camera_info and were "no camera_info recorded before this frame". The frame whose camera_info (the same
    stamp) is recorded just after it is measured as any other; one whose own was not recorded gets the first one
    and says so; a bag with no camera_info at all still measures nothing with `--calibration bag`."""
    frames = scenes["left"]
    bag = workspace / "late_info"
    with Writer(bag, version=Writer.VERSION_LATEST) as writer:
        image = writer.add_connection("/cam/image_raw", "sensor_msgs/msg/Image", typestore=TYPES)
        info = writer.add_connection("/cam/camera_info", "sensor_msgs/msg/CameraInfo", typestore=TYPES)
        for k, frame in enumerate(frames):  # image k, then its camera_info; the first one's was not recorded
            writer.write(image, (100 + k) * 10**9, TYPES.serialize_cdr(_image(frame, k, "cam"),
                                                                   "sensor_msgs/msg/Image"))
            if k:
                writer.write(info, (100 + k) * 10**9 + 1000, TYPES.serialize_cdr(
                    _info(ENDOSCOPE, k, "cam"), "sensor_msgs/msg/CameraInfo"))
    rows, done = _measure(workspace, bag, "--calibration", "bag")
    assert done.returncode == 0, done.stderr
    assert [row.get("error", "") for row in rows] == [""] * FRAMES
    early = [any("no camera_info was recorded before this frame" in w for w in row["warnings"]) for row in rows]
    assert early == [True] + [False] * (FRAMES - 1)
    assert all(abs(row["area_m2"] / cube_scene().true_area_m2 - 1) < 0.005 for row in rows)
    none = workspace / "no_info"
    write_bag(none, "mcap", [("/cam/image_raw", "sensor_msgs/msg/Image",
                              [_image(f, k, "cam") for k, f in enumerate(frames)])])
    rows, done = _measure(workspace, none, "--calibration", "bag")
    assert done.returncode != 0 and "camera_info" in done.stderr, done.stderr


FOXGLOVE_IMAGES = {
    "foxglove_msgs/msg/RawImage": ("builtin_interfaces/Time timestamp\nstring frame_id\nuint32 width\nuint32 height\n"
                                   "string encoding\nuint32 step\nuint8[] data\n"),
    "foxglove_msgs/msg/CompressedImage": ("builtin_interfaces/Time timestamp\nstring frame_id\nuint8[] data\n"
                                          "string format\n"),
}


def test_foxglove_raw_and_compressed_images_are_measured_as_rosbag2s_own(workspace, scenes):
    """Foxglove's own image schemas recorded in a ROS 2 bag (its SDK and bridge write them): RawImage (width
    before height, `rgb8`, `uyvy`...) gives the Af of the same sensor_msgs/Image frames, CompressedImage that of
    the same JPEG; the frames keep their timestamps."""
    from rosbags.typesys import get_types_from_msg

    store = get_typestore(Stores.ROS2_KILTED)
    for name, text in FOXGLOVE_IMAGES.items():
        store.register(get_types_from_msg(text, name))
    frames = scenes["left"]
    jpegs = [cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 85])[1].tobytes() for frame in frames]

    def stamp(k: int):
        return store.types["builtin_interfaces/msg/Time"](sec=100 + k, nanosec=250_000_000)

    raw = [store.types["foxglove_msgs/msg/RawImage"](
        timestamp=stamp(k), frame_id="cam", width=f.shape[1], height=f.shape[0], encoding="rgb8",
        step=3 * f.shape[1], data=np.ascontiguousarray(f[:, :, ::-1]).ravel()) for k, f in enumerate(frames)]
    compressed = [store.types["foxglove_msgs/msg/CompressedImage"](
        timestamp=stamp(k), frame_id="cam", data=np.frombuffer(jpeg, np.uint8), format="jpeg")
        for k, jpeg in enumerate(jpegs)]
    rows = {}
    for name, msgtype, messages in [("foxglove_raw", "foxglove_msgs/msg/RawImage", raw),
                                    ("foxglove_jpeg", "foxglove_msgs/msg/CompressedImage", compressed),
                                    ("ros_raw", "sensor_msgs/msg/Image",
                                     [_image(f, k, "cam") for k, f in enumerate(frames)]),
                                    ("ros_jpeg", "sensor_msgs/msg/CompressedImage",
                                     [_compressed(jpeg, k, "cam") for k, jpeg in enumerate(jpegs)])]:
        bag = workspace / name
        with Writer(bag, version=Writer.VERSION_LATEST) as writer:
            connection = writer.add_connection("/cam/image", msgtype, typestore=store)
            for k, message in enumerate(messages):
                writer.write(connection, (100 + k) * 10**9 + 300_000_000, store.serialize_cdr(message, msgtype))
        write_calibration(workspace / "cam.yaml", ENDOSCOPE, "cam", {"medium": "air"})
        measured, done = _measure(workspace, bag, "--calibration", str(workspace / "cam.yaml"))
        assert done.returncode == 0, done.stderr
        rows[name] = measured
    assert [r["area_m2"] for r in rows["foxglove_raw"]] == [r["area_m2"] for r in rows["ros_raw"]]
    assert [r["area_m2"] for r in rows["foxglove_jpeg"]] == [r["area_m2"] for r in rows["ros_jpeg"]]
    assert len(rows["foxglove_raw"]) == FRAMES
    assert [r["time_s"] for r in rows["foxglove_raw"]] == [pytest.approx(100.25 + k) for k in range(FRAMES)]


def test_a_bag_without_the_asked_topics_is_said_so_without_reading_every_message(workspace, scenes):
    """rosbags reads every message for an empty list of connections: a camera-only bag gave `vogel` "a topic
    has another message type than expected", and measuring a bag with no camera_info with a calibration file
    ended in a Traceback (the images were read as camera_info)."""
    from veg_area_ros.bags import BagError, bag_camera_info, bag_run

    bag = workspace / "camera_only"
    write_bag(bag, "mcap", [("/cam/image_raw", "sensor_msgs/msg/Image", [_image(scenes["left"][0], 0, "cam")])])
    with pytest.raises(BagError, match="no messages on /force"):
        bag_run(bag)
    assert bag_camera_info(bag) is None
