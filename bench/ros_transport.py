"""Images over ROS 2 on one machine: delivered frames/s and mean/p99 latency for 640x480 and
3872x2592 bgr8, best-effort and reliable QoS, between two processes and composed in one executor, under the
shipped shared-memory profile (`shm`, what the nodes use) and Fast DDS as it comes (`default`), in one run,
confined to this machine like the tests.

    .venv/bin/python bench/ros_transport.py [--seconds 4] [--transports shm,default] [--modes processes,composed]

Frames are published as the camera node does (pre-serialized CDR from a numpy frame, a fresh stamp each)
and taken with a raw subscription; latency = arrival - stamp. Each case gets its own ROS domain.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from rosbench import (
    TRANSPORTS,
    Children,
    bench_main,
    figure,
    latency_ms,
    role_command,
    transport_environment,
)

SCRIPT = Path(__file__).resolve()

LOADS = ((640, 480, 30.0), (640, 480, 1000.0), (3872, 2592, 2.0), (3872, 2592, 30.0))
QOS_KINDS = ("best_effort", "reliable")
MODES = ("processes", "composed")
MATCH_TIMEOUT_S = 30.0


def qos_profile(kind: str):
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from veg_area_ros.ros.qos import IMAGE_QOS

    if kind == "best_effort":
        return IMAGE_QOS  # the nodes' image QoS: best effort, newest frame only
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE)


def done_qos():
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def publisher_node(spec: dict):
    """Publishes spec['frames'] frames at spec['rate'] once a subscriber matched (or until the time cap), then
    a JSON summary on `bench_done` (latched)."""
    import numpy as np
    from rclpy.node import Node
    from sensor_msgs.msg import Image
    from std_msgs.msg import String

    from veg_area_ros.cdr import encode_image

    class FramePublisher(Node):
        def __init__(self) -> None:
            super().__init__("bench_publisher")
            self.frame = np.random.default_rng(0).integers(0, 255, (spec["height"], spec["width"], 3), np.uint8)
            self.images = self.create_publisher(Image, "bench_image", qos_profile(spec["qos"]))
            self.done = self.create_publisher(String, "bench_done", done_qos())
            self.created = time.monotonic()
            self.matched_at: float | None = None
            self.first = self.last = 0.0
            self.published = self.failed = 0
            self.finished = False
            self.timer = self.create_timer(1.0 / spec["rate"], self.tick)

        def tick(self) -> None:
            now = time.monotonic()
            if self.matched_at is None:
                if self.images.get_subscription_count():
                    self.matched_at = now
                elif now - self.created > MATCH_TIMEOUT_S:
                    self.finish()
                return
            if now - self.matched_at < 0.5:  # let discovery settle both ways (reliable needs the reader's acks)
                return
            sent = self.published + self.failed
            if sent >= spec["frames"] or (sent and now - self.first > spec["time_cap_s"]):
                self.finish()
                return
            stamp_ns = time.time_ns()
            data = encode_image(self.frame, stamp_ns // 10**9, stamp_ns % 10**9, str(sent))
            try:
                self.images.publish(data)
                self.published += 1
            except Exception:  # RCLError under back-pressure: counted, not fatal
                self.failed += 1
            self.first = self.first or now
            self.last = now

        def finish(self) -> None:
            self.timer.cancel()
            self.finished = True
            summary = {"published": self.published, "failed": self.failed, "matched": self.matched_at is not None,
                       "duration_s": self.last - self.first}
            self.done.publish(String(data=json.dumps(summary)))

    return FramePublisher()


def subscriber_node():
    """Counts frames by sequence number and records latency until the publisher's summary plus a grace."""
    from rclpy.node import Node
    from sensor_msgs.msg import Image
    from std_msgs.msg import String

    from veg_area_ros.cdr import decode_image

    class FrameCounter(Node):
        def __init__(self, qos) -> None:
            super().__init__("bench_subscriber")
            self.sequence: set[int] = set()
            self.latencies: list[float] = []
            self.summary: dict | None = None
            self.summary_at = 0.0
            self.create_subscription(Image, "bench_image", self.on_image, qos, raw=True)
            self.create_subscription(String, "bench_done", self.on_done, done_qos())

        def on_image(self, data: bytes) -> None:
            arrived = time.time()
            header = decode_image(data).header
            self.latencies.append(arrived - header.seconds)
            self.sequence.add(int(header.frame_id))

        def on_done(self, msg) -> None:
            self.summary = json.loads(msg.data)
            self.summary_at = time.monotonic()

        def settled(self) -> bool:
            return self.summary is not None and time.monotonic() - self.summary_at > 0.5

        def result(self) -> dict:
            return {"publisher": self.summary, "received": len(self.sequence), "latency_ms": latency_ms(self.latencies)}

    return FrameCounter


def spin(nodes: list, until, timeout_s: float) -> None:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    deadline = time.monotonic() + timeout_s
    while rclpy.ok() and not until() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)


def role_main(role: str, spec: dict) -> int:
    import rclpy

    from veg_area_ros.ros.run import ensure_ros_environment

    ensure_ros_environment()
    rclpy.init()
    timeout = MATCH_TIMEOUT_S + spec["time_cap_s"] + 20
    try:
        if role == "pub":
            publisher = publisher_node(spec)
            spin([publisher], lambda: publisher.finished, timeout)
            spin([publisher], lambda: False, 3.0)  # the latched summary reaches the subscriber
            return 0
        counter = subscriber_node()(qos_profile(spec["qos"]))
        nodes = [counter] + ([publisher_node(spec)] if role == "composed" else [])
        spin(nodes, counter.settled, timeout)
        print(json.dumps(counter.result()), flush=True)
        return 0
    finally:
        rclpy.try_shutdown()


def run_case(spec: dict, transport: str, mode: str, domain: int) -> dict | None:
    env = transport_environment(transport, domain)
    children = Children()
    timeout = MATCH_TIMEOUT_S + spec["time_cap_s"] + 40
    try:
        if mode == "composed":
            return children.result(children.start(role_command(SCRIPT, "composed", spec), env), timeout)
        counter = children.start(role_command(SCRIPT, "sub", spec), env)
        children.start(role_command(SCRIPT, "pub", spec), env)
        return children.result(counter, timeout)
    finally:
        children.reap()


def inside(args) -> int:
    print(f"{'transport':9} {'mode':9} {'qos':11} {'size':9} {'rate':>6} {'sent':>5} {'got':>5} {'fail':>4} "
          f"{'frames/s':>8} {'mean ms':>8} {'p99 ms':>8}", flush=True)
    domain = 10
    for transport in args.transports.split(","):
        for mode in args.modes.split(","):
            for qos in QOS_KINDS:
                for width, height, rate in LOADS:
                    frames = max(10, int(rate * args.seconds))
                    spec = {"width": width, "height": height, "rate": rate, "qos": qos, "frames": frames,
                            "time_cap_s": 2.0 * frames / rate + 2.0}
                    domain += 1
                    result = run_case(spec, transport, mode, domain)
                    row = f"{transport:9} {mode:9} {qos:11} {f'{width}x{height}':9} {rate:6g}"
                    published = result and result["publisher"]
                    if not published or not published["matched"]:
                        print(f"{row}  (no result: {'timed out' if not result else 'no subscriber matched'})",
                              flush=True)
                        continue
                    latency = result["latency_ms"]
                    fps = result["received"] / max(published["duration_s"], 1e-9)
                    print(f"{row} {published['published']:5d} {result['received']:5d} {published['failed']:4d} "
                          f"{fps:8.1f} {figure(latency['mean']):>8} {figure(latency['p99']):>8}", flush=True)
    print("sent: frames published; got: frames delivered; fail: publish calls that raised (back-pressure);\n"
          "frames/s: delivered per second of publishing; latency from the publisher's stamp to the callback.")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="publishing time per case at the full rate")
    parser.add_argument("--transports", default=",".join(TRANSPORTS))
    parser.add_argument("--modes", default=",".join(MODES))
    return bench_main(SCRIPT, ("pub", "sub", "composed"), role_main, parser, inside)


if __name__ == "__main__":
    sys.exit(main())
