"""area_node: idealizes each frame with the calibration from `camera_info` (or a file), classifies it and
publishes Af (`projected_area`, veg_area_msgs/ProjectedArea: Af, its standard deviation and each term of it,
the classification, the calibration used and the warnings, by name; header = the source frame's), the same as
geometry_msgs/Vector3Stamped on `projected_area/vector` (deprecated, for one release: x = Af m², y = its standard
deviation m², z = object pixels), `projected_area/info` (JSON with everything else), the
binary `mask` (mono8, same header), and on demand (when subscribed) `image_rect`, `overlay` (every frame) and
`overlay/preview` (the overlay at most `preview_rate_hz` times a second: for viewers such as the console,
which then cost the measurement a few remaps a second, not one per frame).

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
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Vector3Stamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String

from veg_area_msgs.msg import ProjectedArea

from ..area import AreaMeasurer
from ..bit_depth import StreamDepth
from ..board import to_grey
from ..board_hint import dictionary_hint
from ..calib_io import metadata_for, read_calibration
from ..camera_info import info_to_camera
from ..cdr import decode_camera_info, stamp_ns, unstamped
from ..classify import CHANNELS, OBJECTS, ClassifyError, SharesOnlyError
from ..frames import read_image
from ..idealize import FrameSizeError
from ..latest import FrameTally
from ..light import LightError
from ..overlay import draw_overlay
from ..settings import AREA_MODE_CHOICES, NO_LEVELS, NO_ROI, THRESHOLD_MODES, TONE_CURVE_CHOICES, MeasurementSettings
from ..sources import default_targets
from ..targets import TargetsError, TargetsNotFoundError, TargetsSpec
from .health import CountedWarnings, InputWatch, publish_safely
from .messages import (
    IMAGE_TRANSPORT_HELP,
    IMAGE_TRANSPORTS,
    ImageMessageError,
    decode_transported,
    image_bytes,
    projected_area,
    projected_area_vector,
    transported_image,
)
from .params import declare, read_start_file
from .qos import ANY_INFO_QOS, IMAGE_QOS, LATCHED_QOS, PER_FRAME_INFO_QOS, RESULT_QOS
from .run import run_nodes

if TYPE_CHECKING:
    from ..camera_model import BrownCamera
    from ..port_area import PortAreaMeasurer

TALLY_LOG_PERIOD_S = 10.0  # the skipped and lost frames' log lines, at most once in this long
BUSY_GAP_NS = 1_000_000  # callbacks closer than 1 ms: the node never waited for messages in between
DEFAULTS = MeasurementSettings()
# the parameters that are MeasurementSettings, tunable at run time (`ros2 param set`), and targets_file
SETTINGS = ("threshold", "threshold_mode", "object", "channel", "roi", "open_px", "close_px", "area_mode", "levels",
            "tone_curve")
TUNABLE = (*SETTINGS, "targets_file", "background_file")



class AreaNode(Node):
    def __init__(self, name: str = "area_node", **kwargs):
        super().__init__(name, **kwargs)
        declare(self, "threshold", 120.0, "Grey level separating object and background, used when "
                "threshold_mode is 'fixed'.", low=0.0, high=255.0)
        declare(self, "threshold_mode", DEFAULTS.threshold_mode, "'otsu' picks the threshold in the ROI of each "
                "frame; 'fixed' uses `threshold`.", choices=THRESHOLD_MODES)
        declare(self, "object", DEFAULTS.object, "Object darker/brighter than the background, or greener.",
                choices=OBJECTS)
        declare(self, "channel", DEFAULTS.channel, "Band the threshold acts on.", choices=CHANNELS)
        declare(self, "roi", list(NO_ROI), "Region of interest x1,y1,x2,y2,... in idealized pixels; [0.0] = "
                "inside the targets, markers excluded.")
        declare(self, "open_px", DEFAULTS.open_px, "Morphological opening radius (removes specks).", low=0, high=50)
        declare(self, "close_px", DEFAULTS.close_px, "Morphological closing radius (fills pin-holes).", low=0,
                high=50)
        declare(self, "targets_file", "", "Targets YAML; '' = the synthetic scene's four markers.")
        declare(self, "area_mode", DEFAULTS.area_mode, "'subpixel': each edge pixel counts its object share from "
                "its grey level; 'count': whole pixels, as in the paper; 'auto' the one calibration_file records "
                "(judged on its board views by veg-area calibrate) or camera_info/metadata says, else subpixel.",
                choices=AREA_MODE_CHOICES)
        declare(self, "levels", list(NO_LEVELS), "Sub-pixel mode: [object, background] grey levels; [0.0] = "
                "from each frame.")
        declare(self, "tone_curve", DEFAULTS.tone_curve, "How the camera encodes light in its grey levels: "
                "'auto' the curve calibration_file records (judged on its board views by veg-area calibrate) or "
                "camera_info/metadata says, else linear; 'linear' as they are, 'srgb' the sRGB curve (most JPEG "
                "cameras): Otsu's threshold and the sub-pixel shares are then read in light.",
                choices=TONE_CURVE_CHOICES)
        declare(self, "background_file", "", "Sub-pixel mode: an image of the empty scene (the flume before the "
                "plant goes in), same camera and settings, to even the light with; '' = fitted in each frame.")
        declare(self, "preview_rate_hz", 5.0, "overlay/preview is drawn at most this often (viewers, the console).",
                low=0.1, high=100.0)
        self.uncalibrated = declare(self, "uncalibrated_frames", "drop",
                                    "Frames before any calibration: 'drop' (throttled warning) or 'measure' "
                                    "(as an uncalibrated camera, flagged calibrated=false).",
                                    choices=("drop", "measure"))
        self.calibration_file = calibration_file = declare(
            self, "calibration_file", "", "Calibration YAML to start with ('' = wait for camera_info).", read_only=True)
        self.transport = declare(self, "image_transport", "raw", IMAGE_TRANSPORT_HELP, choices=IMAGE_TRANSPORTS,
                                 read_only=True)
        image_type, image_topic = transported_image(self.transport)
        self.camera = None
        self.info_frame_id = ""  # the frame_id of the camera_info the calibration came from
        self.frames = FrameTally()
        self.frames_measured = 0
        self.dictionary_hinted = False
        self.bit_depth = StreamDepth()  # a 16-bit camera's depth, held over its frames
        self._skipped_logged = 0
        self._lost_logged = 0
        self._tally_logged_at = -TALLY_LOG_PERIOD_S
        self._busy: deque[tuple[int, int]] = deque(maxlen=64)  # recent measurements, (start, end) ns
        self._measuring_since: int | None = None
        self.area_pub = self.create_publisher(ProjectedArea, "projected_area", RESULT_QOS)
        # deprecated: the Vector3Stamped that `projected_area` was, for recordings and instrument nodes made for it
        self.area_vector_pub = self.create_publisher(Vector3Stamped, "projected_area/vector", RESULT_QOS)
        self.info_pub = self.create_publisher(String, "projected_area/info", RESULT_QOS)
        self.mask_pub = self.create_publisher(Image, "mask", IMAGE_QOS)
        self.rect_pub = self.create_publisher(Image, "image_rect", IMAGE_QOS)
        self.overlay_pub = self.create_publisher(Image, "overlay", IMAGE_QOS)
        self.preview_pub = self.create_publisher(Image, "overlay/preview", IMAGE_QOS)
        self._preview_at = -math.inf  # monotonic s of the last preview
        self.warn = CountedWarnings(self.get_logger())
        self.file_camera = None
        self.file_conditions = None  # calibration_file's medium and distance, said when frames leave them
        self.info_metadata = None  # the text last heard on camera_info/metadata (calib_io.metadata_message)
        self._info_checked: tuple = (None, None, None)  # (that text, the camera it was matched to, the result)
        self.port_camera = None  # a flat port's exact model from calibration_file, for frames of its camera
        calibration = read_start_file(self, "calibration_file", lambda: read_calibration(calibration_file),
                                      "waiting for camera_info instead") if calibration_file else None
        if calibration is not None:
            self.camera, self.port_camera = calibration.camera, calibration.port_camera()
            self.file_camera, self.file_conditions = calibration.camera, calibration.metadata
            port = " (lens and flat port: the exact refraction model)" if self.port_camera else ""
            tone, reading = calibration.metadata.get("tone_curve"), calibration.metadata.get("area_mode")
            recorded = (f"; tone curve {tone} as it records (tone_curve auto reads it)" if tone else "") + (
                f"; area mode {reading} as it records (area_mode auto reads it)" if reading else "")
            self.get_logger().info(f"calibration from {calibration_file}{port}{recorded}")
        self.settings = self._settings({})  # a value out of range or choices at start: the node does not start
        # read when targets_file is set (set it again to re-read an edited file), not at every new calibration
        targets_file = self.get_parameter("targets_file").value
        self.targets = read_start_file(self, "targets_file", lambda: self._load_targets(targets_file),
                                       "no frame is measured until targets_file is set to a readable file")
        background_file = self.get_parameter("background_file").value
        self.background = read_start_file(self, "background_file", lambda: self._load_background(background_file),
                                          "the light is fitted in each frame instead") if background_file else None
        self.measurer = None  # _build reads it: none yet to take the camera's maps from
        self.measurer = self._build_or_log(self.settings, self.camera, self.targets)
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._info_seen = b""  # the last camera_info without its stamp
        # two subscriptions: latched (a calibration published before this node started) and one that every
        # publisher matches (volatile drivers, bag replay); a camera_info heard on both is handled once
        quiet = SubscriptionEventCallbacks(incompatible_qos=lambda _: None)  # the other subscription hears those
        self._info_subscriptions = [
            self.create_subscription(CameraInfo, "camera_info", self._on_camera_info_received, PER_FRAME_INFO_QOS,
                                     raw=True, event_callbacks=quiet),
            self.create_subscription(CameraInfo, "camera_info", self._on_camera_info_received, ANY_INFO_QOS,
                                     raw=True)]
        # what camera_info cannot carry (tone curve, medium, distance) from the node that serves the calibration
        self.create_subscription(String, "camera_info/metadata", self._on_info_metadata, LATCHED_QOS)
        self._take_unavailable = False
        self.create_subscription(image_type, image_topic, self._on_frame,
                                 IMAGE_QOS, raw=True)
        self.input_watch = InputWatch(self, image_topic)

    @staticmethod
    def _load_targets(path: str) -> TargetsSpec:
        return TargetsSpec.load(path) if path else default_targets()

    @staticmethod
    def _load_background(path: str) -> np.ndarray | None:
        """The empty scene's image ('' = none); ValueError with the reason."""
        if not path:
            return None
        image, problem = read_image(Path(path))
        if image is None:
            raise ValueError(f"{path}: {problem}")
        return image

    def _build_or_log(self, settings: MeasurementSettings, camera: BrownCamera | None, targets: TargetsSpec | None
                      ) -> AreaMeasurer | PortAreaMeasurer | None:
        """`_build` at start and for a calibration heard later: a background frame or given levels that do not
        fit these settings (e.g. area_mode auto counting whole pixels, as the calibration's metadata decides) are
        logged and left out (the levels parameter set back to [0.0], so later changes are judged without them),
        and the frames are measured rather than none."""
        try:
            return self._build(settings, camera, targets, self.background)
        except ValueError as exc:
            if isinstance(exc, SharesOnlyError) and exc.option == "levels":
                self.get_logger().error(f"parameter levels: {exc}; set back to {list(NO_LEVELS)}, each frame's "
                                        "own levels are read")
                self.settings = settings = replace(settings, levels=None)
                self.set_parameters([Parameter("levels", Parameter.Type.DOUBLE_ARRAY, list(NO_LEVELS))])
            elif self.background is not None:  # it does not apply, or not to this camera's frames (their size)
                self.get_logger().error(f"parameter background_file: {exc}; the frames are measured without it")
                self.background = None
            else:
                raise
            return self._build_or_log(settings, camera, targets)

    def _settings(self, changed: dict) -> MeasurementSettings:
        """The measurement settings from the parameters, with `changed` (name -> value) over them; raises
        ValueError (ClassifyError) with the reason."""
        value = {name: self.get_parameter(name).value for name in SETTINGS} | changed
        return MeasurementSettings(object=value["object"], channel=value["channel"], roi=value["roi"],
                                   open_px=value["open_px"], close_px=value["close_px"],
                                   area_mode=value["area_mode"], levels=value["levels"],
                                   tone_curve=value["tone_curve"],
                                   ).with_threshold(value["threshold_mode"], value["threshold"])

    def _build(self, settings: MeasurementSettings, camera: BrownCamera | None, targets: TargetsSpec | None,
               background: np.ndarray | None) -> AreaMeasurer | PortAreaMeasurer | None:
        """A measurer for these settings (None without targets); raises ValueError with the reason."""
        if targets is None:
            return None
        from_file = camera is not None and camera == self.file_camera  # not a camera_info that replaced it
        return settings.measurer(camera, targets, self.port_camera if from_file else None, background,
                                 self.file_conditions if from_file else self._info_conditions(camera),
                                 self.measurer)  # its camera's maps, where it is the same camera

    def _info_conditions(self, camera: BrownCamera | None) -> dict | None:
        """The metadata heard on camera_info/metadata if it belongs to `camera` (a camera_info's), else None."""
        if camera is None or self.info_metadata is None:
            return None
        text, checked, conditions = self._info_checked
        if text is self.info_metadata and checked is camera:  # a build and its log line read it once
            return conditions
        try:
            conditions = metadata_for(camera, self.info_metadata)
        except ValueError as exc:
            self.warn("camera_info/metadata ignored", str(exc))
            conditions = None
        self._info_checked = (self.info_metadata, camera, conditions)
        return conditions

    def _on_info_metadata(self, msg: String) -> None:
        if msg.data == self.info_metadata:
            return
        self.info_metadata = msg.data
        if self.camera is None or self.camera == self.file_camera:  # a calibration_file's own metadata rules
            return
        conditions = self._info_conditions(self.camera)
        if conditions is None:
            return
        try:
            measurer = self._build_or_log(self.settings, self.camera, self.targets)
        except Exception as exc:  # e.g. a tone curve this version does not know: measured as before
            self.get_logger().error(f"camera_info/metadata not applied ({exc.__class__.__name__}: {exc})")
            return
        if measurer is not None:  # the frames' sequence goes on: the conditions change no carried state
            measurer.carry_on_from(self.measurer)
        self.measurer = measurer
        self._say_metadata(conditions)

    def _say_metadata(self, conditions: dict) -> None:
        tone, reading = conditions.get("tone_curve"), conditions.get("area_mode")
        medium = conditions.get("medium")
        self.get_logger().info("calibration metadata with camera_info" + (f": medium {medium}" if medium else "")
                               + (f"; tone curve {tone} (tone_curve auto reads it)" if tone else "")
                               + (f"; area mode {reading} (area_mode auto reads it)" if reading else ""))

    def _check_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """A run-time change is accepted only if it builds a measurer (nothing is changed here)."""
        changed = {p.name: p.value for p in parameters}
        if changed.get("uncalibrated_frames", "drop") not in ("drop", "measure"):
            return SetParametersResult(successful=False, reason="uncalibrated_frames must be drop or measure")
        try:
            settings = self._settings({k: v for k, v in changed.items() if k in SETTINGS})
            targets = self._load_targets(changed["targets_file"]) if "targets_file" in changed else self.targets
            background = (self._load_background(changed["background_file"]) if "background_file" in changed
                          else self.background)
            self._build(settings, self.camera, targets, background)
        except (ValueError, OSError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        names = {p.name for p in parameters}
        if "uncalibrated_frames" in names:
            self.uncalibrated = self.get_parameter("uncalibrated_frames").value
        if not names & set(TUNABLE):
            return
        try:
            if "targets_file" in names:
                self.targets = self._load_targets(self.get_parameter("targets_file").value)
            if "background_file" in names:
                self.background = self._load_background(self.get_parameter("background_file").value)
            self.settings = self._settings({})
            previous, self.measurer = self.measurer, self._build(self.settings, self.camera, self.targets,
                                                                 self.background)
        except (ValueError, OSError) as exc:  # the file changed between the check and now
            self.get_logger().error(f"parameters set but not applied ({exc}); measuring as before")
            return
        if isinstance(self.measurer, AreaMeasurer):  # a threshold or ROI tuned: the markers (and more) stay
            self.measurer.carry_on_from(previous)
        if "threshold" in names and self.settings.threshold_mode == "otsu":
            self.get_logger().warning(f"threshold {self.get_parameter('threshold').value:g} kept for later: "
                                      "threshold_mode is otsu; set threshold_mode:=fixed to use it")

    def _busy_between(self, start_ns: int, end_ns: int) -> bool:
        """Whether the node spent most of the time from start to end (ns, the system clock) in its callbacks:
        then a frame's image that came meanwhile waited and was replaced (skipped); a node mostly waiting would
        have taken it (lost)."""
        if end_ns <= start_ns:
            return True
        measuring = 0
        for start, end in reversed(self._busy):  # newest first: the stretches before start_ns end the walk
            if end <= start_ns:
                break
            measuring += max(0, min(end, end_ns) - max(start, start_ns))
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
            fields = decode_camera_info(data)
            self.info_frame_id = fields.header.frame_id
            camera = info_to_camera(fields)
        except ValueError as exc:
            self.warn("camera_info ignored", str(exc))
            return
        if camera == self.camera:
            return
        try:
            measurer = self._build_or_log(self.settings, camera, self.targets)
        except Exception as exc:  # e.g. no memory for its pixel maps: the node goes on with what it had
            self.get_logger().error(f"calibration received but not applied ({exc.__class__.__name__}: {exc}); "
                                    "frames are measured with the previous one", throttle_duration_sec=10.0)
            return
        self.camera, self.measurer = camera, measurer
        self.get_logger().info(f"calibration received: {camera.width}x{camera.height}, fx {camera.fx:.2f}")
        conditions = self._info_conditions(camera)
        if conditions is not None:
            self._say_metadata(conditions)

    def _take_waiting_camera_info(self) -> None:
        """Every camera_info already waiting, before the frame is counted: the executor hands this node one message
        per subscription per wait, so at full rate camera_info would fall behind the frames and overflow its
        queue, and the skipped frames would be under-counted. Same call as rclpy's executor makes."""
        for subscription in self._info_subscriptions:
            while True:
                try:
                    with subscription.handle:
                        taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
                except AttributeError as exc:  # an rclpy without this call: counted as the executor delivers them
                    if not self._take_unavailable:
                        self._take_unavailable = True
                        self.get_logger().warning(f"this rclpy cannot take waiting camera_info ({exc}): skipped "
                                                  "frames are counted as the executor delivers camera_info and may "
                                                  "be under-counted at full rate")
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
        # checked here, not by rclpy's throttle: its logger looks up the caller's source line on every call
        # (0.25 ms), and at full rate frames are skipped with every frame
        if time.monotonic() < self._tally_logged_at + TALLY_LOG_PERIOD_S:
            return
        skipped, lost = self.frames.skipped, self.frames.lost
        if skipped is not None and skipped > self._skipped_logged:
            self.get_logger().warning(f"{skipped} frames skipped, {self.frames.received} measured or refused: the "
                                      "camera is faster than the measurement (the newest frame is measured)")
            self._skipped_logged = skipped
            self._tally_logged_at = time.monotonic()
        if lost is not None and lost > self._lost_logged:
            self.get_logger().warning(f"{lost} frames lost in transport ({self.input_watch.transport}): their "
                                      "camera_info came, the image did not")
            self._lost_logged = lost
            self._tally_logged_at = time.monotonic()

    def _calibration_source(self) -> str:
        """Where the calibration in use came from: "calibration_file <path>", "camera_info", or "" (none)."""
        if self.camera is None:
            return ""
        if self.camera == self.file_camera:
            return f"calibration_file {self.calibration_file}"
        return "camera_info"

    def _on_image(self, data: bytes) -> None:
        try:
            fields = decode_transported(self.transport, data)
            notes: list[str] = []
            frame = fields.pixels(self.bit_depth, notes)
        except ImageMessageError as exc:
            self.warn("frame refused", str(exc))
            return
        header = fields.header
        self.frames.took(header.nanoseconds, time.time_ns(), self._busy_between)
        if self.measurer is None:
            self.warn("frame not measured", "no targets: set targets_file to a readable targets YAML")
            return
        if self.camera is None and self.uncalibrated == "drop":
            self.warn("frame dropped", "no calibration yet (camera_info or calibration_file); set "
                      "uncalibrated_frames:=measure to measure them uncalibrated")
            return
        wanted = [pub.get_subscription_count() > 0 for pub in (self.mask_pub, self.rect_pub, self.overlay_pub)]
        preview = (self.preview_pub.get_subscription_count() > 0 and time.monotonic() - self._preview_at
                   >= 1.0 / self.get_parameter("preview_rate_hz").value)
        try:
            result = self.measurer.measure(frame, keep_images=any(wanted) or preview)
        except FrameSizeError as exc:
            self.warn("frame refused", str(exc))
            return
        except (TargetsError, ClassifyError, LightError) as exc:
            text = str(exc)
            if (not self.dictionary_hinted and isinstance(exc, TargetsNotFoundError) and exc.markers_found == 0
                    and self.targets.markers):
                self.dictionary_hinted = True  # the other ArUco families tried once: a wrong dictionary finds none
                text += dictionary_hint(self.targets.dictionary, to_grey(frame))
            self.warn("frame not measured", text)
            return
        self.frames_measured += 1
        result.warnings.extend(notes)
        if header.nanoseconds == 0:
            result.warnings.append("header stamp 0: the camera driver does not stamp its images, so this result "
                                   "carries stamp 0 too and cannot be paired with force or velocity by time (set "
                                   "the driver to stamp its frames)")
        source = self._calibration_source()
        if source == "camera_info" and self.info_frame_id and header.frame_id and self.info_frame_id != header.frame_id:
            result.warnings.append(f"calibration of another frame: camera_info's frame_id {self.info_frame_id!r} is "
                                   f"not the image's {header.frame_id!r}, so it may be another camera's (remap "
                                   "camera_info to this camera's, as image_transport pairs them)")
        for warning in result.warnings:  # in the result itself (info); the log says each kind, throttled
            kind = warning.split(":", 1)[0]
            self.warn("Af less trustworthy", warning, like=kind)
        stamp = Time(sec=header.sec, nanosec=header.nanosec)
        counts = {"frames_received": self.frames.received, "frames_skipped": self.frames.skipped,
                  "frames_lost": self.frames.lost, "frames_measured": self.frames_measured}
        publish_safely(self, self.area_pub, projected_area(result, stamp, header.frame_id, source, counts))
        if self.area_vector_pub.get_subscription_count() > 0:
            publish_safely(self, self.area_vector_pub, projected_area_vector(result, stamp, header.frame_id))
        if self.info_pub.get_subscription_count() > 0:  # the record as JSON costs its text: made only when read
            summary = result.summary()
            summary.update(stamp={"sec": header.sec, "nanosec": header.nanosec}, frame_id=header.frame_id,
                           frames_received=self.frames.received, frames_dropped=self.frames.skipped,
                           frames_lost=self.frames.lost, weights_rebuilt=self.measurer.rebuilds,
                           frames_measured=self.frames_measured)
            publish_safely(self, self.info_pub, String(data=json.dumps(summary)))
        # the images cost a remap each: made only for topics somebody listens to (rosbag2 counts)
        overlay = draw_overlay(result) if wanted[2] or preview else None
        for publisher, image, want in ((self.mask_pub, result.mask, wanted[0]),
                                       (self.rect_pub, result.image, wanted[1]),
                                       (self.overlay_pub, overlay, wanted[2]), (self.preview_pub, overlay, preview)):
            if want:
                publish_safely(self, publisher, image_bytes(image, stamp, header.frame_id))
        if preview:
            self._preview_at = time.monotonic()


def main(args: list[str] | None = None) -> int:
    return run_nodes([AreaNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
