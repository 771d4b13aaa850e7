"""numpy <-> sensor_msgs/Image and BrownCamera <-> CameraInfo, checked against rclpy's own serialization."""

from __future__ import annotations

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, Image

from veg_area_ros.ros.messages import (
    ImageMessageError,
    camera_to_info,
    image_to_msg,
    info_to_camera,
    msg_to_image,
)
from veg_area_ros.sim.synthetic import ENDOSCOPE


@pytest.mark.parametrize("shape", [(480, 640, 3), (481, 641, 3), (7, 5), (1, 1, 3)])
def test_image_round_trip_through_serialization(shape):
    image = np.random.default_rng(0).integers(0, 256, shape, dtype=np.uint8)
    msg = image_to_msg(image, Time(sec=12, nanosec=34), "cam")
    back = deserialize_message(serialize_message(msg), Image)
    assert back.encoding == ("bgr8" if len(shape) == 3 else "mono8") and back.header.frame_id == "cam"
    assert np.array_equal(msg_to_image(back), image)


def test_padded_rows_and_rgb_are_read_right():
    image = np.random.default_rng(1).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    padded = np.zeros((5, 32), np.uint8)
    padded[:, :21] = image[..., ::-1].reshape(5, 21)  # rgb8, step 32
    msg = Image(height=5, width=7, encoding="rgb8", step=32, data=padded.tobytes())
    assert np.array_equal(msg_to_image(msg), image)


@pytest.mark.parametrize("msg,problem", [
    (Image(height=4, width=4, encoding="16UC1", step=8, data=bytes(32)), "depth cameras"),
    (Image(height=4, width=4, encoding="32FC1", step=16, data=bytes(64)), "not supported .float"),
    (Image(height=4, width=4, encoding="mono16", step=4, data=bytes(16)), "shorter"),
    (Image(height=0, width=4, encoding="mono8", step=4, data=b""), "empty"),
    (Image(height=4, width=4, encoding="bgr8", step=4, data=bytes(16)), "shorter"),
    (Image(height=4, width=4, encoding="mono8", step=4, data=bytes(15)), "15 bytes"),
])
def test_bad_images_say_why(msg, problem):
    with pytest.raises(ImageMessageError, match=problem):
        msg_to_image(msg)


def test_camera_info_round_trip_and_refusals():
    info = deserialize_message(serialize_message(camera_to_info(ENDOSCOPE, "cam")), CameraInfo)
    camera = info_to_camera(info)
    for name, value in ENDOSCOPE.parameters().items():
        assert camera.parameters()[name] == pytest.approx(value, rel=1e-12, abs=1e-15)
    assert info.p[0] == pytest.approx(ENDOSCOPE.fx) and info.p[2] == pytest.approx((640 - 1) / 2)
    with pytest.raises(ValueError, match="uncalibrated"):
        info_to_camera(CameraInfo(width=640, height=480))
    info.d = [float("nan")] * 5
    with pytest.raises(ValueError, match="not finite"):
        info_to_camera(info)
    info.d = [0.0] * 5
    info.width = 100_000  # a corrupt size would have the area node allocate pixel maps of 10^10 px
    with pytest.raises(ValueError, match="beyond any camera"):
        info_to_camera(info)
