"""Camera -> Af over ROS 2, end to end: the package's camera_node and area_node as separate
processes (pre-serialized frames, raw subscription, newest-frame worker) next to the same pipeline written
with plain rclpy Image messages (message objects both ways, measuring in the subscription callback), at
640x480 and 3872x2592, in one run, confined to this machine like the tests. Prints Af results per second
reaching a third process, mean/p99 latency from the camera's stamp to that arrival, frames the area node
dropped, and the memory each node holds (RSS, and PSS: shared pages split among the processes using them).

    .venv/bin/python bench/ros_pipeline.py [--seconds 5] [--transports shm,default] [--sizes 640x480,3872x2592]
        [--noise 0,2,4]

The camera publishes as fast as it can (timer at 1000 Hz for 640x480, 30 Hz for 3872x2592) a still frame of
the synthetic cube in air with the true calibration, so every frame is measurable.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import deque
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from rosbench import (
    Children,
    bench_main,
    cpu_over,
    cpu_seconds,
    figure,
    latency_ms,
    memory_mb,
    role_command,
    shm_mb,
    transport_environment,
)

SCRIPT = Path(__file__).resolve()

LOADS = ((640, 480, 1000.0), (3872, 2592, 30.0))
PIPELINES = ("veg_area_ros", "plain rclpy")
FIRST_RESULT_TIMEOUT_S = 60.0


def plain_camera(spec: dict):
    """A camera node as one would write it with plain rclpy: an Image message filled from numpy each tick."""
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from veg_area_ros.frames import read_image
    from veg_area_ros.ros.messages import image_to_msg
    from veg_area_ros.ros.qos import IMAGE_QOS

    class PlainCamera(Node):
        def __init__(self) -> None:
            super().__init__("plain_camera")
            self.frame, _ = read_image(Path(spec["still"]))
            self.images = self.create_publisher(Image, "image_raw", IMAGE_QOS)
            self.create_timer(1.0 / spec["rate"], self.tick)

        def tick(self) -> None:
            self.images.publish(image_to_msg(self.frame, self.get_clock().now().to_msg(), "camera"))

    return PlainCamera()


def plain_area(spec: dict):
    """An area node as one would write it with plain rclpy: deserialized Image, measured in the callback."""
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from veg_area_msgs.msg import ProjectedArea
    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.calib_io import read_calibration
    from veg_area_ros.classify import Classifier
    from veg_area_ros.ros.messages import msg_to_image, projected_area
    from veg_area_ros.ros.qos import IMAGE_QOS, RESULT_QOS
    from veg_area_ros.sim.synthetic import scene_targets

    class PlainArea(Node):
        def __init__(self) -> None:
            super().__init__("plain_area")
            camera = read_calibration(Path(spec["calibration"])).camera
            self.measurer = AreaMeasurer(camera, scene_targets(), Classifier(threshold=120.0))
            self.areas = self.create_publisher(ProjectedArea, "projected_area", RESULT_QOS)
            self.create_subscription(Image, "image_raw", self.on_image, IMAGE_QOS)

        def on_image(self, msg: Image) -> None:
            result = self.measurer.measure(msg_to_image(msg))
            self.areas.publish(projected_area(result, msg.header.stamp, msg.header.frame_id, "calibration_file"))

    return PlainArea()


def probe(spec: dict) -> dict:
    """Af results arriving in a third process over spec['seconds'] after the first: rate, latency, drops."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String

    from veg_area_msgs.msg import ProjectedArea
    from veg_area_ros.ros.qos import RESULT_QOS

    node = Node("bench_probe")
    latencies: list[float] = []
    infos: deque[bytes] = deque(maxlen=1)  # the newest, raw: the probe must not slow down what it measures

    def on_area(msg: ProjectedArea) -> None:
        latencies.append(time.time() - (msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9))

    def info(raw: bytes) -> dict:
        return json.loads(deserialize_message(raw, String).data)

    node.create_subscription(ProjectedArea, "projected_area", on_area, RESULT_QOS)
    node.create_subscription(String, "projected_area/info", lambda raw: infos.append(raw), RESULT_QOS,
                             raw=True)
    executor = SingleThreadedExecutor()  # one executor: rclpy.spin_once(node) makes one per call (~ms each)
    executor.add_node(node)
    deadline = time.monotonic() + FIRST_RESULT_TIMEOUT_S
    while not latencies and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    if not latencies:
        return {"results": 0}
    settle = time.monotonic() + 1.0  # past the start-up (pixel weights built on the first frame)
    while time.monotonic() < settle:
        executor.spin_once(timeout_sec=0.05)
    latencies.clear()
    started, window_start = time.monotonic(), time.time()
    first_info = info(infos[-1]) if infos else None
    while time.monotonic() - started < spec["seconds"]:
        executor.spin_once(timeout_sec=0.05)
    elapsed = time.monotonic() - started
    out = {"results": len(latencies), "per_s": len(latencies) / elapsed, "latency_ms": latency_ms(latencies),
           "window": [window_start, time.time()]}
    if first_info and infos:
        last_info = info(infos[-1])
        received = last_info["frames_received"] - first_info["frames_received"]
        skipped = sum((last_info[k] or 0) - (first_info[k] or 0) for k in ("frames_dropped", "frames_lost"))
        out.update(frames_in_per_s=received / elapsed, dropped_share=skipped / max(received + skipped, 1),
                   rebuilds=last_info["weights_rebuilt"] - first_info["weights_rebuilt"], frames=received)
    return out


def profiled_area(spec: dict) -> int:
    """The package's area node under cProfile (wall time, this thread), its statistics written to
    spec['profile'] when the node stops."""
    import cProfile

    from veg_area_ros.ros.area_node import AreaNode
    from veg_area_ros.ros.run import run_nodes

    profiler = cProfile.Profile()
    profiler.enable()
    try:
        return run_nodes([AreaNode], [])
    finally:
        profiler.disable()
        profiler.dump_stats(spec["profile"])


def role_main(role: str, spec: dict) -> int:
    import rclpy

    from veg_area_ros.ros.run import ensure_ros_environment, run_nodes

    if role == "plain_camera":
        return run_nodes([lambda: plain_camera(spec)], [])
    if role == "plain_area":
        return run_nodes([lambda: plain_area(spec)], [])
    if role == "profiled_area":
        return profiled_area(spec)
    ensure_ros_environment()
    rclpy.init()
    try:
        print(json.dumps(probe(spec)), flush=True)
    finally:
        rclpy.try_shutdown()
    return 0


NOISY_FRAMES = 8  # a looped folder of this many frames, each with its own sensor noise (decoded once)


def prepare_inputs(folder: Path, noise: list[float]) -> dict[str, dict[str, str]]:
    """A still frame of the cube in air and the camera's true calibration, per size; and per noise level a
    folder of frames of that still with fresh Gaussian sensor noise each (the camera loops it)."""
    import cv2
    import numpy as np

    from veg_area_ros.calib_io import write_calibration
    from veg_area_ros.sim.synthetic import DSLR, ENDOSCOPE, cube_scene, render_scene

    inputs = {}
    rng = np.random.default_rng(0)
    for camera in (ENDOSCOPE, DSLR):
        size = f"{camera.width}x{camera.height}"
        still, calibration = folder / f"cube_{size}.png", folder / f"camera_{size}.yaml"
        clean = render_scene(camera, cube_scene(), 0.7, None, noise_sigma=0.0, supersample=1 if camera is DSLR else 3)
        cv2.imwrite(str(still), clean)
        write_calibration(calibration, camera, f"bench_{size}", {"medium": "air"})
        inputs[size] = {"still": str(still), "calibration": str(calibration)}
        for sigma in noise:
            if sigma == 0:
                continue
            frames = folder / f"noise_{sigma:g}_{size}"
            frames.mkdir()
            for k in range(NOISY_FRAMES):
                noisy = clean + rng.normal(0.0, sigma, clean.shape[:2]).astype(np.float32)[..., None]
                cv2.imwrite(str(frames / f"frame{k}.png"), np.clip(np.rint(noisy), 0, 255).astype(np.uint8))
            inputs[f"{size} noise {sigma:g}"] = {"still": str(frames), "calibration": str(calibration)}
    return inputs


def node_command(module: str, **parameters) -> list[str]:
    command = [sys.executable, "-m", f"veg_area_ros.ros.{module}", "--ros-args"]
    for key, value in parameters.items():
        command += ["-p", f"{key}:={value}"]
    return command


def run_case(pipeline: str, transport: str, spec: dict, domain: int) -> tuple[dict | None, dict]:
    env = transport_environment(transport, domain)
    children = Children()
    memory: dict[str, dict] = {}
    cpu: dict[str, list[tuple[float, float]]] = {"camera": [], "area": [], "area main": []}
    try:
        probe_process = children.start(role_command(SCRIPT, "probe", spec), env)
        if pipeline == "veg_area_ros":
            camera = children.start(node_command("camera_node", source=spec["still"], loop="true", rate_hz=spec["rate"],
                                                 camera_info_url=f"file://{spec['calibration']}"), env)
            area = children.start(role_command(SCRIPT, "profiled_area", spec) if spec.get("profile")
                                  else node_command("area_node"), env)
        else:
            camera = children.start(role_command(SCRIPT, "plain_camera", spec), env)
            area = children.start(role_command(SCRIPT, "plain_area", spec), env)
        deadline = time.monotonic() + FIRST_RESULT_TIMEOUT_S + spec["seconds"] + 30
        while probe_process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.25)
            for name, process in (("camera", camera), ("area", area)):  # the last sample before the probe ends
                if process.poll() is None:
                    memory[name] = memory_mb(process.pid)
                    for key, main_only in ((name, False), (f"{name} main", True)):
                        used = cpu_seconds(process.pid, main_only) if key in cpu else None
                        if used is not None:
                            cpu[key].append((time.time(), used))
            memory["/dev/shm"] = {"rss": shm_mb(), "pss": shm_mb()}
        result = children.result(probe_process, 5.0)
        if result and "window" in result:
            result["cpu_s"] = {name: cpu_over(samples, *result["window"]) for name, samples in cpu.items()}
        return result, memory
    finally:
        children.reap()


def summarize_noise(rates: dict, cpu_per_af: dict) -> None:
    """Per size and transport: the noisy cases' Af/s and the area node's CPU per Af against the noise-free ones
    of the same round (ours only); the median of the rounds' ratios and their range."""
    import statistics

    for (pipeline, transport, size, sigma), noisy in rates.items():
        clean = rates.get((pipeline, transport, size, 0.0), {})
        if pipeline != "veg_area_ros" or sigma == 0:
            continue
        ratios = [noisy[k] / clean[k] for k in noisy if k in clean]
        if not ratios:
            continue
        line = (f"noise {sigma:g} DN, {size} {transport}: Af/s {statistics.median(ratios):.2f}x the noise-free figure "
                f"of the same round (median of {len(ratios)} rounds, {min(ratios):.2f}-{max(ratios):.2f})")
        noisy_cpu = cpu_per_af.get((pipeline, transport, size, sigma), {})
        clean_cpu = cpu_per_af.get((pipeline, transport, size, 0.0), {})
        cpu_ratios = [noisy_cpu[k] / clean_cpu[k] for k in noisy_cpu if k in clean_cpu]
        if cpu_ratios:
            line += f"; the area node's CPU per Af {statistics.median(cpu_ratios):.2f}x"
        print(line, flush=True)


def inside(args) -> int:
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        noise = [float(v) for v in args.noise.split(",")]
        print("rendering the still frames ...", flush=True)
        inputs = prepare_inputs(Path(folder), noise)
        print(f"{'pipeline':12} {'transport':9} {'size':9} {'noise':>5} {'cam Hz':>6} {'Af/s':>6} {'in/s':>6} "
              f"{'drop':>5} {'mean ms':>8} {'p99 ms':>8} {'rebuilt':>9} {'CPU cam':>7} {'area':>5} {'ms/Af':>6} "
              f"{'main':>5}  memory MB (RSS / PSS)", flush=True)
        domain = 100
        rates: dict[tuple[str, str, str, float], dict[int, float]] = {}  # case -> round -> Af/s
        cpu_per_af: dict[tuple[str, str, str, float], dict[int, float]] = {}
        for round_number in range(args.repeats):
            for transport in args.transports.split(","):
                for width, height, rate in LOADS:
                    size = f"{width}x{height}"
                    if size not in args.sizes.split(","):
                        continue
                    cases = [(s, p) for s in noise for p in PIPELINES if s == 0 or p == "veg_area_ros"]
                    # every other round backwards: this machine's speed drifts by up to 2x within minutes, and a
                    # drift must not always favour the cases that come first
                    for sigma, pipeline in cases[::-1] if round_number % 2 else cases:
                        domain += 1
                        key = size + (f" noise {sigma:g}" if sigma else "")
                        spec = dict(inputs[key], rate=rate, seconds=args.seconds)
                        if args.profile and pipeline == "veg_area_ros":
                            spec["profile"] = str(Path(args.profile).resolve() /
                                                  f"area_{transport}_{key.replace(' ', '_')}.prof")
                        result, memory = run_case(pipeline, transport, spec, domain)
                        row = f"{pipeline:12} {transport:9} {size:9} {sigma:5g} {rate:6g}"
                        if not result or not result["results"]:
                            print(f"{row}  no Af arrived within {FIRST_RESULT_TIMEOUT_S:g} s", flush=True)
                            continue
                        case = (pipeline, transport, size, sigma)
                        rates.setdefault(case, {})[round_number] = result["per_s"]
                        latency = result["latency_ms"]
                        dropped = result.get("dropped_share")
                        held = "  ".join(f"{name} {m['rss']:.0f}/{m['pss']:.0f}" if name != "/dev/shm"
                                         else f"{name} {m['rss']:.0f}" for name, m in memory.items())
                        rebuilt = f"{result['rebuilds']}/{result['frames']}" if "rebuilds" in result else "-"
                        window = result["window"][1] - result["window"][0]
                        cpu = result.get("cpu_s", {})
                        shares = [f"{cpu[name] / window:.0%}" if cpu.get(name) is not None else "-"
                                  for name in ("camera", "area")]
                        per_af = None if cpu.get("area") is None else 1000 * cpu["area"] / result["results"]
                        main_per_af = (None if cpu.get("area main") is None
                                       else 1000 * cpu["area main"] / result["results"])
                        if per_af is not None:
                            cpu_per_af.setdefault(case, {})[round_number] = per_af
                        print(f"{row} {result['per_s']:6.1f} {figure(result.get('frames_in_per_s')):>6} "
                              f"{'-' if dropped is None else f'{dropped:.0%}':>5} {figure(latency['mean']):>8} "
                              f"{figure(latency['p99']):>8} {rebuilt:>9} {shares[0]:>7} {shares[1]:>5} "
                              f"{figure(per_af, 2):>6} {figure(main_per_af, 2):>5}  {held}", flush=True)
        summarize_noise(rates, cpu_per_af)
    print("Af/s: results reaching a third process; in/s: frames the area node took (ours reports it); drop: share\n"
          "of the camera's frames skipped while measuring (ours counts them); latency: camera stamp -> Af arrival;\n"
          "CPU: share of one core each node used over the window (two cores here); ms/Af: the area node's CPU time\n"
          "per Af result, all its threads (main: its executor's thread alone, where the callbacks measure).")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="measuring window per case")
    parser.add_argument("--transports", default="shm,default")
    parser.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h, _ in LOADS), help="e.g. 640x480")
    parser.add_argument("--noise", default="0,2,4", help="sensor noise of the camera's frames, DN (0: one still)")
    parser.add_argument("--repeats", type=int, default=1, help="rounds of every case (medians summarized)")
    parser.add_argument("--profile", metavar="FOLDER", help="run the area node under cProfile, one .prof per case "
                        "written here (read with python -m pstats); its rates are then not comparable")
    return bench_main(SCRIPT, ("probe", "plain_camera", "plain_area", "profiled_area"), role_main, parser, inside)


if __name__ == "__main__":
    sys.exit(main())
