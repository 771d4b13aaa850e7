"""numpy <-> sensor_msgs/Image and BrownCamera <-> sensor_msgs/CameraInfo (no cv_bridge), and the rclpy class of
a message type named as in a bag."""

from __future__ import annotations

import importlib

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import CameraInfo, Image

from ..camera_info import camera_info_fields, info_to_camera
from ..camera_model import BrownCamera
from ..cdr import ImageMessageError, encode_image, frame_pixels, image_layout

__all__ = ["ImageMessageError", "camera_to_info", "image_bytes", "image_to_msg", "info_to_camera", "message_class",
           "msg_to_image"]


def image_bytes(image: np.ndarray, stamp: Time, frame_id: str) -> bytes:
    """A serialized sensor_msgs/Image for `publisher.publish(bytes)`: one copy of the pixels, no Python
    message object (the bytes are rclpy's own, tested in test_cdr)."""
    return encode_image(image, stamp.sec, stamp.nanosec, frame_id)


def image_to_msg(image: np.ndarray, stamp: Time, frame_id: str) -> Image:
    """bgr8 for (H, W, 3) uint8, mono8 for (H, W) uint8."""
    encoding, step = image_layout(image)
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = image.shape[:2]
    msg.encoding, msg.is_bigendian, msg.step = encoding, 0, step
    msg.data = np.ascontiguousarray(image).tobytes()  # bytes: rclpy's fast path into the message
    return msg


def msg_to_image(msg: Image) -> np.ndarray:
    """A BGR (H, W, 3) or grey (H, W) uint8 view of the message; rgb8 is converted to BGR."""
    return frame_pixels(msg.data, msg.height, msg.width, msg.encoding, msg.step)


def camera_to_info(camera: BrownCamera, frame_id: str = "camera", stamp: Time | None = None) -> CameraInfo:
    """plumb_bob CameraInfo; the projection matrix is the ideal camera (what `image_rect` is in)."""
    msg = CameraInfo()
    if stamp is not None:
        msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    fields = camera_info_fields(camera)
    msg.width, msg.height, msg.distortion_model = fields["width"], fields["height"], fields["distortion_model"]
    msg.d, msg.k, msg.r, msg.p = fields["d"], fields["k"], fields["r"], fields["p"]
    return msg


def message_class(msgtype: str):
    """'sensor_msgs/msg/Image' -> the rclpy message class."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)
