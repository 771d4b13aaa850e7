"""console_node: the operator's console, a web page (http://127.0.0.1:8080 by default) with the live image
(the area node's overlay, the calibration node's feedback or the camera), Af over time with its std band, the
warnings and frame counts, the calibration's progress with its fit / commit / discard services, the area
node's tuned parameters (set through its parameter services, so `ros2 param get` sees the same values), a ROI
drawn on the image, and the package's recorder started and stopped.

Images reach the page at most MAX_RATE_HZ times a second (BUSY_RATE_HZ while the machine's cores are busy, said
on the page), no wider than MAX_WIDTH_PX; a view's topic is
subscribed only while a page shows it (the area node draws its overlay only for subscribers). Bound to
127.0.0.1 by default; with host:=0.0.0.0 the page changes nothing without the token printed at start."""

from __future__ import annotations

import datetime as dt
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from rcl_interfaces.srv import GetParameters, SetParametersAtomically
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo
from std_srvs.srv import Trigger

from veg_area_msgs.msg import CalibrationProgress, ProjectedArea

from ..cdr import ImageMessageError, decode_camera_info, stamp_ns
from ..console_server import ConsoleServer
from ..console_state import (
    TUNED,
    VIEWS,
    Access,
    AreaSeries,
    CalibrationLog,
    ImageFeed,
    LoadGovernor,
    checked_parameters,
    cpu_pressure,
    folder_size,
    now,
)
from ..stream_thinning import StreamRate, Thinning
from .messages import (
    FRAME_COUNTS,
    IMAGE_TRANSPORT_HELP,
    IMAGE_TRANSPORTS,
    decode_transported,
    progress_as_dict,
    transported_image,
)
from .params import declare
from .qos import IMAGE_QOS, LATCHED_QOS, RESULT_QOS
from .run import lower_priority, run_nodes

if TYPE_CHECKING:
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterValue
    from rclpy.client import Client
    from rclpy.task import Future

SERVICE_WAIT_S = 1.0  # a node whose service is not there within this long is said to be missing
FIT_TIMEOUT_S = 600.0  # a fit of many views with model auto takes minutes on a slow machine
CALL_TIMEOUT_S = 20.0
RECORDER_STOP_S = 60.0  # the recorder writes its bag's summary when stopped
CALIBRATION_SERVICES = {"fit": "calibrate", "commit": "commit", "discard": "discard"}
CAMERA_INFO_PER_S = 2.0  # camera_info: only the served calibration is shown
THINNED_SILENCE_S = 2.0  # a thinned stream that brought nothing for this long is taken whole again


class ConsoleNode(Node):
    def __init__(self, name: str = "console_node", own_process: bool = False, **kwargs):
        super().__init__(name, **kwargs)
        nice = declare(self, "cpu_nice", 10, "How far the console yields the CPU to the measurement: its "
                       "niceness is raised by this much at start when it runs in its own process (0 = as the "
                       "other nodes). Where the camera and area nodes keep every core busy, the console and so "
                       "the pages' images then get what they leave; with a core to spare nothing changes.",
                       low=0, high=19, read_only=True)
        if own_process and nice > 0:  # before the server's threads start: they inherit it
            niceness = lower_priority(nice)
            if niceness is None:
                self.get_logger().warning("cpu_nice: this OS has no niceness; the console runs as the other nodes")
            else:
                self.get_logger().info(f"console at niceness {niceness} (cpu_nice): the measurement comes first")
        host = declare(self, "host", "127.0.0.1", "Address the page is served on; beyond loopback (0.0.0.0, a "
                       "lab address) the page changes nothing without the token printed at start.", read_only=True)
        port = declare(self, "port", 8080, "TCP port of the page.", low=1, high=65535, read_only=True)
        token = declare(self, "token", "", "The token that allows changes ('' = a new one at each start).",
                        read_only=True)
        self.area_name = declare(self, "area_node", "area_node", "The area node's name (its parameters and "
                                 "topics).", read_only=True).strip("/")
        self.calibration_name = declare(self, "calibration_node", "calibration_node", "The calibration node's name "
                                        "(its services, ~/progress and ~/feedback).", read_only=True).strip("/")
        folder = declare(self, "record_folder", "", "Folder the recorder's bags go in ('' = the current folder).",
                         read_only=True)
        self.record_folder = Path(folder or os.getcwd())
        self.access = Access.for_host(host, token)
        self.feeds = {view: ImageFeed() for view in VIEWS}
        self.series = AreaSeries()
        self.calibration_log = CalibrationLog()
        self.load = LoadGovernor()
        self.parameters: dict = {}
        self.present: dict[str, bool] = {self.area_name: False, self.calibration_name: False}
        self.recorder: subprocess.Popen | None = None
        self.bag: Path | None = None
        self._recorder_lock = threading.Lock()
        self._parameters_asked_at: float | None = None  # a get_parameters call in flight since
        # the area node's preview: its overlay at a bounded rate (every frame's overlay would cost it a remap each)
        transport = declare(self, "image_transport", "raw", f"{IMAGE_TRANSPORT_HELP} (the camera view; the "
                            "overlay and the feedback are raw).", choices=IMAGE_TRANSPORTS, read_only=True)
        _, camera_topic = transported_image(transport)
        self.view_topics = {"area": "overlay/preview",
                            "calibration": f"/{self.calibration_name}/feedback", "camera": camera_topic}
        self.view_transports = {"area": "raw", "calibration": "raw", "camera": transport}
        self.view_subscriptions: dict = {}
        # results and camera_info come at the camera's rate: each is thinned to what the page shows, at the rate
        # the results' frame counter tells, and camera_info's own (counted while it comes whole)
        self.rates = {"results": StreamRate(), "camera_info": StreamRate()}
        results_per_s = declare(self, "results_per_s", 30.0, "Results the console takes a second at most (the "
                                "chart's points, the newest warnings and counts): a faster measurement's are "
                                "thinned by their stamps in DDS (a content filter) before they cost the console or "
                                "the area node anything; the page says so. Every result is still published.",
                                low=1.0, high=1000.0, read_only=True)
        self.thinned = {"results": Thinning(results_per_s), "camera_info": Thinning(CAMERA_INFO_PER_S)}
        self.last_taken = {"results": now(), "camera_info": now()}
        self.camera_infos_taken = 0
        self.thinned_subscriptions = {
            "results": self.create_subscription(ProjectedArea, "projected_area", self._on_area, RESULT_QOS),
            "camera_info": self.create_subscription(CameraInfo, "camera_info", self._on_camera_info, LATCHED_QOS,
                                                    raw=True)}
        self.create_subscription(CalibrationProgress, f"/{self.calibration_name}/progress", self._on_progress,
                                 RESULT_QOS)
        self.get_client = self.create_client(GetParameters, f"/{self.area_name}/get_parameters")
        self.set_client = self.create_client(SetParametersAtomically, f"/{self.area_name}/set_parameters_atomically")
        self.calibration_clients = {action: self.create_client(Trigger, f"/{self.calibration_name}/{service}")
                                    for action, service in CALIBRATION_SERVICES.items()}
        self.create_timer(0.5, self._look_around)
        self.server = ConsoleServer(self.feeds, self.state, self, self.access, port)
        self.server.start()  # an address in use or not on this machine: the node does not start, and says so
        shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
        address = f"http://{shown if ':' not in shown else f'[{shown}]'}:{port}/"
        if self.access.loopback_only:
            self.get_logger().info(f"console on {address} (this machine only)")
        else:
            self.get_logger().warning(f"console open to the network on {host}:{port}; to change anything open "
                                      f"{address}?token={self.access.token} (without the token it is view-only)")

    # --- what comes from the graph ---------------------------------------------------------------------------
    def _on_area(self, msg: ProjectedArea) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self.last_taken["results"] = now()
        self.rates["results"].add(stamp, msg.frames_measured)
        self.series.add_area(stamp, msg.area_m2, msg.area_std_m2)
        self.series.add_info(lambda: result_summary(msg))

    def _on_progress(self, msg: CalibrationProgress) -> None:
        self.calibration_log.add_progress(progress_as_dict(msg))

    def _on_camera_info(self, data: bytes) -> None:
        self.last_taken["camera_info"] = now()
        try:
            info = decode_camera_info(data)
            stamp = stamp_ns(data) * 1e-9
        except (ImageMessageError, ValueError):
            return
        self.camera_infos_taken += 1
        if not self.thinned["camera_info"].filtered:
            self.rates["camera_info"].add(stamp, self.camera_infos_taken)
        k = list(info.k)
        self.calibration_log.served = {"model": info.distortion_model, "width": info.width, "height": info.height,
                                       "fx": k[0], "fy": k[4], "cx": k[2], "cy": k[5], "d": list(info.d)}

    def _on_view(self, view: str, data: bytes) -> None:
        # decoded only if a page is shown it
        self.feeds[view].offer(lambda: decode_transported(self.view_transports[view], data).pixels())

    def _look_around(self) -> None:
        """Which nodes are up, the area node's parameters, and the views' topics subscribed while shown."""
        names = {name.strip("/") if not ns.strip("/") else f"{ns.strip('/')}/{name}"
                 for name, ns in self.get_node_names_and_namespaces()}
        self.present = {self.area_name: self.area_name in names, self.calibration_name: self.calibration_name in names}
        moment = now()
        in_flight = self._parameters_asked_at is not None and moment - self._parameters_asked_at < CALL_TIMEOUT_S
        if self.present[self.area_name] and not in_flight and self.get_client.service_is_ready():
            self._parameters_asked_at = moment  # an answer lost with a node that went: asked again after a while
            future = self.get_client.call_async(GetParameters.Request(names=list(TUNED)))
            future.add_done_callback(self._got_parameters)
        self.load.update(cpu_pressure())
        self._thin(moment)
        for view, feed in self.feeds.items():
            feed.max_rate_hz = self.load.image_rate_hz
            subscribed = view in self.view_subscriptions
            if feed.wanted(moment) and not subscribed:
                self.view_subscriptions[view] = self.create_subscription(
                    transported_image(self.view_transports[view])[0], self.view_topics[view],
                    lambda data, v=view: self._on_view(v, data),
                    IMAGE_QOS, raw=True)
            elif subscribed and not feed.wanted(moment):
                self.destroy_subscription(self.view_subscriptions.pop(view))

    def _thin(self, moment: float) -> None:
        """Move each fast stream's content filter to its rate; a filtered stream that went silent (its rate
        fell, or its phase left every window) is taken whole until its rate is known again. camera_info is
        thinned only while one node publishes it (a driver's, with every frame): a second publisher's one
        message (a calibration node serving a new fit) must not fall between the windows."""
        for stream, thinning in self.thinned.items():
            subscription = self.thinned_subscriptions[stream]
            if thinning.filtered and moment - self.last_taken[stream] > THINNED_SILENCE_S:
                self.rates[stream] = StreamRate()
            rate = self.rates[stream].rate_hz
            if stream == "camera_info" and self.count_publishers(subscription.topic_name) != 1:
                rate = None
            change = thinning.change(rate)
            if change is False:
                continue
            try:
                subscription.set_content_filter(*(change or ("", [])))
            except Exception as exc:  # a middleware without content filters: the stream is taken whole
                thinning.filtered, thinning.per_s = False, 0.0  # for good: no windows are made for 0 a second
                self.get_logger().info(f"{subscription.topic_name} taken whole: no content filter here ({exc})")

    def _got_parameters(self, future: Future) -> None:
        self._parameters_asked_at = None
        response = future.result()
        if response is None:
            return
        values = {name: Parameter.from_parameter_msg(_named(name, value)).value
                  for name, value in zip(TUNED, response.values, strict=False)}
        self.parameters = {name: list(v) if isinstance(v, tuple | list) or hasattr(v, "tolist") else v
                           for name, v in values.items()}

    # --- what the page reads ---------------------------------------------------------------------------------
    def state(self, shown: tuple[int, int] | None = None) -> dict:
        """What a page shows; `shown`: the (run, appended) of the Af series the page has (AreaSeries.as_dict)."""
        recording = None
        with self._recorder_lock:
            if self.bag is not None:
                running = self.recorder is not None and self.recorder.poll() is None
                recording = {"bag": str(self.bag), "bytes": folder_size(self.bag), "running": running,
                             "started": self.bag.exists(),  # the recorder creates it once it is up
                             "exit_code": None if running else self.recorder.returncode}
        return {"nodes": {"area": {"name": self.area_name, "present": self.present[self.area_name]},
                          "calibration": {"name": self.calibration_name,
                                          "present": self.present[self.calibration_name]}},
                "area": self.series.as_dict(shown), "calibration": self.calibration_log.as_dict(),
                "parameters": self.parameters, "recording": recording, "load": self.load.as_dict(),
                "thinned": {stream: {"rate_hz": thinning.applied_rate_hz, "per_s": thinning.per_s}
                            if thinning.filtered else None for stream, thinning in self.thinned.items()}}

    # --- what the page asks for (from the server's worker threads) --------------------------------------------
    def _call(self, client: Client, request: object, timeout: float, missing: str) -> tuple[object | None, str]:
        if not client.wait_for_service(timeout_sec=SERVICE_WAIT_S):
            return None, missing
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout):
            future.cancel()
            return None, f"no answer from {client.srv_name} within {timeout:.0f} s"
        return future.result(), ""

    def set_parameters(self, values: dict) -> tuple[bool, str]:
        checked = checked_parameters(values)
        request = SetParametersAtomically.Request(
            parameters=[Parameter(name, value=value).to_parameter_msg() for name, value in checked.items()])
        response, problem = self._call(self.set_client, request, CALL_TIMEOUT_S,
                                       f"{self.area_name} is not running: nothing was changed")
        if response is None:
            return False, problem
        if not response.result.successful:
            return False, f"{self.area_name} refused: {response.result.reason}"
        self.parameters.update(checked)
        said = ", ".join(f"{k} {v}" for k, v in checked.items())
        self.get_logger().info(f"set on {self.area_name} from the console: {said}")
        return True, f"set: {said}"

    def calibration(self, action: str) -> tuple[bool, str]:
        response, problem = self._call(self.calibration_clients[action], Trigger.Request(),
                                       FIT_TIMEOUT_S if action == "fit" else CALL_TIMEOUT_S,
                                       f"{self.calibration_name} is not running: nothing was done")
        if response is None:
            return False, problem
        self.calibration_log.add_result(f"{action}: {response.message}")
        return bool(response.success), response.message

    def record(self, action: str) -> tuple[bool, str]:
        with self._recorder_lock:
            running = self.recorder is not None and self.recorder.poll() is None
            if action == "start":
                if running:
                    return False, f"already recording into {self.bag}"
                bag = self.record_folder / dt.datetime.now().strftime("veg_area_%Y%m%d_%H%M%S")
                if bag.exists():
                    return False, f"{bag} exists (one bag a second at most)"
                try:
                    self.record_folder.mkdir(parents=True, exist_ok=True)
                    log = open(self.record_folder / f"{bag.name}.log", "wb")  # noqa: SIM115 - the child's
                except OSError as exc:
                    return False, f"cannot record into {self.record_folder}: {exc.strerror or exc}"
                with log:
                    self.recorder = subprocess.Popen(
                        [sys.executable, "-m", "veg_area_ros.ros.record_node", "--ros-args", "-r",
                         f"__node:={self.get_name()}_recorder", "-p", f"output:={bag}"],
                        stdout=log, stderr=subprocess.STDOUT, preexec_fn=_die_with_parent)
                self.bag = bag
                self.get_logger().info(f"recording into {bag}")
                return True, f"recording into {bag}"
            if not running:
                return False, "not recording"
            return self._stop_recorder()

    def _stop_recorder(self) -> tuple[bool, str]:
        self.recorder.send_signal(signal.SIGINT)
        try:
            code = self.recorder.wait(RECORDER_STOP_S)
        except subprocess.TimeoutExpired:
            self.recorder.kill()
            code = self.recorder.wait()
        size = folder_size(self.bag)
        done = code == 0
        said = (f"bag {self.bag} closed, {size / 1e6:.1f} MB" if done else
                f"the recorder ended with exit code {code} (see {self.bag}.log); {size / 1e6:.1f} MB in {self.bag}")
        self.get_logger().info(said)
        return done, said

    def destroy_node(self) -> None:
        self.server.stop()
        with self._recorder_lock:
            if self.recorder is not None and self.recorder.poll() is None:
                self._stop_recorder()
        super().destroy_node()


def result_summary(msg: ProjectedArea) -> dict:
    """What the page shows of a result beside its Af (AreaSeries.as_dict): the warnings, the classification and
    the area node's frame counts (None where it cannot know them)."""
    counts = {name: None if getattr(msg, name) < 0 else getattr(msg, name) for name in FRAME_COUNTS}
    return {"warnings": list(msg.warnings), "area_mode": msg.area_mode, "subpixel_applied": msg.subpixel_applied,
            "threshold": msg.threshold, "calibrated": msg.calibrated, "pixel_count": msg.pixel_count,
            "frames_measured": counts["frames_measured"], "frames_skipped": counts["frames_skipped"],
            "frames_lost": counts["frames_lost"], "frames_received": counts["frames_received"]}


def _named(name: str, value: ParameterValue) -> ParameterMsg:
    from rcl_interfaces.msg import Parameter as ParameterMsg

    return ParameterMsg(name=name, value=value)


def _die_with_parent() -> None:
    """The recorder is stopped (SIGINT) when the console closes; if the console is killed, it is too."""
    import ctypes

    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGINT)  # PR_SET_PDEATHSIG: its bag is still closed


def main(args: list[str] | None = None) -> int:
    return run_nodes([lambda: ConsoleNode(own_process=True)], args)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
