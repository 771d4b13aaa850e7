"""The process around the nodes: the ROS environment (log folder, transport), signals that stop the spin
loop between callbacks, and one `run_nodes` used by every node's `main`, the composed graph and the demo."""

from __future__ import annotations

import os
import signal
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import rclpy
from rclpy.node import Node

from ..transport import Transport, buffer_warning, choose_transport

if TYPE_CHECKING:
    from types import FrameType


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

    def _handle(self, number: int, frame: FrameType | None) -> None:
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


EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


def lower_priority(increment: int) -> int | None:
    """Raise the niceness of every thread of this process by `increment` (threads started later inherit it):
    on Linux a thread's niceness is its own, and DDS has started its threads before a node reads its
    parameters. Returns the niceness of the calling thread afterwards, None where the OS has none."""
    if not hasattr(os, "setpriority"):  # Windows
        return None
    if increment <= 0:
        return os.getpriority(os.PRIO_PROCESS, 0)
    tasks = Path("/proc/self/task")
    threads = [int(t.name) for t in tasks.iterdir()] if tasks.is_dir() else [0]
    for thread in threads:
        try:
            now = os.getpriority(os.PRIO_PROCESS, thread)
            os.setpriority(os.PRIO_PROCESS, thread, min(now + increment, 19))
        except ProcessLookupError:  # a thread that ended meanwhile
            continue
    return os.getpriority(os.PRIO_PROCESS, 0)


def warn_unknown_parameters(node: Node) -> None:
    """A parameter given at start (-p, a params file) that the node does not have is said, with the one it was
    likely meant for (`-p rate:=30.0` for rate_hz was ignored in silence)."""
    import difflib

    from rclpy.logging import get_logger

    given = set(getattr(node, "_parameter_overrides", {}))
    declared = set(getattr(node, "_parameters", {}))
    for name in sorted(given - declared):
        close = difflib.get_close_matches(name, sorted(declared), n=1)
        get_logger(node.get_name()).warning(
            f"parameter {name!r} is not one of {node.get_name()}'s parameters: ignored"
            + (f" (did you mean {close[0]!r}?)" if close else ""))


def run_nodes(factories: list[Callable[[], Node]], args: list[str] | None = None,
              until: Callable[[], bool] | None = None) -> int:
    """Create the nodes, spin them in one executor until Ctrl-C / SIGTERM / shutdown or `until()` is true,
    clean up. Exit code 0 on a clean stop (a node may set `stop_requested`, e.g. at the end of a video), 1 on
    a failure, 2 on a mistyped environment, 130 when a second Ctrl-C interrupted a callback. `args`: the
    process's command line (default sys.argv), with its --ros-args."""
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.logging import get_logger
    from rclpy.signals import SignalHandlerOptions

    try:
        transport = ensure_ros_environment()
    except ValueError as exc:  # a mistyped VEG_AREA_TRANSPORT
        print(f"veg_area_ros: {exc}", file=sys.stderr)
        return EXIT_USAGE
    # rclpy's handlers stay out; ours go in after init, so a slow rcl_init is still interrupted as usual
    try:
        rclpy.init(args=args if args is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # rcl's RCLError: a malformed --ros-args (`-p rate_hz` without :=), ROS_DOMAIN_ID=lab
        said = str(exc).splitlines()[0] if str(exc) else exc.__class__.__name__
        print(f"veg_area_ros: ROS cannot start with these --ros-args and ROS_ variables: {said}", file=sys.stderr)
        return EXIT_USAGE
    stop = StopOnSignal()
    log_transport(transport)
    executor = SingleThreadedExecutor()
    nodes: list[Node] = []
    code = EXIT_OK
    try:
        for factory in factories:
            nodes.append(factory())
            executor.add_node(nodes[-1])
            warn_unknown_parameters(nodes[-1])
        while rclpy.ok() and not stop.requested and not any(getattr(n, "stop_requested", False) for n in nodes) \
                and not (until is not None and until()):
            try:
                executor.spin_once(timeout_sec=0.1)
            except ExternalShutdownException:
                raise
            except Exception:  # a callback's bug must not end a measurement run: said, and the nodes go on
                get_logger("veg_area_ros").error(
                    f"a callback failed, the nodes go on:\n{traceback.format_exc()}", throttle_duration_sec=10.0)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
    except ExternalShutdownException:
        pass
    except Exception as exc:  # a node that cannot start (a value out of range, no such device) says why
        print(f"veg_area_ros: {exc}", file=sys.stderr)
        code = EXIT_FAILED
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
