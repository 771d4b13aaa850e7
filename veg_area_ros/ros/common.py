"""What every node shares: parameter declaration with descriptors, safe publishing, the QoS profiles and
the process entry point."""

from __future__ import annotations

import os
import signal
import sys
import time
import traceback
from collections.abc import Callable

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from ..latest import REMEMBERED
from ..transport import Transport, buffer_warning, choose_transport

# images: what camera drivers use (best effort, newest frame only); a slow consumer never queues frames
IMAGE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)
SENSOR_QOS = qos_profile_sensor_data
# camera_info from a calibration: latched, so a node that starts later still gets the calibration
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
RESULT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=50, reliability=ReliabilityPolicy.RELIABLE)
# camera_info as the area node takes it, on two subscriptions. Both deep: while a slow frame (the first builds the
# pixel weights) is measured, each frame's camera_info waits and is counted (depth 1 keeps the newest).
# Latched: gets a calibration published before the node started (calibration_node, camera_node); a volatile
# publisher cannot match it.
PER_FRAME_INFO_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=REMEMBERED,
                                reliability=LATCHED_QOS.reliability, durability=LATCHED_QOS.durability)
# Any publisher: best effort + volatile matches every offered QoS, so camera drivers that publish camera_info
# volatile with each frame (usb_cam, v4l2_camera, `ros2 bag play` of a bag without offered QoS) are heard too.
ANY_INFO_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=REMEMBERED, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)


def declare(node: Node, name: str, default, description: str, *, low: float | None = None,
            high: float | None = None, choices: tuple[str, ...] = (), read_only: bool = False):
    """Declare a parameter with a descriptor (and a range or the allowed values in its description)."""
    text = description + (f" One of: {', '.join(choices)}." if choices else "")
    descriptor = ParameterDescriptor(description=text, read_only=read_only)
    if low is not None and high is not None and not isinstance(default, bool):
        if isinstance(default, int):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=0)]
        elif isinstance(default, float):
            descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high),
                                                                  step=0.0)]
    return node.declare_parameter(name, default, descriptor).value


class CountedWarnings:
    """Throttled log lines that say what the throttle hid. Throttled per kind and detail (a new problem is
    always shown); each line carries how many of its kind came so far and how many like it were not shown
    since its last line (rclpy's throttle drops them unsaid)."""

    def __init__(self, logger, period_s: float = 5.0, clock: Callable[[], float] = time.monotonic):
        self._logger, self._period, self._clock = logger, period_s, clock
        self._total: dict[str, int] = {}
        self._hidden: dict[tuple[str, str], int] = {}
        self._last: dict[tuple[str, str], float] = {}

    def __call__(self, kind: str, detail: str, level: str = "warning") -> None:
        self._total[kind] = self._total.get(kind, 0) + 1
        key, now = (kind, detail), self._clock()
        if key in self._last and now - self._last[key] < self._period:
            self._hidden[key] = self._hidden.get(key, 0) + 1
            return
        if len(self._last) > 1000:  # details with ever-new text must not grow this without bound
            self._last.clear()
        hidden = self._hidden.pop(key, 0)
        since = f", {hidden} like it not shown since its last line" if hidden else ""
        getattr(self._logger, level)(f"{kind}: {detail} ({self._total[kind]} so far{since})")
        self._last[key] = now

    def total(self, kind: str) -> int:
        return self._total.get(kind, 0)


def publish_safely(node: Node, publisher, msg) -> bool:
    """Publish; a transport under back-pressure raises RCLError: log it (throttled) and go on. After Ctrl-C
    (the context is shut down) there is nobody to tell: nothing is sent, nothing logged."""
    if not node.context.ok():
        return False
    try:
        publisher.publish(msg)
        return True
    except Exception as exc:  # rclpy raises RCLError (not importable by a stable name) or RuntimeError
        node.get_logger().warning(f"publishing on {publisher.topic_name} failed: {exc}", throttle_duration_sec=5.0)
        return False


def ensure_ros_environment() -> Transport:
    """Before rclpy.init(): HOME or ROS_LOG_DIR (rclpy needs one; a service manager may give neither), and the
    transport (veg_area_ros.transport's rule), which is returned to be logged once the node is up."""
    if "HOME" not in os.environ and "ROS_LOG_DIR" not in os.environ:
        os.environ["ROS_LOG_DIR"] = "/tmp/veg_area_ros_log"
    transport = choose_transport(dict(os.environ))
    transport.apply(os.environ)
    return transport


def log_transport(transport: Transport) -> None:
    """The transport in use, once per process, and what may keep images from other machines."""
    from rclpy.logging import get_logger

    logger = get_logger("veg_area_ros")
    logger.info(f"transport: {transport.description}")
    warning = buffer_warning(transport)
    if warning:
        logger.warning(warning)


QUIET_INPUT_S = 10.0  # a node without frames for this long says why it may be


class InputWatch:
    """Says in the log, every QUIET_INPUT_S without a frame, whether a publisher of the node's image topic has
    matched at all, with the transport in use: the first thing to check when a camera gives no Af."""

    def __init__(self, node: Node, topic: str):
        self.node, self.topic = node, node.resolve_topic_name(topic)
        self.transport = choose_transport(dict(os.environ)).description
        self.frames = 0
        self._seen_at_last_check = 0
        node.create_timer(QUIET_INPUT_S, self._check)

    def frame(self) -> None:
        self.frames += 1

    def _check(self) -> None:
        if self.frames > self._seen_at_last_check:
            self._seen_at_last_check = self.frames
            return
        publishers = self.node.count_publishers(self.topic)
        if publishers == 0:
            reason = f"no publisher of {self.topic} matched"
        else:
            reason = f"{publishers} publisher(s) of {self.topic} matched but no frame arrived"
        self.node.get_logger().warning(f"{reason} in the last {QUIET_INPUT_S:g} s (transport: {self.transport}; "
                                       "another machine's nodes need the same transport and ROS_DOMAIN_ID)")


class StopOnSignal:
    """Ctrl-C / SIGTERM ask the spin loop to stop after the callback that is running: rclpy's own handlers
    raise KeyboardInterrupt wherever Python happens to be, e.g. between a bag record and its count (a bag
    whose metadata then disagrees with its data). A second signal interrupts at once (a callback that hangs);
    none does while the nodes close (a recorder writing its bag's summary)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.requested = False
        self.closing = False
        self._previous = {number: signal.signal(number, self._handle) for number in self.SIGNALS}

    def _handle(self, number: int, frame) -> None:
        if self.closing:
            os.write(2, b"veg_area_ros: closing (files are being written)\n")
            return
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        os.write(2, b"veg_area_ros: stopping after the current callback (again to interrupt it)\n")

    def restore(self) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)


def run_nodes(factories: list[Callable[[], Node]], args: list[str] | None = None) -> int:
    """Create the nodes, spin them in one executor until Ctrl-C / SIGTERM / shutdown, clean up. Exit code 0
    on a clean stop (a node may call `request_stop()` on itself, e.g. at the end of a video), 1 on a failure,
    130 when a second Ctrl-C interrupted a callback."""
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.logging import get_logger
    from rclpy.signals import SignalHandlerOptions

    try:
        transport = ensure_ros_environment()
    except ValueError as exc:  # a mistyped VEG_AREA_TRANSPORT
        print(f"veg_area_ros: {exc}", file=sys.stderr)
        return 2
    # rclpy's handlers stay out; ours go in after init, so a slow rcl_init is still interrupted as usual
    rclpy.init(args=args if args is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    stop = StopOnSignal()
    log_transport(transport)
    executor = SingleThreadedExecutor()
    nodes: list[Node] = []
    code = 0
    try:
        for factory in factories:
            nodes.append(factory())
            executor.add_node(nodes[-1])
        while rclpy.ok() and not stop.requested and not any(getattr(n, "stop_requested", False) for n in nodes):
            try:
                executor.spin_once(timeout_sec=0.1)
            except ExternalShutdownException:
                raise
            except Exception:  # a callback's bug must not end a measurement run: said, and the nodes go on
                get_logger("veg_area_ros").error(
                    f"a callback failed, the nodes go on:\n{traceback.format_exc()}", throttle_duration_sec=10.0)
    except KeyboardInterrupt:
        code = 130
    except ExternalShutdownException:
        pass
    except Exception as exc:  # a node that cannot start (bad parameter file, ...) says why and exits 1
        print(f"veg_area_ros: {exc}", file=sys.stderr)
        code = 1
    finally:
        stop.closing = True
        try:
            for node in nodes:
                node.destroy_node()
            if rclpy.ok():
                rclpy.try_shutdown()
        finally:
            stop.restore()
    # a node may end its run with a failure of its own (a recorder whose topics never appeared)
    return code or max((getattr(node, "exit_code", 0) for node in nodes), default=0)
