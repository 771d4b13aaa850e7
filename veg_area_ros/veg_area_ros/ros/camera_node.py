"""camera_node: publishes `image_raw` (sensor_msgs/Image, bgr8) and, when it has a calibration,
`camera_info`, from the synthetic endoscope (default), a device, a video file, or an image folder/glob.
Frames go out pre-serialized (veg_area_ros.cdr): one copy from the camera's buffer to the wire."""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING

from rclpy.node import Node
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String

from ..calib_io import camera_info_url_to_path, metadata_message, read_calibration
from ..cdr import restamp
from ..sources import SYNTHETIC_SCENES, DeviceSource, SourceError, open_source
from .health import publish_safely
from .messages import camera_to_info, image_bytes
from .params import declare, read_start_file
from .qos import IMAGE_QOS, LATCHED_QOS
from .run import run_nodes

if TYPE_CHECKING:
    from rclpy.parameter import Parameter


class CameraNode(Node):
    def __init__(self, name: str = "camera_node", **kwargs):
        super().__init__(name, **kwargs)
        source = declare(self, "source", "synthetic",
                         "'synthetic', a V4L2 device (index or /dev/videoN), a video file, an image folder or glob, "
                         "a rosbag2 bag.",
                         read_only=True)
        self.frame_id = declare(self, "frame_id", "camera", "frame_id of the published headers.", read_only=True)
        rate = declare(self, "rate_hz", 10.0, "Frames per second published.", low=0.1, high=1000.0)
        loop = declare(self, "loop", False, "Start files over at their end (else stop cleanly).", read_only=True)
        width = declare(self, "image_width", 0, "Requested device width (0: the device's).", low=0, high=20000,
                        read_only=True)
        height = declare(self, "image_height", 0, "Requested device height (0: the device's).", low=0, high=20000,
                         read_only=True)
        url = declare(self, "camera_info_url", "", "file:// or package:// YAML calibration published on "
                      "camera_info (${NAME} and ${ROS_HOME} put in as camera_info_manager does).", read_only=True)
        camera_name = declare(self, "camera_name", "camera", "The camera's name: ${NAME} in camera_info_url.",
                              read_only=True)
        scene = declare(self, "synthetic_scene", "board_then_cube", "What the synthetic camera shows.",
                        choices=SYNTHETIC_SCENES, read_only=True)
        medium = declare(self, "synthetic_medium", "water", "Synthetic camera in air or behind a port in water.",
                         choices=("air", "water"), read_only=True)
        self.stop_requested = False
        self.frames_published = 0
        self.notes_said = 0  # of the source's notes
        self.image_pub = self.create_publisher(Image, "image_raw", IMAGE_QOS)
        self.info_pub = self.create_publisher(CameraInfo, "camera_info", LATCHED_QOS)
        # what camera_info cannot carry (tone curve, medium, distance), for an area node given camera_info only
        self.metadata_pub = self.create_publisher(String, "camera_info/metadata", LATCHED_QOS)
        self.camera_info = None
        path = camera_info_url_to_path(url, camera_name)
        calibration = read_start_file(self, "camera_info_url", lambda: read_calibration(path),
                                      "publishing image_raw without camera_info") if path is not None else None
        if calibration is not None:  # serialized once; each frame only changes its stamp
            self.camera_info = serialize_message(camera_to_info(calibration.camera, self.frame_id))
            publish_safely(self, self.metadata_pub,
                           String(data=metadata_message(calibration.camera, calibration.metadata)))
            self.get_logger().info(f"camera_info from {path}")
        self.source = open_source(source, loop, width, height, scene, medium)
        self.source_name = source
        self.timer = self.create_timer(1.0 / rate, self._tick)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(f"publishing {source} on {self.image_pub.topic_name} at {rate:g} Hz")

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        for parameter in parameters:  # rate_hz's range is checked by its descriptor
            if parameter.name == "rate_hz":
                self.timer.cancel()
                self.timer = self.create_timer(1.0 / parameter.value, self._tick)

    def _tick(self) -> None:
        try:
            image = self.source.read()
        except SourceError as exc:
            self.get_logger().warning(f"{exc}; retrying", throttle_duration_sec=5.0)
            if isinstance(self.source, DeviceSource):
                with contextlib.suppress(SourceError):  # still gone: the next tick retries
                    self.source.reopen()
            return
        for note in getattr(self.source, "notes", ())[self.notes_said:]:  # a 16-bit file's depth, files passed over
            self.get_logger().warning(note)
            self.notes_said += 1
        if image is None:
            self.get_logger().info(f"end of {self.source_name} after {self.frames_published} frames; stopping")
            self.timer.cancel()
            self.stop_requested = True
            return
        stamp = self.get_clock().now().to_msg()
        if self.camera_info is not None:  # first: a consumer has the frame's calibration when the frame comes
            publish_safely(self, self.info_pub, restamp(self.camera_info, stamp.sec, stamp.nanosec))
        if publish_safely(self, self.image_pub, image_bytes(image, stamp, self.frame_id)):
            self.frames_published += 1

    def destroy_node(self) -> None:
        self.source.release()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_nodes([CameraNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
