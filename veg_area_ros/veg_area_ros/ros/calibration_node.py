"""calibration_node: collects board views from `image_raw`, fits the combined lens-and-refraction model,
and serves it: `camera_info` (latched), `set_camera_info`, and the YAML at `camera_info_url`. Says what it has
kept and what is still missing on `~/progress` (veg_area_msgs/CalibrationProgress) and, while watched, in the
`~/feedback` image."""

from __future__ import annotations

import math
import os
import threading
import time
from typing import TYPE_CHECKING

from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from sensor_msgs.srv import SetCameraInfo
from std_msgs.msg import String
from std_srvs.srv import Trigger

from veg_area_msgs.msg import CalibrationProgress

from ..bit_depth import StreamDepth
from ..board import BoardSpec, BoardSpecError, detect_scaled, to_grey
from ..board_hint import board_hint
from ..calib_io import (
    camera_info_url_to_path,
    fit_metadata,
    metadata_message,
    provenance,
    quality_rms,
    read_calibration,
    write_calibration,
)
from ..calibration import COVERAGE_CELLS, CalibrationError, View, calibrate, coverage_grid
from ..camera_model import MODELS, BrownCamera
from ..feedback import FitView, fit_reach, render_feedback
from ..guidance import CalibrationGuide
from ..replacement import Judgement, judge
from ..sources import DEFAULT_BOARD
from ..tone_evidence import KeptFrames
from .health import CountedWarnings, InputWatch, publish_safely
from .messages import (
    IMAGE_TRANSPORT_HELP,
    IMAGE_TRANSPORTS,
    ImageMessageError,
    camera_to_info,
    decode_transported,
    image_bytes,
    info_to_camera,
    progress_message,
    transported_image,
)
from .params import declare, read_start_file
from .qos import IMAGE_QOS, LATCHED_QOS, RESULT_QOS
from .run import run_nodes

if TYPE_CHECKING:
    import numpy as np

HINT_AFTER_FRAMES = 30  # frames without a board before the spec's usual mistakes are tried (once)
HINT_FRAMES = 3


class CalibrationNode(Node):
    def __init__(self, name: str = "calibration_node", **kwargs):
        super().__init__(name, **kwargs)
        board_text = declare(self, "board", DEFAULT_BOARD, "Board spec, as for `veg-area calibrate --board`.",
                             read_only=True)
        self.medium = declare(self, "medium", "water", "Medium the calibration is made in.", choices=("air", "water"),
                              read_only=True)
        self.distance = declare(self, "calibration_distance_m", 0.7, "Camera-to-board distance, metres.",
                                low=0.01, high=100.0, read_only=True)
        self.min_views = declare(self, "min_views", 12, "Views kept before an automatic fit (which also waits for "
                                 "enough variety: see ~/feedback).", low=4, high=500, read_only=True)
        declare(self, "model", "auto", "Camera model fitted (ROS's distortion_model); auto fits all three and picks "
                "the one that best predicts held-out views (as `veg-area calibrate --model`); read at each fit.",
                choices=("auto", *MODELS))  # refused at start by `declare`, at each fit by `calibrate`
        self.auto_calibrate = declare(self, "auto_calibrate", True, "Fit once min_views varied views are in.",
                                      read_only=True)
        self.camera_name = declare(self, "camera_name", "camera", "camera_name written in the YAML.", read_only=True)
        url = declare(self, "camera_info_url", "file://" + os.path.expanduser("~/.ros/camera_info/veg_area.yaml"),
                      "Where the calibration is loaded from at start and written to (file://).", read_only=True)
        self.frame_id = declare(self, "frame_id", "camera", "frame_id of the published camera_info.", read_only=True)
        self.transport = declare(self, "image_transport", "raw", IMAGE_TRANSPORT_HELP, choices=IMAGE_TRANSPORTS,
                                 read_only=True)
        image_type, image_topic = transported_image(self.transport)
        try:
            self.board = BoardSpec.parse(board_text)
        except BoardSpecError as exc:
            raise ValueError(f"parameter board: {exc}") from exc
        self.path = camera_info_url_to_path(url, self.camera_name)
        self.views: list[View] = []
        self.kept_frames = KeptFrames(self.board)  # the views' frames, for the tone curve judged at each fit
        self.guide: CalibrationGuide | None = None  # from the first frame on (its size)
        self.image_size: tuple[int, int] | None = None
        self.frames_seen = 0
        self.frames_skipped = 0  # arrived while the last one was still being looked at: counted, never queued
        self.frames_looked = 0
        self.bit_depth = StreamDepth()  # a 16-bit camera's depth, held over its frames
        self._skipped_said, self._skipped_said_at = 0, -math.inf  # the skipped count last reported, and when
        self.feedback_published = 0  # ~/feedback images: drawn only while someone subscribes
        self.frames_without_board = 0  # looked at before any view was found
        self.hint_frames: list = []  # a few of them, for the board spec's usual mistakes
        self.hinted = False
        self.camera: BrownCamera | None = None
        self.rms: float = math.inf
        self.served_metadata: dict = {}  # what the served calibration records of its fit: judged against
        self.pending: tuple | None = None  # a fit kept back (or from fewer than min_views): ~/commit, ~/discard
        self.fitted = False
        self.fit_view: FitView | None = None
        self.info_pub = self.create_publisher(CameraInfo, "camera_info", LATCHED_QOS)
        # what camera_info cannot carry (tone curve, medium, distance), for an area node given camera_info only
        self.metadata_pub = self.create_publisher(String, "camera_info/metadata", LATCHED_QOS)
        self.progress_pub = self.create_publisher(CalibrationProgress, "~/progress", RESULT_QOS)
        self.feedback_pub = self.create_publisher(Image, "~/feedback", IMAGE_QOS)
        self.create_subscription(image_type, image_topic, self._on_image, IMAGE_QOS, raw=True)  # a view, no copy
        self.input_watch = InputWatch(self, image_topic)
        self.warn = CountedWarnings(self.get_logger())
        self.create_service(Trigger, "~/calibrate", self._on_calibrate)
        self.create_service(Trigger, "~/commit", self._on_commit)
        self.create_service(Trigger, "~/discard", self._on_discard)
        self.create_service(SetCameraInfo, "set_camera_info", self._on_set_camera_info)
        if self.path is not None and self.path.exists():
            existing = read_start_file(self, "camera_info_url", lambda: read_calibration(self.path),
                                       "serving no calibration until a fit or set_camera_info")
            if existing is not None:
                self._serve(existing.camera, quality_rms(existing), persist=False, metadata=existing.metadata)
                self.get_logger().info(f"serving {self.path} (RMS {self.rms:.3f} px)")
        # frames are looked at in a thread of their own: a 10-megapixel frame's board search must not hold up
        # the executor (services, parameters), and a frame that arrives meanwhile replaces the waiting one
        self._state = threading.Lock()
        self._waiting: bytes | None = None
        self._wake = threading.Condition()
        self._closing = False
        self._looker = threading.Thread(target=self._look_loop, name="calibration-views", daemon=True)
        self._looker.start()

    # --- views -----------------------------------------------------------------------------------------
    def _on_image(self, data: bytes) -> None:
        self.input_watch.frame()
        with self._wake:
            self.frames_seen += 1
            if self._waiting is not None:
                self.frames_skipped += 1
            self._waiting = data
            self._wake.notify()

    def _look_loop(self) -> None:
        while True:
            with self._wake:
                while self._waiting is None and not self._closing:
                    self._wake.wait(0.5)
                if self._closing:
                    return
                data, self._waiting = self._waiting, None
            try:
                with self._state:
                    self._look(data)
                    self.frames_looked += 1
                    if self.frames_skipped != self._skipped_said and time.monotonic() - self._skipped_said_at > 2.0:
                        self._skipped_said, self._skipped_said_at = self.frames_skipped, time.monotonic()
                        self._report(f"{self.frames_skipped} frames skipped so far: they came while an earlier "
                                     "one was looked at")
            except Exception as exc:  # a bug must not end the view collection: said, throttled
                self.warn("frame not looked at", f"{type(exc).__name__}: {exc}")

    def _look(self, data: bytes) -> None:
        try:
            notes: list[str] = []
            image = decode_transported(self.transport, data).pixels(self.bit_depth, notes)
        except ImageMessageError as exc:
            self.warn("frame ignored", str(exc))
            return
        for note in notes:
            self.warn("16-bit frame", note)
        size = (image.shape[1], image.shape[0])
        if self.image_size is None:
            self.image_size = size
            self.guide = CalibrationGuide(self.board, size, self.min_views)
        elif size != self.image_size:
            self.warn("frame ignored", f"{size[0]}x{size[1]}, the views so far are "
                                       f"{self.image_size[0]}x{self.image_size[1]}")
            return
        watched = self.feedback_pub.get_subscription_count() > 0
        collecting = not self.fitted
        if not collecting and not watched:
            return  # a served fit: views are collected again only after ~/calibrate is called
        detection = detect_scaled(self.board, image)
        if detection is None and collecting and not self.views:
            self._no_board_yet(image)
        verdict = None
        if detection is not None and collecting:
            verdict = self.guide.offer(detection, image)
            if verdict.kept:
                self.views.append(View(f"frame{self.frames_seen}", detection))
                self.kept_frames.offer(self.views[-1].name, detection, image)
                self._report(f"view {len(self.views)} kept ({len(detection)} points, coverage "
                             f"{self._coverage():.0%} of an 8x6 grid)")
            elif verdict.kind != "similar":
                self._report(f"view rejected: {verdict.reason}")
        if watched:
            feedback = render_feedback(image, self.guide, None if detection is None else detection.image_points,
                                       verdict, self.fit_view)
            if publish_safely(self, self.feedback_pub, image_bytes(feedback, self.get_clock().now().to_msg(),
                                                                   self.frame_id)):
                self.feedback_published += 1
        if verdict is not None and verdict.kept and self.auto_calibrate and self.guide.enough():
            self._fit()

    def _no_board_yet(self, image: np.ndarray) -> None:
        """Frames while no view was ever found: a few kept, and after HINT_AFTER_FRAMES the board spec's usual
        mistakes tried on them, once, the board found said on ~/progress (a wrong spec looked like an empty view)."""
        self.frames_without_board += 1
        if self.frames_without_board % (HINT_AFTER_FRAMES // HINT_FRAMES) == 0 and not self.hinted:
            self.hint_frames = [*self.hint_frames[-(HINT_FRAMES - 1):], to_grey(image)]
        if self.frames_without_board >= HINT_AFTER_FRAMES and not self.hinted:
            self.hinted = True
            hint = board_hint(self.board, self.hint_frames)
            text = (f"no {self.board} board in the first {self.frames_without_board} frames"
                    + (hint if hint else ": is the board in view, and is the spec (parameter board) the board's?"))
            self.get_logger().warning(text)
            self._report(text)

    def _coverage(self) -> float:
        """The kept views' share of an 8x6 grid over the image: the figure the fit and its file report."""
        if self.image_size is None or not self.views:
            return 0.0
        return float(coverage_grid([v.detection.image_points.reshape(-1, 2) for v in self.views],
                                   *self.image_size, *COVERAGE_CELLS).mean())

    def _report(self, text: str, **extra) -> None:
        self.get_logger().info(text)
        guide = self.guide.summary() if self.guide is not None else {}
        state = {"views_kept": len(self.views), "frames_seen": self.frames_seen,
                 "frames_looked": self.frames_looked, "frames_skipped": self.frames_skipped,
                 "feedback_published": self.feedback_published,
                 "coverage": self._coverage(),
                 "fitted": self.fitted, "rms_px": None if math.isinf(self.rms) else self.rms, "message": text,
                 **{k: v for k, v in guide.items() if k != "views_kept"}, **extra}
        stamp = self.get_clock().now().to_msg()
        publish_safely(self, self.progress_pub, progress_message(state, stamp, self.frame_id))

    # --- fitting and serving ---------------------------------------------------------------------------
    def _fit(self) -> tuple[bool, str]:
        missing = self.guide.still_needed() if self.guide is not None else "views of the board"
        lacking = f"; the views still lack variety: {missing}" if missing else ""
        if self.image_size is None or len(self.views) < 4:
            return False, f"{len(self.views)} views kept; at least 4 are needed (12+ recommended){lacking}"
        try:
            result = calibrate(self.views, self.image_size, model=self.get_parameter("model").value)
        except CalibrationError as exc:
            self._report(f"fit failed: {exc}{lacking}")
            return False, f"{exc}{lacking}"
        self.fitted = True
        self.fit_view = FitView(result.rms_px, dict(result.std), result.projection_std_px,
                                result.image_points[-1] if result.image_points else None,
                                result.residuals[-1] if result.residuals else None, fit_reach(result.camera))
        warnings = list(result.warnings)
        metadata = fit_metadata(result.summary(), self.medium, self.distance, str(self.board), "calibration_node")
        tone = self.kept_frames.judge(result.used(self.views), result.camera)
        metadata.update(tone.metadata())  # the tone curve, edge trend and reading measuring takes, and why
        described = (f"{result.views_used} views ({result.camera.model}"
                     + (f"; {result.model_choice['reason']}" if result.model_choice else "")
                     + f"): RMS {result.rms_px:.4f} px, fx {result.camera.fx:.2f} fy {result.camera.fy:.2f} "
                     f"cx {result.camera.xp:.2f} cy {result.camera.yp:.2f}; tone curve "
                     + (tone.curve if tone.decided else tone.reason)
                     + ("" if tone.reading is None else "; area mode " + (
                         f"{tone.reading.mode} (its views spread {100 * tone.reading.spreads['subpixel']:.2f} % with "
                         f"the shares, {100 * tone.reading.spreads['count']:.2f} % counted)" if tone.reading.decided
                         else tone.reading.reason)))
        verdict = (judge(self.camera, self.served_metadata, result) if self.camera is not None
                   else Judgement(True, "no calibration served yet"))
        if not verdict.replace:
            self.pending = (result.camera, result.rms_px, metadata)
            text = (f"fitted on {described}; kept the served calibration: {verdict.reason}; ~/commit serves and "
                    f"writes this fit, ~/discard drops it{lacking}")
            self._report(text, warnings=warnings)
            return False, text
        if result.views_used < self.min_views:  # served, but written only on request
            self.pending = (result.camera, result.rms_px, metadata)
            self._serve(result.camera, result.rms_px, persist=False, metadata=metadata)
            text = (f"calibrated on {described}; served but not written to camera_info_url: {result.views_used} "
                    f"views, fewer than min_views {self.min_views} (~/commit writes it){lacking}")
        else:
            self.pending = None
            self._serve(result.camera, result.rms_px, persist=True, metadata=metadata)
            text = f"calibrated on {described} ({verdict.reason}){lacking}"
        self._report(text, warnings=warnings)
        for warning in warnings:
            self.get_logger().warning(warning)
        return True, text

    def _on_commit(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Serve and write the fit waiting for a decision (kept back, or from fewer than min_views)."""
        with self._state:
            if self.pending is None:
                response.success, response.message = False, "no fit is waiting (~/calibrate fits one)"
                return response
            camera, rms, metadata = self.pending
            failed = self._serve(camera, rms, persist=True, metadata=metadata)
            self.pending = None
        response.success = failed is None
        response.message = failed or f"committed: served and written to {self.path}"
        self._report(response.message)
        return response

    def _on_discard(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self._state:
            had, self.pending = self.pending is not None, None
        response.success, response.message = had, "discarded the waiting fit" if had else "no fit is waiting"
        return response

    def _serve(self, camera: BrownCamera, rms: float, persist: bool, metadata: dict | None = None) -> str | None:
        """Publish (latched) and, with `persist`, write the calibration; the reason the write failed, or None."""
        failed = None
        if persist and self.path is not None:
            try:
                write_calibration(self.path, camera, self.camera_name, metadata)
            except OSError as exc:
                failed = f"not written to {self.path}: {exc.strerror or exc}"
                self.get_logger().error(f"calibration served but {failed}")
        self.camera, self.rms, self.served_metadata = camera, rms, metadata or {}
        info = camera_to_info(camera, self.frame_id, self.get_clock().now().to_msg())
        publish_safely(self, self.metadata_pub, String(data=metadata_message(camera, self.served_metadata)))
        publish_safely(self, self.info_pub, info)
        return failed

    def _on_calibrate(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self._state:
            self.fitted = False  # a fit on request: also resumes collecting views afterwards
            response.success, response.message = self._fit()
        return response

    def destroy_node(self) -> None:
        with self._wake:
            self._closing = True
            self._wake.notify()
        self._looker.join(timeout=30)
        super().destroy_node()

    def _on_set_camera_info(self, request: SetCameraInfo.Request, response: SetCameraInfo.Response
                            ) -> SetCameraInfo.Response:
        try:
            camera = info_to_camera(request.camera_info)
        except ValueError as exc:
            response.success, response.status_message = False, f"refused: {exc}"
            return response
        # an explicit replacement by the user: persisted and served whatever its RMS (unknown here); not while
        # the views' thread fits and serves
        with self._state:
            failed = self._serve(camera, math.inf, persist=True, metadata={"source": "set_camera_info",
                                                                           **provenance("calibration_node")})
            self.fitted = True
        if failed:  # served, but a service must not say a failed write succeeded
            response.success, response.status_message = False, f"camera_info set and served but {failed}"
            return response
        response.success, response.status_message = True, f"camera_info set and written to {self.path}"
        self.get_logger().info(response.status_message)
        return response


def main(args: list[str] | None = None) -> int:
    return run_nodes([CalibrationNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
