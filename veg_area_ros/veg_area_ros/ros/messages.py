"""numpy <-> sensor_msgs/Image and BrownCamera <-> sensor_msgs/CameraInfo (no cv_bridge), a frame's result as
veg_area_msgs/ProjectedArea (and the deprecated Vector3Stamped), and the rclpy class of a message type named as
in a bag."""

from __future__ import annotations

import importlib

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import CameraInfo, CompressedImage, Image

from veg_area_msgs.msg import CalibrationProgress, ProjectedArea

from ..area_result import AreaResult
from ..camera_info import camera_info_fields, info_to_camera
from ..camera_model import BrownCamera
from ..cdr import (
    CompressedImageFields,
    ImageFields,
    ImageMessageError,
    decode_compressed_image,
    decode_image,
    encode_image,
    frame_pixels,
    image_layout,
)

__all__ = ["ImageMessageError", "camera_to_info", "image_bytes", "image_to_msg", "info_to_camera", "message_class",
           "msg_to_image", "progress_as_dict", "progress_message", "projected_area", "projected_area_vector"]


# image_transport's plugins whose frames the nodes take: raw Image on image_raw, and CompressedImage on
# image_raw/<plugin> (JPEG or PNG from `compressed`, lossless rows from `zstd`)
IMAGE_TRANSPORTS = ("raw", "compressed", "zstd")
IMAGE_TRANSPORT_HELP = ("How the camera's images come: 'raw' (sensor_msgs/Image on image_raw), 'compressed' "
                        "(CompressedImage, JPEG or PNG, on image_raw/compressed) or 'zstd' (lossless, on "
                        "image_raw/zstd), as image_transport's plugins publish them.")


def transported_image(transport: str) -> tuple[type, str]:
    """The message type and topic of the camera's images through an image_transport plugin."""
    if transport not in IMAGE_TRANSPORTS:
        raise ValueError(f"image_transport must be one of {', '.join(IMAGE_TRANSPORTS)}, got {transport!r}")
    return (Image, "image_raw") if transport == "raw" else (CompressedImage, f"image_raw/{transport}")


def decode_transported(transport: str, data: bytes) -> ImageFields | CompressedImageFields:
    """A serialized image message of `transported_image(transport)` as its fields (`pixels()` gives the frame)."""
    return decode_image(data) if transport == "raw" else decode_compressed_image(data)

FRAME_COUNTS = ("frames_received", "frames_skipped", "frames_lost", "frames_measured")


def projected_area(result: AreaResult, stamp: Time, frame_id: str, calibration_source: str,
                   frames: dict[str, int | None] | None = None) -> ProjectedArea:
    """A frame's Af with every field named: the std and its terms, the classification, the calibration used,
    the warnings and the node's frame counts (`frames`, FRAME_COUNTS; a count not known or not given: -1); the
    rest of the record stays in projected_area/info's JSON."""
    msg = ProjectedArea()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    msg.area_m2, msg.area_std_m2 = float(result.area_m2), float(result.area_std_m2)
    msg.scale_std_m2, msg.threshold_std_m2 = float(result.scale_std_m2), float(result.threshold_std_m2)
    msg.discretisation_std_m2, msg.levels_std_m2 = float(result.discretisation_std_m2), float(result.levels_std_m2)
    msg.plane_offset_std_m2, msg.exposure_std_m2 = float(result.plane_offset_std_m2), float(result.exposure_std_m2)
    msg.glare_std_m2, msg.edge_trend_std_m2 = float(result.glare_std_m2), float(result.edge_trend_std_m2)
    msg.calibration_std_m2 = float(result.calibration_std_m2)
    msg.edge_trend_m2 = result.edge_trend_m2
    msg.pixel_count, msg.count_area_m2 = int(result.pixel_count), float(result.count_area_m2)
    msg.threshold, msg.area_mode, msg.tone_curve = float(result.threshold), result.area_mode, result.tone_curve
    msg.subpixel_applied, msg.calibrated = bool(result.subpixel_applied), bool(result.calibrated)
    msg.calibration_source = calibration_source
    msg.warnings = [str(w) for w in result.warnings]
    for name in FRAME_COUNTS:
        count = (frames or {}).get(name)
        setattr(msg, name, -1 if count is None else int(count))
    return msg


def progress_message(state: dict, stamp: Time, frame_id: str) -> CalibrationProgress:
    """The calibration node's progress (its fields as `progress_as_dict` gives them back) as a message."""
    msg = CalibrationProgress()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    msg.message = str(state.get("message", ""))
    for name in ("views_kept", "frames_seen", "frames_looked", "frames_skipped", "feedback_published",
                 "coverage_cells"):
        setattr(msg, name, int(state.get(name) or 0))
    msg.coverage = float(state.get("coverage") or 0.0)
    msg.fitted = bool(state.get("fitted"))
    msg.rms_px = float("nan") if state.get("rms_px") is None else float(state["rms_px"])
    msg.still_needed = str(state.get("still_needed") or "")
    bars, rejected = state.get("bars") or {}, state.get("rejected") or {}
    msg.bar_names, msg.bar_values = [str(k) for k in bars], [float(v) for v in bars.values()]
    msg.rejected_reasons, msg.rejected_counts = [str(k) for k in rejected], [int(v) for v in rejected.values()]
    msg.warnings = [str(w) for w in state.get("warnings") or []]
    return msg


def progress_as_dict(msg: CalibrationProgress) -> dict:
    """A progress message as plain data (the console's page and JSON readers): bars and rejections as
    name -> value, the RMS None before any fit, still_needed None when nothing is."""
    rms = float(msg.rms_px)
    return {"message": msg.message, "views_kept": msg.views_kept, "frames_seen": msg.frames_seen,
            "frames_looked": msg.frames_looked, "frames_skipped": msg.frames_skipped,
            "feedback_published": msg.feedback_published, "coverage": msg.coverage,
            "coverage_cells": msg.coverage_cells, "fitted": msg.fitted, "rms_px": None if rms != rms else rms,
            "still_needed": msg.still_needed or None,
            "bars": dict(zip(msg.bar_names, (float(v) for v in msg.bar_values), strict=True)),
            "rejected": dict(zip(msg.rejected_reasons, (int(v) for v in msg.rejected_counts), strict=True)),
            "warnings": list(msg.warnings)}


def projected_area_vector(result: AreaResult, stamp: Time, frame_id: str) -> Vector3Stamped:
    """The earlier form of the result, kept for one release on projected_area/vector: x = Af m², y = its std m²,
    z = object pixels."""
    msg = Vector3Stamped()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    msg.vector.x, msg.vector.y, msg.vector.z = result.area_m2, result.area_std_m2, float(result.pixel_count)
    return msg


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


def message_class(msgtype: str) -> type:
    """'sensor_msgs/msg/Image' -> the rclpy message class."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)
