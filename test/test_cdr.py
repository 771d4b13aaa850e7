"""The CDR codec for sensor_msgs/Image and CameraInfo byte for byte against rclpy's own
serialization (except alignment padding, which rclpy leaves uninitialised), and its refusals."""

from __future__ import annotations

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, Image

from veg_area_ros.bit_depth import StreamDepth
from veg_area_ros.cdr import (
    CameraInfoFields,
    Header,
    ImageMessageError,
    _camera_info_writer,
    _image_writer,
    decode_camera_info,
    decode_image,
    encode_image,
    restamp,
    unstamped,
)
from veg_area_ros.ros.messages import camera_to_info, image_to_msg, msg_to_image
from veg_area_ros.sim.synthetic import DSLR, ENDOSCOPE


def same_except_padding(ours, writer, theirs: bytes) -> None:
    assert len(ours) == len(theirs)
    padding = {i for span in writer.padding for i in span}
    differing = [i for i in range(min(len(ours), 4096)) if ours[i] != theirs[i] and i not in padding]
    assert differing == [], differing[:10]
    assert ours[4096:] == theirs[4096:]  # the pixels (no padding after the data's length)


frame_ids = st.text(alphabet=st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12)


@settings(max_examples=60, deadline=None)
@given(height=st.integers(1, 9), width=st.integers(1, 13), colour=st.booleans(), frame_id=frame_ids,
       sec=st.integers(-2**31, 2**31 - 1), nanosec=st.integers(0, 999_999_999))
def test_image_bytes_are_rclpys(height, width, colour, frame_id, sec, nanosec):
    shape = (height, width, 3) if colour else (height, width)
    image = np.random.default_rng(height * width).integers(0, 256, shape, dtype=np.uint8)
    ours = encode_image(image, sec, nanosec, frame_id)
    theirs = serialize_message(image_to_msg(image, Time(sec=sec, nanosec=nanosec), frame_id))
    same_except_padding(ours, _image_writer(image, sec, nanosec, frame_id), theirs)
    fields = decode_image(theirs)
    assert (fields.header, fields.encoding) == (Header(sec, nanosec, frame_id), "bgr8" if colour else "mono8")
    assert np.array_equal(fields.pixels(), image)
    assert np.array_equal(msg_to_image(deserialize_message(ours, Image)), image)


@pytest.mark.parametrize("encoding, channels, step_pad", [("rgb8", 3, 5), ("mono8", 1, 3), ("bgr8", 3, 0)])
def test_foreign_images_with_padded_rows_decode_like_rclpys(encoding, channels, step_pad):
    rng = np.random.default_rng(3)
    height, width = 5, 7
    step = width * channels + step_pad
    msg = Image(height=height, width=width, encoding=encoding, step=step,
                data=rng.integers(0, 256, height * step, dtype=np.uint8).tobytes())
    msg.header.frame_id = "odd"
    assert np.array_equal(decode_image(serialize_message(msg)).pixels(), msg_to_image(msg))


def test_decoding_a_camera_frame_is_a_view_not_a_copy():
    image = np.zeros((2592, 3872, 3), np.uint8)
    buffer = encode_image(image, 1, 2, "dslr")
    pixels = decode_image(buffer).pixels()
    assert pixels.shape == image.shape and not pixels.flags.owndata and not pixels.flags.writeable


@pytest.mark.parametrize("camera", [ENDOSCOPE, DSLR])
@pytest.mark.parametrize("frame_id", ["", "cam", "camera_optical_frame"])
def test_camera_info_bytes_are_rclpys(camera, frame_id):
    msg = camera_to_info(camera, frame_id, Time(sec=5, nanosec=6))
    msg.binning_x, msg.roi.width, msg.roi.do_rectify = 2, 17, True
    theirs = serialize_message(msg)
    fields = decode_camera_info(theirs)
    assert fields == CameraInfoFields(Header(5, 6, frame_id), msg.height, msg.width, "plumb_bob", list(msg.d),
                                      list(msg.k), list(msg.r), list(msg.p), (2, 0), (0, 0, 0, 17, True))
    writer = _camera_info_writer(fields)
    same_except_padding(writer.bytes(), writer, theirs)
    empty = CameraInfo()
    assert decode_camera_info(serialize_message(empty)).d == []


def test_restamping_and_comparing_without_the_stamp():
    """The camera node serializes camera_info once and restamps it per frame; the area node skips a
    camera_info whose content (all but the stamp) it has seen."""
    msg = camera_to_info(ENDOSCOPE, "cam", Time(sec=1, nanosec=2))
    serialized = serialize_message(msg)
    msg.header.stamp = Time(sec=-3, nanosec=999_999_999)
    assert restamp(serialized, -3, 999_999_999) == serialize_message(msg)
    assert unstamped(serialized) == unstamped(serialize_message(msg))
    msg.k[0] += 1e-9
    assert unstamped(serialized) != unstamped(serialize_message(msg))
    msg.header.frame_id = "other"
    msg.k[0] -= 1e-9
    assert unstamped(serialized) != unstamped(serialize_message(msg))
    with pytest.raises(ImageMessageError, match="too short"):
        restamp(b"\x00\x01\x00\x00\x01", 0, 0)


@pytest.mark.parametrize("mangle, problem", [
    (lambda b: b[:40], "ends"),
    (lambda b: b"\x00\x00" + b[2:], "not little-endian CDR"),
    (lambda b: b[:-1], "early"),
])
def test_broken_bytes_are_refused_with_a_reason(mangle, problem):
    buffer = encode_image(np.zeros((4, 4), np.uint8), 0, 0, "cam")
    with pytest.raises(ImageMessageError, match=problem):
        decode_image(mangle(buffer)).pixels()


def test_bad_image_fields_are_refused_like_messages():
    msg = Image(height=4, width=4, encoding="32FC1", step=16, data=bytes(64))
    with pytest.raises(ImageMessageError, match="not supported"):
        decode_image(serialize_message(msg)).pixels()


def test_a_16_bit_streams_depth_is_held_so_a_darker_frame_is_not_read_brighter():
    """A 12-bit camera's frame whose values stay under 1024 would pass for 10-bit data on its own (read four
    times brighter); a stream that has shown 12-bit values keeps reading it at 12 bits, and each says so."""
    bright = np.full((4, 4), 3000, np.uint16)
    dark = np.full((4, 4), 800, np.uint16)

    def fields(image: np.ndarray) -> object:
        msg = Image(height=4, width=4, encoding="mono16", step=8, data=image.astype("<u2").tobytes())
        return decode_image(serialize_message(msg))

    alone: list[str] = []
    assert fields(dark).pixels(notes=alone).max() == 800 >> 2
    assert "read as 10-bit data" in alone[0]
    stream, notes = StreamDepth(), []
    assert fields(bright).pixels(stream, notes).max() == 3000 >> 4
    assert fields(dark).pixels(stream, notes).max() == 800 >> 4
    assert stream.bits == 12 and all("read as 12-bit data" in note for note in notes) and len(notes) == 2
    assert "reached 3000" in notes[1]
    full = np.full((4, 4), 60000, np.uint16)  # 16-bit data: read as OpenCV and cv_bridge read it, nothing said
    said: list[str] = []
    assert fields(full).pixels(StreamDepth(), said).max() == 60000 >> 8 and not said


GOOD_IMAGE = encode_image(np.zeros((5, 7, 3), np.uint8), 1, 2, "cam")
GOOD_INFO = _camera_info_writer(CameraInfoFields(
    Header(1, 2, "cam"), 480, 640, "plumb_bob", [0.1] * 5, [500, 0, 320, 0, 500, 240, 0, 0, 1],
    [1, 0, 0, 0, 1, 0, 0, 0, 1], [500, 0, 320, 0, 0, 500, 240, 0, 0, 0, 1, 0])).bytes()


@settings(max_examples=300, deadline=None)
@given(image=st.booleans(), cut=st.integers(0, 400), edits=st.lists(st.tuples(st.integers(0, 400),
       st.integers(0, 255)), max_size=6), tail=st.binary(max_size=20))
def test_mangled_bytes_give_a_frame_or_a_reason_never_another_error(image, cut, edits, tail):
    """Whatever a foreign publisher or a damaged bag hands over: a frame (calibration), or ValueError saying why."""
    from veg_area_ros.camera_info import info_to_camera

    data = bytearray(GOOD_IMAGE if image else GOOD_INFO)
    for position, value in edits:
        if position < len(data):
            data[position] = value
    data = bytes(data[:cut]) + tail
    try:
        if image:
            frame = decode_image(data).pixels()
            assert frame.dtype == np.uint8 and frame.ndim in (2, 3)
        else:
            assert info_to_camera(decode_camera_info(data)).width > 0
    except ValueError:
        pass
