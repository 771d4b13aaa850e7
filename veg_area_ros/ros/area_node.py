"""area_node: idealizes each frame with the calibration from `camera_info` (or a file), classifies it and
publishes Af (`projected_area`, geometry_msgs/Vector3Stamped: x = Af m², y = its standard deviation m²,
z = object pixels; header = the source frame's), `projected_area/info` (JSON with everything else), the
binary `mask` (mono8, same header), and on demand (when subscribed) `image_rect` and `overlay`.

Frames arrive as raw CDR bytes (`raw=True`: the pixels are a view, never copied in Python) on a depth-1
best-effort subscription and are measured in its callback: while a frame is measured the middleware keeps
only the newest one, so a camera faster than the measurement costs skipped frames (counted from the
per-frame camera_info, reported in `projected_area/info` and the log), never a queue or stale results."""

from __future__ import annotations

import contextlib
import json
import math
import time
from collections import deque

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3Stamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String

from ..area import AreaMeasurer, PortAreaMeasurer, draw_overlay
from ..calib_io import CalibrationFileError, read_calibration
from ..camera_info import info_to_camera
from ..cdr import decode_camera_info, decode_image, stamp_ns, unstamped
from ..classify import AREA_MODES, CHANNELS, OBJECTS, Classifier, ClassifyError
from ..idealize import FrameSizeError
from ..latest import FrameTally
from ..scale import TargetsError, TargetsSpec
from ..synthetic import SCENE_DICTIONARY, SCENE_MARKERS
from .common import (
    ANY_INFO_QOS,
    IMAGE_QOS,
    PER_FRAME_INFO_QOS,
    RESULT_QOS,
    CountedWarnings,
    InputWatch,
    declare,
    publish_safely,
)
from .messages import ImageMessageError, image_bytes

BUSY_GAP_NS = 1_000_000  # callbacks closer than 1 ms: the node never waited for messages in between
TUNABLE = ("threshold", "threshold_mode", "object", "channel", "roi", "open_px", "close_px", "targets_file",
           "area_mode", "levels")


def default_targets() -> TargetsSpec:
    """The synthetic scene's four markers: what the built-in default camera shows."""
    return TargetsSpec.from_dict({"dictionary": SCENE_DICTIONARY,
                                  "markers": {k: list(v) for k, v in SCENE_MARKERS.items()}})


class AreaNode(Node):
    def __init__(self, name: str = "area_node", **kwargs):
        super().__init__(name, **kwargs)
        declare(self, "threshold", 120.0, "Grey level separating object and background.", low=0.0, high=255.0)
        declare(self, "threshold_mode", "fixed", "'fixed' uses `threshold`; 'otsu' picks it in the ROI.",
                choices=("fixed", "otsu"))
        declare(self, "object", "dark", "Object darker/brighter than the background, or greener.", choices=OBJECTS)
        declare(self, "channel", "grey", "Band the threshold acts on.", choices=CHANNELS)
        declare(self, "roi", [0.0], "Region of interest x1,y1,x2,y2,... in idealized pixels; [0.0] = inside "
                "the targets, markers excluded.")
        declare(self, "open_px", 0, "Morphological opening radius (removes specks).", low=0, high=50)
        declare(self, "close_px", 0, "Morphological closing radius (fills pin-holes).", low=0, high=50)
        declare(self, "targets_file", "", "Targets YAML; '' = the synthetic scene's four markers.")
        declare(self, "area_mode", "subpixel", "'subpixel': each edge pixel counts its object share from its grey "
                "level; 'count': whole pixels, as in the paper.", choices=AREA_MODES)
        declare(self, "levels", [0.0], "Sub-pixel mode: [object, background] grey levels; [0.0] = from each frame.")
        self.uncalibrated = declare(self, "uncalibrated_frames", "drop",
                                    "Frames before any calibration: 'drop' (throttled warning) or 'measure' "
                                    "(as an uncalibrated camera, flagged calibrated=false).",
                                    choices=("drop", "measure"))
        calibration_file = declare(self, "calibration_file", "", "Calibration YAML to start with ('' = wait for "
                                   "camera_info).", read_only=True)
        self.camera = None
        self.frames = FrameTally()
        self.frames_measured = 0
        self._skipped_logged = 0
        self._lost_logged = 0
        self._busy: deque[tuple[int, int]] = deque(maxlen=64)  # recent measurements, (start, end) ns
        self._measuring_since: int | None = None
        self.area_pub = self.create_publisher(Vector3Stamped, "projected_area", RESULT_QOS)
        self.info_pub = self.create_publisher(String, "projected_area/info", RESULT_QOS)
        self.mask_pub = self.create_publisher(Image, "mask", IMAGE_QOS)
        self.rect_pub = self.create_publisher(Image, "image_rect", IMAGE_QOS)
        self.overlay_pub = self.create_publisher(Image, "overlay", IMAGE_QOS)
        self.file_camera = None
        self.port_camera = None  # a flat port's exact model from calibration_file, for frames of its camera
        if calibration_file:
            try:
                calibration = read_calibration(calibration_file)
                self.camera, self.port_camera = calibration.camera, calibration.port_camera()
                self.file_camera = calibration.camera
                port = " (lens and flat port: the exact refraction model)" if self.port_camera else ""
                self.get_logger().info(f"calibration from {calibration_file}{port}")
            except CalibrationFileError as exc:
                self.get_logger().error(f"{exc}; waiting for camera_info instead")
        self.settings = {p: self.get_parameter(p).value for p in TUNABLE}
        # read when targets_file is set (set it again to re-read an edited file), not at every new calibration
        self.targets = self._load_targets(self.settings["targets_file"])  # invalid start parameters: the node fails
        self.measurer = self._build(self.settings, self.camera, self.targets)
        self.add_on_set_parameters_callback(self._on_parameters)
        self._info_seen = b""  # the last camera_info without its stamp
        # two subscriptions: latched (a calibration published before this node started) and one that every
        # publisher matches (volatile drivers, bag replay); a camera_info heard on both is handled once
        quiet = SubscriptionEventCallbacks(incompatible_qos=lambda _: None)  # the other subscription hears those
        self._info_subscriptions = [
            self.create_subscription(CameraInfo, "camera_info", self._on_camera_info_received, PER_FRAME_INFO_QOS,
                                     raw=True, event_callbacks=quiet),
            self.create_subscription(CameraInfo, "camera_info", self._on_camera_info_received, ANY_INFO_QOS,
                                     raw=True)]
        self.create_subscription(Image, "image_raw", self._on_frame, IMAGE_QOS, raw=True)
        self.input_watch = InputWatch(self, "image_raw")
        self.warn = CountedWarnings(self.get_logger())

    @staticmethod
    def _load_targets(path: str) -> TargetsSpec:
        return TargetsSpec.load(path) if path else default_targets()

    def _build(self, settings: dict, camera, targets: TargetsSpec) -> AreaMeasurer:
        """A measurer for these settings; raises ValueError (ClassifyError, ...) with the reason."""
        if settings["threshold_mode"] not in ("fixed", "otsu"):
            raise ClassifyError(f"threshold_mode must be fixed or otsu, got {settings['threshold_mode']!r}")
        threshold = "otsu" if settings["threshold_mode"] == "otsu" else float(settings["threshold"])
        classifier = Classifier(threshold=threshold, object=settings["object"], channel=settings["channel"],
                                open_px=int(settings["open_px"]), close_px=int(settings["close_px"]))
        roi = list(settings["roi"])
        if roi == [0.0] or not roi:
            polygon = None
        else:
            if len(roi) % 2 or len(roi) < 6 or not all(math.isfinite(v) for v in roi):
                raise ClassifyError("roi needs at least 3 x,y pairs of finite numbers (or [0.0] for the default)")
            polygon = roi
        levels = list(settings["levels"])
        if settings["area_mode"] not in AREA_MODES:
            raise ClassifyError(f"area_mode must be one of {', '.join(AREA_MODES)}, got {settings['area_mode']!r}")
        options = dict(roi=polygon, area_mode=settings["area_mode"], levels=None if levels in ([0.0], []) else levels)
        if self.port_camera is not None and camera == self.file_camera:  # not a camera_info that replaced it
            return PortAreaMeasurer(self.port_camera, targets, classifier, **options)
        return AreaMeasurer(camera, targets, classifier, **options)

    def _on_parameters(self, parameters) -> SetParametersResult:
        proposed = dict(self.settings)
        for parameter in parameters:
            if parameter.name in proposed:
                proposed[parameter.name] = parameter.value
            elif parameter.name == "uncalibrated_frames" and parameter.value not in ("drop", "measure"):
                return SetParametersResult(successful=False, reason="uncalibrated_frames must be drop or measure")
        try:
            targets = self.targets
            if any(parameter.name == "targets_file" for parameter in parameters):
                targets = self._load_targets(proposed["targets_file"])
            measurer = self._build(proposed, self.camera, targets)
        except (ValueError, OSError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.settings, self.targets, self.measurer = proposed, targets, measurer
        for parameter in parameters:
            if parameter.name == "uncalibrated_frames":
                self.uncalibrated = parameter.value
        return SetParametersResult(successful=True)

    def _busy_between(self, start_ns: int, end_ns: int) -> bool:
        """Whether the node spent most of the time from start to end (ns, the system clock) in its callbacks:
        then a frame's image that came meanwhile waited and was replaced (skipped); a node mostly waiting would
        have taken it (lost)."""
        if end_ns <= start_ns:
            return True
        measuring = sum(max(0, min(end, end_ns) - max(start, start_ns)) for start, end in self._busy)
        return measuring >= 0.5 * (end_ns - start_ns)

    def _on_camera_info_received(self, data: bytes, info: dict) -> None:  # two arguments: rclpy passes the info
        started = time.time_ns()
        try:
            self._on_camera_info(data, info)
        finally:
            self._note_busy(started, time.time_ns())

    def _note_busy(self, start_ns: int, end_ns: int) -> None:
        """A stretch of time in this node's callbacks; stretches less than BUSY_GAP_NS apart are one (the
        executor's dispatch between callbacks keeps the node as busy)."""
        if self._busy and start_ns - self._busy[-1][1] < BUSY_GAP_NS:
            self._busy[-1] = (self._busy[-1][0], end_ns)
        else:
            self._busy.append((start_ns, end_ns))

    def _on_camera_info(self, data: bytes, info: dict | None = None) -> None:
        with contextlib.suppress(ImageMessageError):
            self.frames.announce(stamp_ns(data), (info or {}).get("received_timestamp") or time.time_ns())
        content = unstamped(data)
        if content == self._info_seen:  # a camera republishing its calibration with every frame: nothing new
            return
        self._info_seen = content
        try:
            camera = info_to_camera(decode_camera_info(data))
        except ValueError as exc:
            self.warn("camera_info ignored", str(exc))
            return
        if camera == self.camera:
            return
        try:
            measurer = self._build(self.settings, camera, self.targets)
        except Exception as exc:  # e.g. no memory for its pixel maps: the node goes on with what it had
            self.get_logger().error(f"calibration received but not applied ({exc.__class__.__name__}: {exc}); "
                                    "frames are measured with the previous one", throttle_duration_sec=10.0)
            return
        self.camera, self.measurer = camera, measurer
        self.get_logger().info(f"calibration received: {camera.width}x{camera.height}, fx {camera.fx:.2f}")

    def _take_waiting_camera_info(self) -> None:
        """Every camera_info already waiting, before the frame is counted: the executor hands this node one message
        per subscription per wait, so at full rate camera_info would fall behind the frames and overflow its
        queue, and the skipped frames would be under-counted. Same call as rclpy's executor makes."""
        for subscription in self._info_subscriptions:
            while True:
                try:
                    with subscription.handle:
                        taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
                except AttributeError:  # another rclpy without this call: counted as the executor delivers them
                    return
                if taken is None:
                    break
                self._on_camera_info(*taken[:2])

    def _on_frame(self, data: bytes) -> None:
        self.input_watch.frame()
        try:
            self._take_waiting_camera_info()
        except Exception as exc:  # a camera_info that cannot be taken or applied must not cost the frame
            self.get_logger().error(f"camera_info not taken: {exc.__class__.__name__}: {exc}",
                                    throttle_duration_sec=5.0)
        self._measuring_since = time.time_ns()
        try:
            self._on_image(data)
        except Exception as exc:  # one bad frame must not end the node's measuring
            self.warn("frame not measured", f"{exc.__class__.__name__}: {exc}", "error")
        finally:
            self._note_busy(self._measuring_since, time.time_ns())
            self._measuring_since = None
        skipped, lost = self.frames.skipped, self.frames.lost
        if skipped is not None and skipped > self._skipped_logged:
            self.get_logger().warning(f"{skipped} frames skipped, {self.frames.received} measured or refused: the "
                                      "camera is faster than the measurement (the newest frame is measured)",
                                      throttle_duration_sec=10.0)
            self._skipped_logged = skipped
        if lost is not None and lost > self._lost_logged:
            self.get_logger().warning(f"{lost} frames lost in transport ({self.input_watch.transport}): their "
                                      "camera_info came, the image did not", throttle_duration_sec=10.0)
            self._lost_logged = lost

    def _on_image(self, data: bytes) -> None:
        try:
            fields = decode_image(data)
            frame = fields.pixels()
        except ImageMessageError as exc:
            self.warn("frame refused", str(exc))
            return
        header = fields.header
        self.frames.took(header.nanoseconds, time.time_ns(), self._busy_between)
        if self.camera is None and self.uncalibrated == "drop":
            self.warn("frame dropped", "no calibration yet (camera_info or calibration_file); set "
                      "uncalibrated_frames:=measure to measure them uncalibrated")
            return
        wanted = [pub.get_subscription_count() > 0 for pub in (self.mask_pub, self.rect_pub, self.overlay_pub)]
        try:
            result = self.measurer.measure(frame, keep_images=any(wanted))
        except FrameSizeError as exc:
            self.warn("frame refused", str(exc))
            return
        except (TargetsError, ClassifyError) as exc:
            self.warn("frame not measured", str(exc))
            return
        self.frames_measured += 1
        stamp = Time(sec=header.sec, nanosec=header.nanosec)
        area = Vector3Stamped()
        area.header.stamp, area.header.frame_id = stamp, header.frame_id
        area.vector.x, area.vector.y, area.vector.z = result.area_m2, result.area_std_m2, float(result.pixel_count)
        publish_safely(self, self.area_pub, area)
        summary = result.summary()
        summary.update(stamp={"sec": header.sec, "nanosec": header.nanosec}, frame_id=header.frame_id,
                       frames_received=self.frames.received, frames_dropped=self.frames.skipped,
                       frames_lost=self.frames.lost, weights_rebuilt=self.measurer.rebuilds,
                       frames_measured=self.frames_measured)
        publish_safely(self, self.info_pub, String(data=json.dumps(summary)))
        # the images cost a remap each: made only for topics somebody listens to (rosbag2 counts)
        for publisher, image, want in ((self.mask_pub, result.mask, wanted[0]),
                                       (self.rect_pub, result.image, wanted[1]),
                                       (self.overlay_pub, wanted[2] and draw_overlay(result), wanted[2])):
            if want:
                publish_safely(self, publisher, image_bytes(image, stamp, header.frame_id))


def main(args: list[str] | None = None) -> int:
    from .common import run_nodes

    return run_nodes([AreaNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
