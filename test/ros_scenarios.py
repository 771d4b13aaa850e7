"""ROS scenarios run by test/ros_harness.py (inside a private network namespace where possible): real node
processes plus a probe node in this process. Prints `RESULT {json}` for the test to judge; always reaps."""

from __future__ import annotations

import ipaddress
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "veg_area_ros"))

# what the harness gave this process (a user's shell, confined): the nodes and commands it starts get exactly
# this; the probes in this process take the nodes' transport (main() applies it to os.environ)
GIVEN_ENVIRONMENT = dict(os.environ)


class Nodes:
    """Node processes started with `python -m veg_area_ros.ros.<module> --ros-args ...`; always reaped."""

    def __init__(self):
        self.processes: list[tuple[str, subprocess.Popen]] = []

    def start(self, module: str, remap: dict | None = None, name: str | None = None, **parameters) -> subprocess.Popen:
        args = [sys.executable, "-m", f"veg_area_ros.ros.{module}", "--ros-args"]
        for source, target in (remap or {}).items():
            args += ["-r", f"{source}:={target}"]
        if name:
            args += ["-r", f"__node:={name}"]
        for key, value in parameters.items():
            args += ["-p", f"{key}:={json.dumps(value) if isinstance(value, list | bool) else value}"]
        process = subprocess.Popen(args, env=GIVEN_ENVIRONMENT, stdout=sys.stderr, stderr=sys.stderr)
        self.processes.append((module, process))
        return process

    def alive(self) -> dict[str, bool]:
        return {module: process.poll() is None for module, process in self.processes}

    def reap(self) -> None:
        for _, process in self.processes:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 10
        for _, process in self.processes:
            try:
                process.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def spin_for(node, seconds: float, until=lambda: True, longest: float = 60.0) -> None:
    """Spin a probe node for `seconds`, handling its callbacks as they come; then on while `until()` is false,
    at most `longest` seconds more (a busy machine starts the nodes late: a count asserted must have come)."""
    import rclpy

    start = time.monotonic()
    while time.monotonic() < start + seconds or (not until() and time.monotonic() < start + seconds + longest):
        rclpy.spin_once(node, timeout_sec=0.05)


def _address(hex_address: str) -> str:
    host, port = hex_address.split(":")
    if len(host) == 8:
        return f"{socket.inet_ntop(socket.AF_INET, struct.pack('<I', int(host, 16)))}:{int(port, 16)}"
    raw = bytes.fromhex(host)
    words = b"".join(raw[i:i + 4][::-1] for i in range(0, 16, 4))
    return f"[{socket.inet_ntop(socket.AF_INET6, words)}]:{int(port, 16)}"


def sockets_of(pids: list[int]) -> list[dict]:
    """Internet sockets held by these processes: protocol, local and remote address, and whether it stays on
    this machine, judged now (a multicast group's memberships go with the process that joined it)."""
    inodes = set()
    for pid in pids:
        try:
            for fd in os.listdir(f"/proc/{pid}/fd"):
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
                if target.startswith("socket:["):
                    inodes.add(target[8:-1])
        except OSError:
            continue
    joined = multicast_interfaces()
    found = []
    for proto in ("tcp", "tcp6", "udp", "udp6"):
        try:
            lines = Path(f"/proc/net/{proto}").read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if fields[9] in inodes:
                local, remote = _address(fields[1]), _address(fields[2])
                found.append({"proto": proto, "local": local, "remote": remote,
                              "machine_only": _machine_only(local, joined) and _machine_only(remote, joined)})
    return found


def multicast_interfaces() -> dict[str, set[str]]:
    """IPv4 multicast group -> the interfaces that joined it in this network namespace (/proc/net/igmp)."""
    joined: dict[str, set[str]] = {}
    device = ""
    for line in Path("/proc/net/igmp").read_text().splitlines()[1:]:
        if not line.startswith("\t"):
            device = line.split()[1]
        else:
            group = socket.inet_ntop(socket.AF_INET, struct.pack("<I", int(line.split()[0], 16)))
            joined.setdefault(group, set()).add(device)
    return joined


def _machine_only(address: str, joined: dict[str, set[str]]) -> bool:
    """Loopback or unspecified; a multicast group (Fast DDS discovery) when it is joined on loopback alone."""
    host = address.rsplit(":", 1)[0].strip("[]")
    if ipaddress.ip_address(host).is_multicast:
        return joined.get(host) == {"lo"}
    return host in ("0.0.0.0", "::", "::1") or host.startswith("127.") or host.startswith("::ffff:127.")


def off_machine(sockets: list[dict]) -> list[dict]:
    """The sockets that can reach beyond this machine."""
    return [s for s in sockets if not s["machine_only"]]


def _sockets_in(result) -> list[dict]:
    """Every socket list a scenario reported, wherever it sits in its result."""
    if isinstance(result, dict):
        return [*result.get("sockets", []), *(s for key, value in result.items() if key != "sockets"
                                               for s in _sockets_in(value))]
    return []


def udp_datagrams_sent() -> int:
    """UDP datagrams sent so far in this network namespace (/proc/net/snmp, all processes)."""
    header, values = (line.split() for line in Path("/proc/net/snmp").read_text().splitlines()
                      if line.startswith("Udp:"))
    return int(values[header.index("OutDatagrams")])


def interfaces() -> list[str]:
    return [line.split(":")[0].strip() for line in Path("/proc/net/dev").read_text().splitlines()[2:]]


def scenario_delivery(options: dict, nodes: Nodes) -> dict:
    """camera_node publishing a still image of each size in a loop; a probe counts what arrives."""
    import cv2
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image

    from veg_area_ros.ros.qos import IMAGE_QOS

    results = {}
    rclpy.init()
    probe = Node("probe")
    try:
        for width, height, rate, seconds in options["cases"]:
            still = Path(f"still_{width}x{height}.png")
            cv2.imwrite(str(still), np.random.default_rng(0).integers(0, 255, (height, width, 3), np.uint8))
            stamps: list[float] = []
            latencies: list[float] = []

            def on_image(msg, stamps=stamps, latencies=latencies):
                sent = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
                stamps.append(sent)
                latencies.append(time.time() - sent)

            subscription = probe.create_subscription(Image, f"image_{width}", on_image, IMAGE_QOS)
            process = nodes.start("camera_node", remap={"image_raw": f"image_{width}"}, name=f"camera_{width}",
                                  source=str(still.resolve()), loop=True, rate_hz=float(rate))
            deadline = time.monotonic() + 60
            while not stamps and time.monotonic() < deadline:
                rclpy.spin_once(probe, timeout_sec=0.1)
            stamps.clear()
            latencies.clear()
            datagrams_before = udp_datagrams_sent()
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                rclpy.spin_once(probe, timeout_sec=0.05)
            datagrams = udp_datagrams_sent() - datagrams_before
            gaps = np.diff(stamps) * rate if len(stamps) > 1 else np.array([])
            missing = int(np.sum(np.maximum(np.round(gaps) - 1, 0)))
            results[f"{width}x{height}"] = {
                "received": len(stamps), "missing": missing, "rate_hz": rate, "seconds": seconds,
                "mean_latency_ms": 1000 * float(np.mean(latencies)) if latencies else None,
                "udp_datagrams_sent": datagrams,
                "sockets": sockets_of([os.getpid(), process.pid])}
            probe.destroy_subscription(subscription)
            process.send_signal(signal.SIGINT)
            process.wait(10)
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return results


def scenario_calibration_trap(options: dict, nodes: Nodes) -> dict:
    """The calibration node judges a new fit against the served one on evidence, not RMS: A serves a 5-view fit
    from its file and is fed 16 varied views (~/calibrate); B serves the many-view fit A wrote and is fed 5 of
    first 8 views (~/calibrate, then ~/commit)."""
    import shutil

    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image
    from std_srvs.srv import Trigger
    from test_guidance import BOARD_SPEC, PORT, poses

    from veg_area_ros.calib_io import fit_metadata, read_calibration, write_calibration
    from veg_area_ros.calibration import View, calibrate
    from veg_area_ros.ros.messages import image_to_msg
    from veg_area_ros.ros.qos import IMAGE_QOS
    from veg_area_ros.sim.synthetic import ENDOSCOPE, render_board_views

    images = render_board_views(ENDOSCOPE, BOARD_SPEC, poses(16), port=PORT, rng=np.random.default_rng(1),
                                noise_sigma=2.0, supersample=2)
    few = calibrate([View(f"v{i}", BOARD_SPEC.detect(image)) for i, image in enumerate(images[:5])],
                    ENDOSCOPE.image_size)
    file_a, file_b = Path("a.yaml").resolve(), Path("b.yaml").resolve()
    write_calibration(file_a, few.camera, metadata=fit_metadata(few.summary(), "water", 0.7, str(BOARD_SPEC), "test"))
    out: dict = {"a_before": read_calibration(file_a).metadata["views_used"]}
    rclpy.init()
    probe = Node("probe")
    publisher = probe.create_publisher(Image, "image_raw", IMAGE_QOS)

    def spin(seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            rclpy.spin_once(probe, timeout_sec=0.02)

    def feed(frames: list[np.ndarray], nodes_listening: int) -> None:
        # the node just started among those already listening (counting them all: the first image went to the
        # earlier nodes only when CI was loaded and cal_b kept 3 of 8 views), and a second more for its side of
        # the match
        deadline = time.monotonic() + 30
        while publisher.get_subscription_count() < nodes_listening and time.monotonic() < deadline:
            spin(0.1)
        spin(1.0)
        for image in frames:
            for _ in range(3):
                publisher.publish(image_to_msg(image, probe.get_clock().now().to_msg(), "camera"))
                spin(0.25)
        spin(2.0)

    def trigger(service: str) -> list:
        client = probe.create_client(Trigger, service)
        if not client.wait_for_service(timeout_sec=20):
            return [None, "no service"]
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(probe, future, timeout_sec=60)
        response = future.result()
        return [None, "no answer"] if response is None else [response.success, response.message]

    try:
        nodes.start("calibration_node", name="cal_a", camera_info_url=f"file://{file_a}", min_views=12,
                     auto_calibrate=False)
        feed(images, 1)
        out["a_calibrate"] = trigger("cal_a/calibrate")
        out["a_after"] = read_calibration(file_a).metadata["views_used"]
        shutil.copy(file_a, file_b)
        before = file_b.read_bytes()
        nodes.start("calibration_node", name="cal_b", camera_info_url=f"file://{file_b}", min_views=4,
                    auto_calibrate=False)
        feed(images[:8], 2)
        out["b_calibrate"] = trigger("cal_b/calibrate")
        out["b_unchanged"] = file_b.read_bytes() == before
        out["b_commit"] = trigger("cal_b/commit")
        out["b_after"] = read_calibration(file_b).metadata["views_used"]
        out["b_commit_again"] = trigger("cal_b/commit")
        file_c = Path("c.yaml").resolve()  # no calibration yet, and fewer views than min_views: served only
        nodes.start("calibration_node", name="cal_c", camera_info_url=f"file://{file_c}", min_views=12,
                    auto_calibrate=False)
        feed(images[:8], 3)
        out["c_calibrate"] = trigger("cal_c/calibrate")
        out["c_written_before_commit"] = file_c.exists()
        out["c_commit"] = trigger("cal_c/commit")
        out["c_written_after_commit"] = file_c.exists()
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return out


def main() -> int:
    from console_scenario import scenario_console

    from veg_area_ros.ros.run import ensure_ros_environment

    name, options = sys.argv[1], json.loads(sys.argv[2])
    if name != "foreign":  # the probes here talk to our nodes as one of them would; a foreign node does not
        ensure_ros_environment()
    nodes = Nodes()
    try:
        result = {"delivery": scenario_delivery, "graph": scenario_graph, "record": scenario_record,
                  "drag": scenario_drag, "interop": scenario_interop, "foreign": scenario_foreign,
                  "full_rate": scenario_full_rate, "driver_qos": scenario_driver_qos,
                  "replay": scenario_replay, "record_cli": scenario_record_cli,
                  "two_machines": scenario_two_machines, "bad_start_files": scenario_bad_start_files,
                  "guidance": scenario_guidance, "replay_into_recorder": scenario_replay_into_recorder,
                  "compressed_driver": scenario_compressed_driver,
                  "mono16_driver": scenario_mono16_driver,
                  "calibration_trap": scenario_calibration_trap, "console": scenario_console,
                  "metadata": scenario_metadata}[name](
                      options, nodes)
        result["interfaces"] = interfaces()
        result["off_machine"] = off_machine(_sockets_in(result))
        result["alive_at_end"] = nodes.alive()
    finally:
        nodes.reap()
    result["exit_codes"] = {module: process.returncode for module, process in nodes.processes}
    print("RESULT " + json.dumps(result), flush=True)
    return 0


def scenario_graph(options: dict, nodes: Nodes) -> dict:
    """camera (synthetic, board views then the cube) -> calibration_node -> area_node, each its own process;
    then run-time changes (set_camera_info, parameters) and bad frames injected on image_raw."""
    import rclpy
    from rcl_interfaces.srv import SetParameters
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import CameraInfo, Image
    from sensor_msgs.srv import SetCameraInfo
    from std_msgs.msg import String

    from veg_area_ros.calib_io import read_calibration
    from veg_area_ros.ros.messages import camera_to_info, info_to_camera
    from veg_area_ros.ros.qos import IMAGE_QOS, LATCHED_QOS, RESULT_QOS
    from veg_area_ros.sim.synthetic import cube_scene

    out: dict = {"truth_m2": cube_scene().true_area_m2}
    calibration_file = Path("served.yaml").resolve()
    rate = float(options.get("rate_hz", 10.0))
    nodes.start("camera_node", rate_hz=rate)
    nodes.start("calibration_node", camera_info_url=f"file://{calibration_file}", min_views=12)
    nodes.start("area_node")
    rclpy.init()
    probe = Node("probe")
    image_stamps: list[float] = []
    infos: list[dict] = []
    camera_infos: list[CameraInfo] = []
    probe.create_subscription(Image, "image_raw", lambda m: image_stamps.append(time.monotonic()), IMAGE_QOS)
    probe.create_subscription(String, "projected_area/info", lambda m: infos.append(json.loads(m.data)), RESULT_QOS)
    probe.create_subscription(CameraInfo, "camera_info", camera_infos.append, LATCHED_QOS)
    from rcl_interfaces.msg import Log
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    area_log: list[str] = []
    probe.create_subscription(Log, "/rosout", lambda m: m.name == "area_node" and area_log.append(m.msg),
                              QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    inject = probe.create_publisher(Image, "image_raw", IMAGE_QOS)
    masks: list[dict] = []

    def on_mask(m: Image) -> None:
        masks.append({"encoding": m.encoding, "size": [m.width, m.height], "object_px": sum(1 for b in m.data if b),
                      "values": sorted(set(m.data)), "stamp": [m.header.stamp.sec, m.header.stamp.nanosec]})

    probe.create_subscription(Image, "mask", on_mask, IMAGE_QOS)

    def spin_until(condition, seconds: float) -> bool:
        deadline = time.monotonic() + seconds
        while not condition() and time.monotonic() < deadline:
            rclpy.spin_once(probe, timeout_sec=0.05)
        return condition()

    def calibrated(after: int = 0) -> list[dict]:
        return [i for i in infos[after:] if i["calibrated"]]

    def call(client, request, seconds: float = 20.0):
        if not client.wait_for_service(timeout_sec=seconds):
            return None
        future = client.call_async(request)
        rclpy.spin_until_future_complete(probe, future, timeout_sec=seconds)
        return future.result()

    try:
        spin_until(lambda: len(calibrated()) >= 5, 180)
        out["rate_window"] = image_stamps[-20:]
        areas = [i["area_m2"] for i in calibrated()]
        out["calibrated_areas"] = areas
        out["calibrated_scales"] = [i["scale_m_per_px"] for i in calibrated()]
        spin_until(lambda: len(masks) >= 3, 20)
        out["masks"] = masks[-3:]
        out["info_stamps"] = [[i["stamp"]["sec"], i["stamp"]["nanosec"]] for i in infos]
        out["frame_counts"] = {k: infos[-1][k] for k in ("frames_received", "frames_dropped", "frames_measured")}
        out["camera_info_received"] = bool(camera_infos)
        out["persisted"] = calibration_file.exists()
        if calibration_file.exists():
            out["persisted_fx"] = read_calibration(calibration_file).camera.fx
            out["persisted_model"] = read_calibration(calibration_file).metadata.get("model_choice")
            out["persisted_tone"] = {key: read_calibration(calibration_file).metadata.get(key)
                                     for key in ("tone_curve", "tone_curve_evidence", "area_mode",
                                                 "area_mode_evidence")}
        if camera_infos:
            out["served_fx"] = info_to_camera(camera_infos[-1]).fx

        # a late joiner still gets the latched calibration
        late: list[CameraInfo] = []
        late_node = Node("late_probe")
        late_node.create_subscription(CameraInfo, "camera_info", late.append, LATCHED_QOS)
        deadline = time.monotonic() + 10
        while not late and time.monotonic() < deadline:
            rclpy.spin_once(late_node, timeout_sec=0.1)
        out["late_joiner_got_camera_info"] = bool(late)
        late_node.destroy_node()

        # set_camera_info: a camera with 3 % longer focal length -> Af of the same frames changes
        served = info_to_camera(camera_infos[-1])
        import dataclasses

        changed = dataclasses.replace(served, c=served.c * 1.03)
        request = SetCameraInfo.Request()
        request.camera_info = camera_to_info(changed)
        response = call(probe.create_client(SetCameraInfo, "set_camera_info"), request)
        out["set_camera_info"] = None if response is None else [response.success, response.status_message]
        mark = len(infos)
        spin_until(lambda: len(calibrated(mark)) >= 8, 30)
        out["areas_after_set_camera_info"] = [i["area_m2"] for i in calibrated(mark)[3:]]
        out["scales_after_set_camera_info"] = [i["scale_m_per_px"] for i in calibrated(mark)[3:]]
        out["persisted_fx_after_set"] = read_calibration(calibration_file).camera.fx

        # parameters at run time: an out-of-range threshold is refused with a reason, a valid change applies
        parameters = probe.create_client(SetParameters, "area_node/set_parameters")

        def set_parameter(name: str, value):
            return call(parameters, SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()]))

        def refusal(name: str, value) -> list | None:
            """[successful, reason] of a change, None when the service did not answer."""
            done = set_parameter(name, value)
            return None if done is None else [done.results[0].successful, done.results[0].reason]

        out["bad_threshold"] = refusal("threshold", 300.0)
        out["bad_roi"] = refusal("roi", [1.0, 2.0])
        out["far_roi"] = refusal("roi", [2000.0, 2000.0, 2100.0, 2000.0, 2100.0, 2100.0])
        out["bad_threshold_mode"] = refusal("threshold_mode", "median")
        out["place_before_tuning"] = [infos[-1]["homography"], infos[-1]["weights_rebuilt"]]
        good = set_parameter("threshold", 60.0)  # the default mode is otsu, as on the command line: kept, said
        out["good_threshold"] = None if good is None else good.results[0].successful
        fixed = set_parameter("threshold_mode", "fixed")
        out["fixed_threshold_mode"] = None if fixed is None else fixed.results[0].successful
        spin_until(lambda: any("kept for later" in line for line in area_log), 5)
        out["threshold_kept_lines"] = [line for line in area_log if "kept for later" in line]
        mark = len(infos)
        spin_until(lambda: len(calibrated(mark)) >= 6, 30)
        out["thresholds_after_change"] = sorted({i["threshold"] for i in calibrated(mark)[3:]})
        out["places_after_tuning"] = [list(place) for place in
                                      {(json.dumps(i["homography"]), i["weights_rebuilt"]) for i in calibrated(mark)}]
        out["area_modes_before"] = sorted({i["area_mode"] for i in calibrated(mark)[3:]})
        out["bad_area_mode"] = refusal("area_mode", "fractional")
        out["bad_levels"] = refusal("levels", [100.0, 101.0])
        good_mode = set_parameter("area_mode", "count")
        out["good_area_mode"] = None if good_mode is None else good_mode.results[0].successful
        mark = len(infos)
        spin_until(lambda: len(calibrated(mark)) >= 6, 30)
        out["area_modes_after_change"] = sorted({i["area_mode"] for i in calibrated(mark)[3:]})
        out["levels_while_counting"] = refusal("levels", [40.0, 200.0])
        set_parameter("area_mode", "subpixel")
        mark = len(infos)  # tone_curve auto (the default), a calibration from camera_info: read as grey levels
        spin_until(lambda: len(calibrated(mark)) >= 5, 30)
        out["tone_curves_by_default"] = sorted({str((i.get("levels") or {}).get("tone_curve"))
                                                for i in calibrated(mark)[3:]})
        out["bad_tone_curve"] = refusal("tone_curve", "gamma")
        good_tone = set_parameter("tone_curve", "srgb")
        out["good_tone_curve"] = None if good_tone is None else good_tone.results[0].successful
        mark = len(infos)
        spin_until(lambda: len(calibrated(mark)) >= 5, 30)
        out["tone_curves_after_change"] = sorted({str((i.get("levels") or {}).get("tone_curve"))
                                                  for i in calibrated(mark)[3:]})
        set_parameter("tone_curve", "auto")

        # bad frames on image_raw: wrong encoding, wrong size, empty data, lying step
        for encoding, width, height, data in (("16UC1", 640, 480, bytes(640 * 480 * 2)),
                                              ("bgr8", 320, 240, bytes(320 * 240 * 3)),
                                              ("bgr8", 640, 480, b""),
                                              ("mono8", 640, 480, bytes(100))):
            msg = Image(encoding=encoding, width=width, height=height, step=width * (3 if encoding == "bgr8" else 2),
                        data=data)
            msg.header.stamp = probe.get_clock().now().to_msg()
            inject.publish(msg)
            rclpy.spin_once(probe, timeout_sec=0.05)
        mark = len(infos)
        out["measures_after_bad_frames"] = spin_until(lambda: len(calibrated(mark)) >= 3, 30)
        # one more bad frame after the throttle period: its line says how many the throttle hid
        spin_until(lambda: False, 5.5)
        msg = Image(encoding="16UC1", width=640, height=480, step=1280, data=bytes(640 * 480 * 2))
        msg.header.stamp = probe.get_clock().now().to_msg()
        inject.publish(msg)
        spin_until(lambda: sum("frame refused" in line for line in area_log) >= 2, 10)
        out["refused_lines"] = [line for line in area_log if "frame refused" in line]

        # bad calibrations: a camera_info beyond any camera (refused: the served one stays), then the targets file
        # spoiled on disk before a new calibration comes (the file was read when set: the calibration applies)
        from veg_area_ros.sim.synthetic import scene_targets_content

        targets = Path("targets.yaml").resolve()
        content = scene_targets_content()
        content["markers"][7] = [0.0, 0.16]  # listed, never in view: said in every result
        targets.write_text(yaml.safe_dump(content))
        done = set_parameter("targets_file", str(targets))
        out["targets_file_set"] = None if done is None else done.results[0].successful
        set_parameter("threshold", 120.0)
        mark = len(infos)
        spin_until(lambda: len(calibrated(mark)) >= 4, 30)
        out["areas_before_bogus_camera_info"] = [i["area_m2"] for i in calibrated(mark)[2:]]
        targets.write_text("markers: [spoiled")
        bogus = camera_to_info(served)
        bogus.width = bogus.height = 100_000
        probe.create_publisher(CameraInfo, "camera_info", LATCHED_QOS).publish(bogus)
        absurd = camera_to_info(dataclasses.replace(served, k1=1e6))  # a lens no camera has: Af +570 % before
        probe.create_publisher(CameraInfo, "camera_info", LATCHED_QOS).publish(absurd)
        mark = len(infos)
        spin_until(lambda: len(calibrated(mark)) >= 4, 30)
        out["areas_after_bogus_camera_info"] = [i["area_m2"] for i in calibrated(mark)[2:]]
        request = SetCameraInfo.Request()
        request.camera_info = absurd
        response = call(probe.create_client(SetCameraInfo, "set_camera_info"), request)
        out["set_absurd_camera_info"] = None if response is None else [response.success, response.status_message]
        out["ignored_lines"] = [line for line in area_log if "camera_info ignored" in line]
        request = SetCameraInfo.Request()
        request.camera_info = camera_to_info(served)  # the fitted calibration back: Af of the cube again
        response = call(probe.create_client(SetCameraInfo, "set_camera_info"), request)
        out["set_camera_info_back"] = None if response is None else response.success
        mark = len(infos)
        spin_until(lambda: len(calibrated(mark)) >= 6, 30)
        out["areas_after_spoiled_targets_file"] = [i["area_m2"] for i in calibrated(mark)[3:]]
        out["scales_after_spoiled_targets_file"] = [i["scale_m_per_px"] for i in calibrated(mark)[3:]]
        # a write that fails (the file's place taken by a folder, which stops root too): served, answered failure
        calibration_file.rename(calibration_file.with_suffix(".kept"))
        calibration_file.mkdir()
        request = SetCameraInfo.Request()
        request.camera_info = camera_to_info(served)
        response = call(probe.create_client(SetCameraInfo, "set_camera_info"), request)
        out["set_camera_info_unwritable"] = None if response is None else [response.success,
                                                                            response.status_message]
        calibration_file.rmdir()
        calibration_file.with_suffix(".kept").rename(calibration_file)
        out["sockets"] = sockets_of([os.getpid()] + [p.pid for _, p in nodes.processes])
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return out


def air_endoscope_calibration() -> Path:
    """The synthetic endoscope's true calibration in air, as a camera_info YAML in the scenario's folder."""
    from veg_area_ros.calib_io import write_calibration
    from veg_area_ros.sim.synthetic import ENDOSCOPE

    calibration = Path("endoscope.yaml").resolve()
    write_calibration(calibration, ENDOSCOPE, "endoscope", {"medium": "air"})
    return calibration


def scenario_record(options: dict, nodes: Nodes) -> dict:
    """camera (synthetic cube in air, true calibration published) -> area_node, recorded by two record nodes:
    one closed with SIGINT, one killed with SIGKILL mid-run. The bags are judged by the test afterwards."""
    calibration = air_endoscope_calibration()
    topics = ["image_raw", "camera_info", "projected_area", "projected_area/info"]
    # recorders and camera first, the area node once they are recording: the bag then holds every image the
    # live node measures from its first (it carries its pixel weights from frame to frame). The recorder finds
    # the area node's topics by polling, so it may miss its first results (the tests allow for that).
    closed = nodes.start("record_node", name="recorder", output=str(Path("closed_bag").resolve()), topics=topics)
    killed = nodes.start("record_node", name="doomed", output=str(Path("killed_bag").resolve()),
                         topics=["image_raw"])
    nodes.start("camera_node", rate_hz=float(options["rate_hz"]), synthetic_scene="cube", synthetic_medium="air",
                camera_info_url=f"file://{calibration}")
    time.sleep(float(options["settle_s"]))
    nodes.start("area_node")
    # until the area node has measured `results` frames (a loaded machine starts it slower), at least `seconds`
    import rclpy
    from rclpy.node import Node

    from veg_area_msgs.msg import ProjectedArea
    from veg_area_ros.ros.qos import RESULT_QOS

    rclpy.init()
    probe = Node("record_probe")
    results: list[int] = []
    probe.create_subscription(ProjectedArea, "projected_area", lambda _: results.append(1), RESULT_QOS)
    started, deadline = time.monotonic(), time.monotonic() + 180
    while (len(results) < int(options.get("results", 30)) or time.monotonic() - started < float(options["seconds"])) \
            and time.monotonic() < deadline:
        rclpy.spin_once(probe, timeout_sec=0.05)
    probe.destroy_node()
    rclpy.try_shutdown()
    killed.kill()
    killed.wait(10)
    time.sleep(1.0)
    closed.send_signal(signal.SIGINT)
    closed.wait(20)
    return {"closed_exit": closed.returncode, "killed_exit": killed.returncode,
            "sockets": sockets_of([p.pid for _, p in nodes.processes if p.poll() is None])}


def scenario_full_rate(options: dict, nodes: Nodes) -> dict:
    """camera_node looping a still of the cube as fast as it can -> area_node, which falls behind; this probe
    keeps every camera_info stamp (deep reliable queue) to know what was published, and the area node's info."""
    import cv2
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo
    from std_msgs.msg import String

    from veg_area_ros.sim.synthetic import DISTANCE_M, ENDOSCOPE, cube_scene, render_scene

    calibration, still = air_endoscope_calibration(), Path("cube.png").resolve()
    cv2.imwrite(str(still), render_scene(ENDOSCOPE, cube_scene(), DISTANCE_M))
    rclpy.init()
    probe = Node("probe")
    published: list[int] = []
    infos: list[dict] = []
    deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100_000, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
    probe.create_subscription(CameraInfo, "camera_info",
                              lambda m: published.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec), deep)
    probe.create_subscription(String, "projected_area/info", lambda m: infos.append(json.loads(m.data)),
                              QoSProfile(depth=100_000, reliability=ReliabilityPolicy.RELIABLE))
    nodes.start("area_node")
    deadline = time.monotonic() + 30  # the camera starts once the area node takes images (its subscription seen)
    while probe.count_subscribers("image_raw") < 1 and time.monotonic() < deadline:
        rclpy.spin_once(probe, timeout_sec=0.05)
    camera = nodes.start("camera_node", source=str(still), loop=True, rate_hz=1000.0,
                         camera_info_url=f"file://{calibration}")
    camera_started = time.monotonic()
    try:
        end = time.monotonic() + float(options["seconds"]) + 10
        while time.monotonic() < end:
            rclpy.spin_once(probe, timeout_sec=0.01)
        camera.send_signal(signal.SIGINT)  # then take what is still queued here, so no camera_info is left out
        camera_seconds = time.monotonic() - camera_started
        camera.wait(10)
        idle_since, deadline = time.monotonic(), time.monotonic() + 30
        while time.monotonic() - idle_since < 1.0 and time.monotonic() < deadline:
            before = len(published) + len(infos)
            rclpy.spin_once(probe, timeout_sec=0.05)
            if len(published) + len(infos) > before:
                idle_since = time.monotonic()
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    counted = [i for i in infos if i.get("frames_dropped") is not None]
    window = counted[len(counted) // 4:]  # from when the area node has long been behind
    first, last = (window[0], window[-1]) if len(window) > 1 else ({}, {})

    def ns(info: dict) -> int:
        return info["stamp"]["sec"] * 10**9 + info["stamp"]["nanosec"]
    return {"published_in_window": sum(1 for s in published if ns(first) < s <= ns(last)) if first else 0,
            "received_in_window": last["frames_received"] - first["frames_received"] if first else 0,
            "dropped_in_window": last["frames_dropped"] - first["frames_dropped"] if first else 0,
            "lost_in_window": last["frames_lost"] - first["frames_lost"] if first else 0,
            "truth_m2": cube_scene().true_area_m2, "areas": [i["area_m2"] for i in window[-20:]],
            "camera_seconds": camera_seconds}


def scenario_foreign(options: dict, nodes: Nodes) -> dict:
    """A node as a lab's force-balance driver or rviz runs it: Fast DDS's defaults, none of our settings. It
    counts the images and Af it receives (ProjectedArea, and the deprecated Vector3Stamped as an instrument node
    written for it reads it) and publishes force readings at 20 Hz."""
    import rclpy
    from geometry_msgs.msg import Vector3Stamped, WrenchStamped
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image
    from std_msgs.msg import String

    from veg_area_msgs.msg import ProjectedArea

    rclpy.init()
    node = Node("force_balance")
    images: list[list[int]] = []
    areas: list[float] = []
    area_stamps: list[str] = []
    last_info: list[str] = []
    fields: list[dict] = []  # the last ProjectedArea, every field by name
    vector_areas: dict[str, list[float]] = {}  # stamp -> [x, y, z] of projected_area/vector

    def on_area(msg: ProjectedArea) -> None:
        areas.append(msg.area_m2)
        area_stamps.append(f"{msg.header.stamp.sec}.{msg.header.stamp.nanosec:09d}")
        fields[:] = [{name: getattr(msg, name) for name in msg.get_fields_and_field_types() if name != "header"}]
        fields[0]["warnings"] = list(msg.warnings)

    def on_vector(msg: Vector3Stamped) -> None:
        vector_areas[f"{msg.header.stamp.sec}.{msg.header.stamp.nanosec:09d}"] = [msg.vector.x, msg.vector.y,
                                                                                  msg.vector.z]

    if options.get("images", True):
        node.create_subscription(Image, "image_raw", lambda m: images.append([m.width, m.height]),
                                 qos_profile_sensor_data)
    node.create_subscription(ProjectedArea, "projected_area", on_area, 10)
    node.create_subscription(Vector3Stamped, "projected_area/vector", on_vector, 10)
    node.create_subscription(String, "projected_area/info", lambda m: last_info.append(m.data), 10)
    force = node.create_publisher(WrenchStamped, "force", 10)
    sent = []

    def publish_force():
        msg = WrenchStamped()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.wrench.force.x = 0.5
        force.publish(msg)
        sent.append(1)

    node.create_timer(0.05, publish_force)
    least_images, least_areas = int(options.get("least_images", 0)), int(options.get("least_areas", 0))
    spin_for(node, float(options["seconds"]), until=lambda: len(images) >= least_images and len(areas) >= least_areas)
    node.destroy_node()
    rclpy.try_shutdown()
    return {"images": len(images), "image_sizes": sorted({tuple(size) for size in images}), "areas": areas,
            "area_stamps": area_stamps, "last_info": json.loads(last_info[-1]) if last_info else None,
            "last_fields": fields[0] if fields else None, "vector_areas": vector_areas,
            "forces_sent": len(sent), "profile": os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE")}


def scenario_interop(options: dict, nodes: Nodes) -> dict:
    """Our nodes (the shipped profile) and a node on Fast DDS's defaults on one machine: camera_node ->
    area_node -> the foreign node (Af and 640x480 images), and the foreign node's force -> this probe (our
    profile). Only inside a private network namespace: the foreign node uses every interface it finds."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.node import Node

    from veg_area_ros.sim.synthetic import cube_scene

    calibration = air_endoscope_calibration()
    ours = [nodes.start("camera_node", rate_hz=10.0, synthetic_scene="cube", synthetic_medium="air",
                        camera_info_url=f"file://{calibration}"), nodes.start("area_node")]
    defaults = {k: v for k, v in GIVEN_ENVIRONMENT.items() if not k.startswith(("FASTDDS_", "VEG_AREA_"))}
    wanted = {"seconds": options["seconds"], "least_images": options.get("least_images", 0),
              "least_areas": options.get("least_areas", 0)}
    foreign = subprocess.Popen([sys.executable, __file__, "foreign", json.dumps(wanted)],
                               env=defaults, stdout=subprocess.PIPE, stderr=sys.stderr, text=True)
    nodes.processes.append(("foreign", foreign))
    rclpy.init()
    probe = Node("probe")
    forces: list[float] = []
    probe.create_subscription(WrenchStamped, "force", lambda m: forces.append(m.wrench.force.x), 10)
    sockets: list[dict] = []
    try:
        deadline = time.monotonic() + float(options["seconds"]) + 120
        while foreign.poll() is None and time.monotonic() < deadline:
            rclpy.spin_once(probe, timeout_sec=0.05)
            if forces and not sockets:  # everyone is up: our processes' sockets, while they are open
                sockets = sockets_of([os.getpid()] + [p.pid for p in ours])
        lines = [line for line in foreign.communicate(timeout=30)[0].splitlines() if line.startswith("RESULT ")]
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return {"foreign": json.loads(lines[-1][len("RESULT "):]) if lines else None, "forces_received": len(forces),
            "truth_m2": cube_scene().true_area_m2, "sockets": sockets}


def scenario_drag(options: dict, nodes: Nodes) -> dict:
    """drag_node fed synthetic Af (10 Hz), force (200 Hz, noisy) and velocity (50 Hz) with a known Cd; its
    DragCoefficient messages, the deprecated Vector3Stamped beside them, and a run-time change of a start-only
    parameter."""
    import rclpy
    from geometry_msgs.msg import TwistStamped, Vector3Stamped, WrenchStamped
    from rcl_interfaces.srv import SetParameters
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from veg_area_msgs.msg import DragCoefficient, ProjectedArea
    from veg_area_ros.ros.qos import RESULT_QOS

    cd, density, area, velocity = options["cd"], 998.2, options["area_m2"], options["velocity_m_s"]
    force = 0.5 * density * velocity**2 * area * cd
    nodes.start("drag_node", tolerance_s=0.05, force_axis="-y", force_std_n=0.005 * force)
    rclpy.init()
    probe = Node("drag_probe")
    received: list[list[float]] = []
    received_stamps: list[list[int]] = []
    area_stamps: list[list[int]] = []
    named: list[dict] = []
    vectors: dict[tuple[int, int], list[float]] = {}

    def on_drag(msg: DragCoefficient) -> None:
        received.append([msg.drag_coefficient, msg.drag_coefficient_std, msg.velocity_m_s])
        received_stamps.append([msg.header.stamp.sec, msg.header.stamp.nanosec])
        named.append({name: getattr(msg, name) for name in msg.get_fields_and_field_types() if name != "header"}
                     | {"area_warnings": list(msg.area_warnings)})

    def on_vector(msg: Vector3Stamped) -> None:
        vectors[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = [msg.vector.x, msg.vector.y, msg.vector.z]

    results = probe.create_subscription(DragCoefficient, "drag_coefficient", on_drag, RESULT_QOS)
    vector_results = probe.create_subscription(Vector3Stamped, "drag_coefficient/vector", on_vector, RESULT_QOS)
    publishers = {name: probe.create_publisher(kind, name, RESULT_QOS)
                  for name, kind in (("force", WrenchStamped), ("velocity", TwistStamped),
                                     ("projected_area", ProjectedArea))}
    rng = np.random.default_rng(5)
    try:
        # every way matched, the drag node's output to us too: a Cd published before that would be lost (seen
        # on a loaded machine: 29 of 40 arrived)
        deadline = time.monotonic() + 30
        while ((any(p.get_subscription_count() == 0 for p in publishers.values()) or results.get_publisher_count() == 0
                or vector_results.get_publisher_count() == 0) and time.monotonic() < deadline):
            rclpy.spin_once(probe, timeout_sec=0.1)
        # a second more: a publisher sees the match before the subscriber's side has completed it (CI, loaded:
        # the first 10 Af, one second of them, had no Cd)
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            rclpy.spin_once(probe, timeout_sec=0.05)
        start = probe.get_clock().now().nanoseconds
        for tick in range(int(options["seconds"] * 200)):  # a 200 Hz clock of simulated instruments
            stamp_ns = start + tick * 5_000_000
            sec, nanosec = divmod(stamp_ns, 1_000_000_000)
            msg = WrenchStamped()  # a force sample at every tick
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
            msg.wrench.force.y = -force * (1 + 0.005 * rng.standard_normal())  # the balance points upstream
            publishers["force"].publish(msg)
            if tick % 4 == 0:
                msg = TwistStamped()
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
                msg.twist.linear.x = velocity
                publishers["velocity"].publish(msg)
            if tick % 20 == 10:
                msg = ProjectedArea()
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
                msg.area_m2, msg.area_std_m2 = area, 0.002 * area
                msg.warnings = ["clipped highlights: a test's warning"] if tick % 40 == 10 else []
                publishers["projected_area"].publish(msg)
                area_stamps.append([sec, nanosec])
            rclpy.spin_once(probe, timeout_sec=0.0)
            time.sleep(0.001)
        deadline = time.monotonic() + 10
        while len(received) < options["seconds"] * 10 - 2 and time.monotonic() < deadline:
            rclpy.spin_once(probe, timeout_sec=0.1)
        client = probe.create_client(SetParameters, "drag_node/set_parameters")
        client.wait_for_service(timeout_sec=30)
        future = client.call_async(SetParameters.Request(parameters=[Parameter("density", value=1000.0)
                                                                     .to_parameter_msg()]))
        rclpy.spin_until_future_complete(probe, future, timeout_sec=30)
        refused = None if future.result() is None else [future.result().results[0].successful,
                                                        future.result().results[0].reason]
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return {"received": received, "true_cd": cd, "received_stamps": received_stamps, "area_stamps": area_stamps,
            "named": named, "vectors": {f"{sec}.{nanosec:09d}": v for (sec, nanosec), v in vectors.items()},
            "density_change": refused}


def _two_pcs(shm_root: Path) -> dict[str, list[str]]:
    """Two network namespaces joined by a veth pair (10.77.0.1 and .2, multicast routed over it), each with its
    own /dev/shm: two PCs on one lab network. Returns the command prefix that runs a process on each."""
    def ip(*args: str) -> None:
        subprocess.run(["ip", *args], check=True, capture_output=True)

    # the namespaces' names (/run/netns) live in a tmpfs of this private mount namespace: none on the host
    subprocess.run(["mount", "-t", "tmpfs", "tmpfs", "/run"], check=True)
    prefixes = {}
    ip("link", "add", "veg_a", "type", "veth", "peer", "name", "veg_b")
    for pc, address in (("a", "10.77.0.1/24"), ("b", "10.77.0.2/24")):
        namespace = f"veg_pc_{pc}"
        ip("netns", "add", namespace)
        ip("link", "set", f"veg_{pc}", "netns", namespace)
        ip("-n", namespace, "link", "set", "lo", "up")
        ip("-n", namespace, "addr", "add", address, "dev", f"veg_{pc}")
        ip("-n", namespace, "link", "set", f"veg_{pc}", "up")
        ip("-n", namespace, "route", "add", "224.0.0.0/4", "dev", f"veg_{pc}")
        shm = shm_root / f"shm_{pc}"
        shm.mkdir(parents=True, exist_ok=True)
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1g", "tmpfs", str(shm)], check=True)
        prefixes[pc] = ["ip", "netns", "exec", namespace, "sh", "-c",
                        f'mount --bind {shm} /dev/shm && exec "$@"', "sh"]
    return prefixes


def scenario_two_machines(options: dict, nodes: Nodes) -> dict:
    """Camera PC: camera_node (640x480 bgr8, options["rate_hz"]) and an instrument node on Fast DDS's defaults;
    measuring PC: area_node and another such node. Our nodes on the shipped default transport."""
    from veg_area_ros.sim.synthetic import cube_scene

    pcs = _two_pcs(Path("pcs").resolve())
    calibration = air_endoscope_calibration()
    defaults = {k: v for k, v in GIVEN_ENVIRONMENT.items() if not k.startswith(("FASTDDS_", "VEG_AREA_"))}
    seconds = float(options["seconds"])
    listeners = {}
    for pc in ("a", "b"):
        listeners[pc] = subprocess.Popen(
            [*pcs[pc], sys.executable, __file__, "foreign", json.dumps({"seconds": seconds + 15, "images": False,
                                                                 "least_areas": options.get("least_areas", 0)})],
            env=defaults, stdout=subprocess.PIPE, stderr=sys.stderr, text=True)
        nodes.processes.append((f"listener_{pc}", listeners[pc]))
    ours = dict(GIVEN_ENVIRONMENT)
    for pc, module, parameters in (("b", "area_node", {}),
                                   ("a", "camera_node", dict(rate_hz=float(options["rate_hz"]), synthetic_scene="cube",
                                                             synthetic_medium="air",
                                                             camera_info_url=f"file://{calibration}"))):
        args = [*pcs[pc], sys.executable, "-m", f"veg_area_ros.ros.{module}", "--ros-args"]
        for key, value in parameters.items():
            args += ["-p", f"{key}:={value}"]
        nodes.processes.append((module, subprocess.Popen(args, env=ours, stdout=sys.stderr, stderr=sys.stderr)))
    results = {}
    for pc, listener in listeners.items():
        lines = [line for line in listener.communicate(timeout=seconds + 120)[0].splitlines()
                 if line.startswith("RESULT ")]
        results[pc] = json.loads(lines[-1][len("RESULT "):]) if lines else None
    return {"camera_pc": results["a"], "measuring_pc": results["b"], "truth_m2": cube_scene().true_area_m2}


def scenario_record_cli(options: dict, nodes: Nodes) -> dict:
    """`veg-area record` as a user types it, beside a camera: a mistyped topic (--duration 3) and --all (8)."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    nodes.start("camera_node", rate_hz=5.0, synthetic_scene="cube", synthetic_medium="air")
    rclpy.init()
    probe = Node("camera_watch")
    images: list[int] = []
    probe.create_subscription(Image, "image_raw", lambda m: images.append(1), qos_profile_sensor_data)
    deadline = time.monotonic() + 60
    while not images and time.monotonic() < deadline:  # the camera is publishing before anyone records
        rclpy.spin_once(probe, timeout_sec=0.1)
    probe.destroy_node()
    rclpy.try_shutdown()
    runs = {}
    # --all records for 8 s: discovery alone takes 2-5 s of it on a loaded machine
    for name, args, seconds in (("mistyped", ["image_rwa"], 3), ("all", ["--all"], 8)):
        started = time.monotonic()
        done = subprocess.run([sys.executable, "-m", "veg_area_ros.cli", "record", *args, "--duration", str(seconds),
                               "-o", str(Path(name).resolve())], env=GIVEN_ENVIRONMENT, capture_output=True,
                              text=True, timeout=60)
        runs[name] = {"exit": done.returncode, "stderr": done.stderr[-2000:], "seconds": time.monotonic() - started,
                      "bag": str(Path(name).resolve())}
    # a disk that fills while recording: a 512 kB tmpfs in a private mount namespace (one 640x480 image is 900 kB)
    if shutil.which("unshare") is None:
        runs["full"] = None
        return runs
    full = Path("full").resolve()
    full.mkdir()
    done = subprocess.run(["unshare", "-m", "sh", "-c", f"mount -t tmpfs -o size=512k none {full} && exec "
                           f"{sys.executable} -m veg_area_ros.cli record image_raw camera_info --duration 6 -o "
                           f"{full / 'bag'}"], env=GIVEN_ENVIRONMENT, capture_output=True, text=True, timeout=90)
    runs["full"] = {"exit": done.returncode, "stderr": done.stderr[-3000:]}
    return runs


def scenario_replay(options: dict, nodes: Nodes) -> dict:
    """A recorded bag's image_raw and camera_info replayed by `veg-area play` to a fresh area node; this probe
    keeps the replayed run's Af by stamp."""
    import rclpy
    from rclpy.node import Node

    from veg_area_msgs.msg import ProjectedArea
    from veg_area_ros.ros.qos import RESULT_QOS

    rclpy.init()
    probe = Node("replay_probe")
    areas: dict[str, float] = {}
    probe.create_subscription(
        ProjectedArea, "projected_area",
        lambda m: areas.__setitem__(f"{m.header.stamp.sec}.{m.header.stamp.nanosec:09d}", m.area_m2), RESULT_QOS)
    area = nodes.start("area_node")
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not probe.get_publishers_info_by_topic("/projected_area"):
            rclpy.spin_once(probe, timeout_sec=0.1)
        player = subprocess.Popen([sys.executable, "-m", "veg_area_ros.cli", "play", options["bag"], "--topics",
                                   "image_raw", "camera_info", "--delay", "2"], env=GIVEN_ENVIRONMENT,
                                  stdout=sys.stderr, stderr=sys.stderr)
        nodes.processes.append(("player", player))
        deadline = time.monotonic() + 120
        while player.poll() is None and time.monotonic() < deadline:
            rclpy.spin_once(probe, timeout_sec=0.05)
        end = time.monotonic() + 3  # the last frames' results
        while time.monotonic() < end:
            rclpy.spin_once(probe, timeout_sec=0.05)
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return {"areas": areas, "player_exit": player.returncode, "area_alive": area.poll() is None}


INFO_QOS_OF = {  # how camera drivers offer camera_info
    "usb_cam": dict(reliability="RELIABLE", durability="VOLATILE", depth=100),
    "sensor_data": dict(reliability="BEST_EFFORT", durability="VOLATILE", depth=5),
    "latched": dict(reliability="RELIABLE", durability="TRANSIENT_LOCAL", depth=1),
}


def scenario_driver_qos(options: dict, nodes: Nodes) -> dict:
    """A camera driver in this probe: image_raw (sensor data QoS) and camera_info with every frame, offered with
    options["qos"] (INFO_QOS_OF); the area node (started after the driver's first frames) must measure."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image
    from std_msgs.msg import String

    from veg_area_msgs.msg import ProjectedArea
    from veg_area_ros.ros.messages import camera_to_info, image_to_msg
    from veg_area_ros.ros.qos import RESULT_QOS
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene

    offered = INFO_QOS_OF[options["qos"]]
    info_qos = QoSProfile(depth=offered["depth"], reliability=getattr(ReliabilityPolicy, offered["reliability"]),
                          durability=getattr(DurabilityPolicy, offered["durability"]))
    rclpy.init()
    probe = Node("driver")
    image_pub = probe.create_publisher(Image, "image_raw", qos_profile_sensor_data)
    info_pub = probe.create_publisher(CameraInfo, "camera_info", info_qos)
    areas: list[float] = []
    infos: list[str] = []
    probe.create_subscription(ProjectedArea, "projected_area", lambda m: areas.append(m.area_m2), RESULT_QOS)
    probe.create_subscription(String, "projected_area/info", lambda m: infos.append(m.data), RESULT_QOS)
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7, roll_deg=0.0)
    published = 0

    def publish() -> None:
        nonlocal published
        stamp = probe.get_clock().now().to_msg()
        image = image_to_msg(frame, stamp, "camera")
        info = camera_to_info(ENDOSCOPE, options.get("info_frame_id", "camera"), stamp)
        info_pub.publish(info)
        image_pub.publish(image)
        published += 1

    probe.create_timer(0.1, publish)
    try:
        end = time.monotonic() + 1.0
        while time.monotonic() < end:  # the driver runs first, as in a lab
            rclpy.spin_once(probe, timeout_sec=0.05)
        nodes.start("area_node")
        spin_for(probe, float(options["seconds"]), until=lambda: len(areas) >= options.get("least_areas", 0))
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    last = json.loads(infos[-1]) if infos else {}
    return {"areas": areas, "published": published, "truth_m2": cube_scene().true_area_m2,
            "frames_received": last.get("frames_received", 0), "frames_measured": last.get("frames_measured", 0),
            "warnings": last.get("warnings", [])}



def scenario_bad_start_files(options: dict, nodes: Nodes) -> dict:
    """Every node started with a file it cannot read (targets_file missing, calibration_file and both
    camera_info_url files corrupt): each logs why and what it does instead, and runs on; the area node measures
    once targets_file is set to a readable file."""
    import rclpy
    from rcl_interfaces.msg import Log
    from rcl_interfaces.srv import SetParameters
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    from veg_area_ros.ros.qos import RESULT_QOS
    from veg_area_ros.sim.synthetic import scene_targets_content

    corrupt = Path("corrupt.yaml").resolve()
    corrupt.write_text("image_width: [640\n")
    logs: dict[str, list[str]] = {}
    rclpy.init()
    probe = Node("probe")
    # transient local, as rclpy publishes /rosout: the start-up lines come before the probe discovers the nodes
    probe.create_subscription(Log, "/rosout", lambda m: logs.setdefault(m.name, []).append(m.msg),
                              QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                                         durability=DurabilityPolicy.TRANSIENT_LOCAL))
    infos: list[dict] = []
    probe.create_subscription(String, "projected_area/info", lambda m: infos.append(json.loads(m.data)), RESULT_QOS)
    nodes.start("camera_node", camera_info_url=f"file://{corrupt}", synthetic_scene="cube", rate_hz=5.0)
    nodes.start("calibration_node", camera_info_url=f"file://{corrupt}")
    nodes.start("area_node", targets_file=str(Path("missing_targets.yaml").resolve()),
                calibration_file=str(corrupt), uncalibrated_frames="measure",
                background_file=str(Path("missing_background.png").resolve()))

    def spin_until(condition, seconds: float) -> bool:
        deadline = time.monotonic() + seconds
        while not condition() and time.monotonic() < deadline:
            rclpy.spin_once(probe, timeout_sec=0.05)
        return condition()

    def said(node: str, text: str) -> bool:
        return any(text in line for line in logs.get(node, []))

    out: dict = {}
    try:
        spin_until(lambda: said("area_node", "frame not measured") and said("camera_node", "parameter")
                   and said("calibration_node", "parameter"), 60)
        out["logs"] = logs
        out["measured_without_targets"] = len(infos)
        out["alive_before_fix"] = nodes.alive()
        client = probe.create_client(SetParameters, "area_node/set_parameters")
        client.wait_for_service(timeout_sec=20)
        # first a targets file of another ArUco dictionary than the markers in view: the node says which it sees
        other = Path("targets_5x5.yaml").resolve()
        other.write_text(yaml.safe_dump({**scene_targets_content(), "dictionary": "DICT_5X5_50"}))
        future = client.call_async(SetParameters.Request(
            parameters=[Parameter("targets_file", value=str(other)).to_parameter_msg()]))
        spin_until(future.done, 20)
        out["dictionary_hint"] = spin_until(
            lambda: said("area_node", "not DICT_5X5_50's: is the targets file's dictionary DICT_4X4_50?"), 30)
        targets = Path("targets.yaml").resolve()
        content = scene_targets_content()
        content["markers"][7] = [0.0, 0.16]  # listed, never in view: said in every result
        targets.write_text(yaml.safe_dump(content))
        future = client.call_async(SetParameters.Request(
            parameters=[Parameter("targets_file", value=str(targets)).to_parameter_msg()]))
        spin_until(future.done, 20)
        out["targets_file_set"] = future.done() and future.result().results[0].successful
        out["measured_after_fix"] = spin_until(lambda: len(infos) >= 3, 60)
        out["warnings"] = infos[-1]["warnings"] if infos else None
        spin_until(lambda: said("area_node", "Af less trustworthy"), 10)
        out["logs"] = logs
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return out




def scenario_guidance(options: dict, nodes: Nodes) -> dict:
    """calibration_node fed a sequence of board views (options["sequence"]: varied, no_tilt, no_corner or
    no_roll, from test_guidance's pose generator) by the probe: its ~/progress, whether it fitted, and ~/feedback
    (first without a subscriber, then with one)."""
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image
    from test_guidance import BOARD_SPEC, PORT, poses

    from veg_area_msgs.msg import CalibrationProgress
    from veg_area_ros.ros.messages import image_to_msg, msg_to_image, progress_as_dict
    from veg_area_ros.ros.qos import IMAGE_QOS, RESULT_QOS
    from veg_area_ros.sim.synthetic import ENDOSCOPE, render_board_views

    sequence = options["sequence"]
    arguments = {"varied": {}, "no_tilt": {"tilt": 0.0}, "no_roll": {"rolls": (0.0,)},
                 "no_corner": {"places": ((-1, -1), (1, -1), (-1, 1), (0, 0), (-1, 0), (0, -1), (0, 1), (1, 0))}}
    images = render_board_views(ENDOSCOPE, BOARD_SPEC, poses(16, **arguments[sequence]), port=PORT,
                                rng=np.random.default_rng(1), noise_sigma=2.0, supersample=2)
    served = Path("guided.yaml").resolve()
    board = {"board": options["board"]} if "board" in options else {}  # the node's spec, if not the printed board
    nodes.start("calibration_node", camera_info_url=f"file://{served}", min_views=12, **board)
    rclpy.init()
    probe = Node("probe")
    progress: list[dict] = []
    probe.create_subscription(CalibrationProgress, "calibration_node/progress",
                              lambda m: progress.append(progress_as_dict(m)), RESULT_QOS)
    publisher = probe.create_publisher(Image, "image_raw", IMAGE_QOS)
    out: dict = {"sequence": sequence}

    def spin(seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            rclpy.spin_once(probe, timeout_sec=0.02)

    deadline = time.monotonic() + 30
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        spin(0.1)
    for image in images:  # each pose held for three frames, as a hand holds it
        for _ in range(3):
            publisher.publish(image_to_msg(image, probe.get_clock().now().to_msg(), "camera"))
            spin(0.25)
    spin(15 if sequence == "varied" and "board" not in options else 3)  # a fit takes seconds
    if "board" in options:  # the same views on until the node has looked at 30 (a busy machine skips some)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (progress and progress[-1]["frames_looked"] >= 32) and not any(
                p["message"].startswith("no ") for p in progress):
            publisher.publish(image_to_msg(images[len(progress) % len(images)], probe.get_clock().now().to_msg(),
                                           "camera"))
            spin(0.25)
        spin(3)
    out["progress"] = progress[-1] if progress else None
    out["feedback_before_subscribing"] = progress[-1].get("feedback_published") if progress else None
    out["rejected_lines"] = [p["message"] for p in progress if p["message"].startswith("view rejected")]
    out["no_board_lines"] = [p["message"] for p in progress if p["message"].startswith("no ")]
    out["fitted"] = served.exists()

    # ~/feedback: nothing before anyone subscribes (the node counts what it published), then frames
    feedback: list = []
    probe.create_subscription(Image, "calibration_node/feedback", feedback.append, IMAGE_QOS)
    spin(2.0)
    image = images[len(images) // 2]
    for _ in range(8):
        publisher.publish(image_to_msg(image, probe.get_clock().now().to_msg(), "camera"))
        spin(0.3)
    spin(1.0)
    out["feedback_count"] = len(feedback)
    if feedback:
        last = feedback[-1]
        out["feedback_encoding"], out["feedback_size"] = last.encoding, [last.width, last.height]
        shown = msg_to_image(last)
        detection = BOARD_SPEC.detect(image)
        from veg_area_ros.feedback import KEPT_COLOUR, REJECTED_COLOUR, SIMILAR_COLOUR

        rings = []
        for x, y in detection.image_points[::5]:  # a ring round each detected point, in one of the point colours
            patch = shown[round(y) - 4:round(y) + 5, round(x) - 4:round(x) + 5].reshape(-1, 3).astype(int)
            rings.append(int(min(np.min(np.abs(patch - np.array(colour)).sum(axis=1))
                                 for colour in (KEPT_COLOUR, SIMILAR_COLOUR, REJECTED_COLOUR))))
        out["ring_distances"] = rings
    # a burst faster than frames can be looked at: the ones that came meanwhile are counted, not queued
    for _ in range(40):
        publisher.publish(image_to_msg(image, probe.get_clock().now().to_msg(), "camera"))
    spin(3.0)
    for _ in range(3):  # frames after more than 2 s: the node reports its skipped count
        publisher.publish(image_to_msg(image, probe.get_clock().now().to_msg(), "camera"))
        spin(1.0)
    said = [p for p in progress if "frames skipped so far" in p["message"]]
    out["skipped_report"] = said[-1] if said else None
    probe.destroy_node()
    rclpy.try_shutdown()
    return out


def scenario_replay_into_recorder(options: dict, nodes: Nodes) -> dict:
    """`veg-area record` of some topics started beside `veg-area play` of a bag written by other tools (no QoS
    metadata), or (`silent`) beside a publisher of those topics that never publishes: the player's exit and
    output, the recorder's exit and stderr."""
    recorder = subprocess.Popen([sys.executable, "-m", "veg_area_ros.cli", "record", *options["topics"],
                                 "--duration", str(options["duration"]), "-o", options["output"]],
                                env=GIVEN_ENVIRONMENT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    nodes.processes.append(("recorder", recorder))
    if options.get("silent"):
        import rclpy
        from rclpy.node import Node
        from sensor_msgs.msg import CameraInfo

        rclpy.init()
        silent = Node("silent_camera")
        publishers = [silent.create_publisher(CameraInfo, topic, 10) for topic in options["topics"]]
        while recorder.poll() is None:
            rclpy.spin_once(silent, timeout_sec=0.1)
        del publishers
        silent.destroy_node()
        rclpy.try_shutdown()
        player_exit, player_stderr = None, ""
    else:
        player = subprocess.Popen([sys.executable, "-m", "veg_area_ros.cli", "play", options["bag"], "--delay", "0",
                                   "--wait-for-subscribers", "20"], env=GIVEN_ENVIRONMENT,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        nodes.processes.append(("player", player))
        _, player_stderr = player.communicate(timeout=120)
        player_exit = player.returncode
    _, recorded_stderr = recorder.communicate(timeout=120)
    stamps = {}
    if Path(options["output"]).exists():  # which messages came: the first, the last or others missing
        from rosbags.rosbag2 import Reader

        from veg_area_ros.cdr import stamp_ns
        with Reader(options["output"]) as reader:
            for connection, _, data in reader.messages():
                stamps.setdefault(connection.topic, []).append(stamp_ns(data) // 10**9)
    return {"player_exit": player_exit, "player_stderr": player_stderr[-3000:], "stamps": stamps,
            "recorder_exit": recorder.returncode, "recorder_stderr": recorded_stderr[-3000:]}


def scenario_compressed_driver(options: dict, nodes: Nodes) -> dict:
    """A camera driver in this probe publishing image_transport's compressed topic (image_raw/compressed, JPEG,
    sensor data QoS; with `transport` zstd, its zstd plugin's image_raw/zstd, the bgr8 rows zstd-compressed behind
    the plugin's header) and camera_info; the area node started with that image_transport measures it, the
    calibration node started with it looks at the frames (its own camera_info remapped aside), the console started
    with it shows them in its camera view (one JPEG fetched as a page fetches it), and a record node records both
    topics as they are published (closed with SIGINT at the end)."""
    import cv2
    import numpy as np
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, CompressedImage

    from veg_area_msgs.msg import CalibrationProgress, ProjectedArea
    from veg_area_ros.ros.messages import camera_to_info
    from veg_area_ros.ros.qos import RESULT_QOS
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene

    transport = options.get("transport", "compressed")
    rclpy.init()
    probe = Node("compressed_driver")
    image_pub = probe.create_publisher(CompressedImage, f"image_raw/{transport}", qos_profile_sensor_data)
    info_pub = probe.create_publisher(CameraInfo, "camera_info", qos_profile_sensor_data)
    areas: list[float] = []
    probe.create_subscription(ProjectedArea, "projected_area", lambda m: areas.append(m.area_m2), RESULT_QOS)
    looked = [0]
    probe.create_subscription(CalibrationProgress, "calibration_node/progress",
                              lambda m: looked.__setitem__(0, max(looked[0], m.frames_looked)), RESULT_QOS)
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7)
    if transport == "zstd":  # zstd_image_transport's layout: height, width, is_bigendian, step, encoding, frame
        from backports import zstd

        jpeg = np.frombuffer(struct.pack("<IIBII", *frame.shape[:2], 0, frame.shape[1] * 3, 4) + b"bgr8"
                             + zstd.compress(frame.tobytes(), 3), np.uint8)
        image_format = "zstd"
    else:
        jpeg = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 90])[1]
        image_format = "bgr8; jpeg compressed bgr8"
    published = 0

    def publish() -> None:
        nonlocal published
        stamp = probe.get_clock().now().to_msg()
        message = CompressedImage(format=image_format, data=jpeg.ravel().tobytes())
        message.header.stamp, message.header.frame_id = stamp, "camera"
        info_pub.publish(camera_to_info(ENDOSCOPE, "camera", stamp))
        image_pub.publish(message)
        published += 1

    recorder = nodes.start("record_node", output=str(Path("recorded").resolve()),
                           topics=[f"image_raw/{transport}", "camera_info"])
    probe.create_timer(0.2, publish)
    try:
        nodes.start("area_node", image_transport=transport)
        nodes.start("calibration_node", image_transport=transport,
                    camera_info_url=f"file://{Path('calibration.yaml').resolve()}",
                    remap={"camera_info": "calibration/camera_info",
                           "camera_info/metadata": "calibration/camera_info/metadata"})
        nodes.start("console_node", image_transport=transport, port=CONSOLE_PROBE_PORT)
        spin_for(probe, float(options["seconds"]), until=lambda: len(areas) >= 5 and looked[0] >= 3)
        shown = console_frame("camera", probe)
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    recorder.send_signal(signal.SIGINT)
    recorder.wait(20)
    return {"areas": areas, "published": published, "jpeg": np.asarray(jpeg).ravel().tolist(),
            "recorder_exit": recorder.returncode, "calibration_frames_looked": looked[0], "console_camera": shown}


CONSOLE_PROBE_PORT = 18093


def console_frame(view: str, probe, seconds: float = 30.0) -> dict:
    """One JPEG of a console view, asked for as a page asks (the first asks make the console subscribe):
    its size in bytes and the frame size the console says, or what it answered last. The probe spins between
    the asks (its timers publish the frames)."""
    import urllib.error
    import urllib.request

    import rclpy

    deadline, answer = time.monotonic() + seconds, {}
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{CONSOLE_PROBE_PORT}/api/frame/{view}", timeout=5) as reply:
                body = reply.read()
                answer = {"status": reply.status, "bytes": len(body), "size": reply.headers.get("X-Frame-Size")}
                if reply.status == 200 and body[:2] == b"\xff\xd8":
                    return answer
        except (urllib.error.URLError, ConnectionError, TimeoutError) as exc:
            answer = {"error": str(exc)}
        spin_until = time.monotonic() + 0.3
        while time.monotonic() < spin_until:
            rclpy.spin_once(probe, timeout_sec=0.05)
    return answer


def scenario_mono16_driver(options: dict, nodes: Nodes) -> dict:
    """A machine-vision camera's driver in this probe publishing a 12-bit sensor's frames as mono16 on image_raw
    (sensor data QoS) with camera_info, every other frame left unstamped (header stamp 0, as some drivers leave
    it); the area node measures them: each result's Af, warnings and stamp."""
    import cv2
    import numpy as np
    import rclpy
    from builtin_interfaces.msg import Time
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image

    from veg_area_msgs.msg import ProjectedArea
    from veg_area_ros.ros.messages import camera_to_info
    from veg_area_ros.ros.qos import RESULT_QOS
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene

    rclpy.init()
    probe = Node("mono16_driver")
    image_pub = probe.create_publisher(Image, "image_raw", qos_profile_sensor_data)
    info_pub = probe.create_publisher(CameraInfo, "camera_info", qos_profile_sensor_data)
    results: list[tuple[float, list[str], int]] = []
    probe.create_subscription(ProjectedArea, "projected_area", lambda m: results.append(
        (m.area_m2, list(m.warnings), m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)), RESULT_QOS)
    grey = cv2.cvtColor(render_scene(ENDOSCOPE, cube_scene(), 0.7), cv2.COLOR_BGR2GRAY)
    twelve = (grey.astype(np.uint16) << 4) | np.random.default_rng(0).integers(0, 16, grey.shape, dtype=np.uint16)

    published = 0

    def publish() -> None:
        nonlocal published
        stamp = probe.get_clock().now().to_msg() if published % 2 == 0 else Time()
        published += 1
        message = Image(height=480, width=640, encoding="mono16", is_bigendian=0, step=1280,
                        data=twelve.astype("<u2").tobytes())
        message.header.stamp, message.header.frame_id = stamp, "camera"
        info_pub.publish(camera_to_info(ENDOSCOPE, "camera", stamp))
        image_pub.publish(message)

    probe.create_timer(0.2, publish)
    try:
        nodes.start("area_node")
        spin_for(probe, float(options["seconds"]), until=lambda: sum(r[2] == 0 for r in results) >= 2
                 and sum(r[2] != 0 for r in results) >= 2)
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return {"results": results, "grey": grey.ravel().tolist()}


def scenario_metadata(options: dict, nodes: Nodes) -> dict:
    """A calibration whose file records the tone curve srgb and the medium air, served on camera_info by the
    camera node (camera_info_url as camera_info_manager's default: ${ROS_HOME}/camera_info/${NAME}.yaml) or the
    calibration node (its camera_info_url) to an area node given no
    calibration_file (tone_curve auto): the tone curve the area node's results were read with, and what the
    file's edge trend did to them. With `area_mode` the file records that reading too, and with `background` the
    area node is given a frame of the empty scene, with `levels` the object's and background's levels (which only
    the shares use)."""
    from veg_area_ros.calib_io import write_calibration
    from veg_area_ros.sim.synthetic import ENDOSCOPE

    # where camera_info_manager's default URL, file://${ROS_HOME}/camera_info/${NAME}.yaml, finds it
    calibration = Path("ros_home", "camera_info", "endoscope.yaml").resolve()
    calibration.parent.mkdir(parents=True)
    GIVEN_ENVIRONMENT["ROS_HOME"] = str(Path("ros_home").resolve())
    # and an edge trend learned under the linear curve: applied to frames read as grey levels, refused (said) else
    trend = {"learned": True, "slope_px_per_dn": -0.003, "slope_std": 0.0005, "reference_dn": 190.0,
             "range_dn": [150.0, 250.0], "views": 8, "residual_px": 0.02, "scatter_px": 0.0, "tone_curve": "linear"}
    # and the parameters' covariance, carried to each frame's std once the metadata has come
    from veg_area_ros.camera_uncertainty import CameraCovariance

    covariance = CameraCovariance.from_std(dict.fromkeys(ENDOSCOPE.param_names, 1e-3), {}).as_dict()
    metadata = {"medium": "air", "tone_curve": options["tone_curve"], "edge_trend": trend,
                "camera_covariance": covariance}
    if options.get("area_mode"):
        metadata.update(area_mode=options["area_mode"], area_mode_evidence="3 views: spread 0.61 % with the "
                        "shares, 0.52 % counted")
    write_calibration(calibration, ENDOSCOPE, "endoscope", metadata)
    if options["server"] == "camera":
        nodes.start("camera_node", rate_hz=5.0, synthetic_scene="cube", synthetic_medium="air",
                    camera_info_url="file://${ROS_HOME}/camera_info/${NAME}.yaml", camera_name="endoscope")
    else:
        nodes.start("calibration_node", camera_info_url=f"file://{calibration}")
        nodes.start("camera_node", rate_hz=5.0, synthetic_scene="cube", synthetic_medium="air")
    area_options = {}
    if options.get("background"):
        import cv2

        background = Path("empty_flume.png").resolve()
        cv2.imwrite(str(background), np.full((ENDOSCOPE.height, ENDOSCOPE.width), 200, np.uint8))
        area_options["background_file"] = str(background)
    if options.get("levels"):
        area_options["levels"] = [40.0, 200.0]
    nodes.start("area_node", **area_options)
    import rclpy
    from rclpy.node import Node
    from std_msgs.msg import String

    from veg_area_ros.ros.qos import RESULT_QOS

    rclpy.init()
    probe = Node("metadata_probe")
    infos: list[dict] = []
    probe.create_subscription(String, "projected_area/info", lambda m: infos.append(json.loads(m.data)), RESULT_QOS)
    try:
        def settled() -> bool:  # ten results, the last five read with one curve and one reading
            read = [(i.get("tone_curve"), i.get("area_mode")) for i in infos if i.get("calibrated")]
            return len(read) >= 10 and len(set(read[-5:])) == 1

        spin_for(probe, 0.0, until=settled, longest=float(options["seconds"]))
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
    return {"tone_curves": [i.get("tone_curve") for i in infos if i.get("calibrated")],
            "edge_trends": [i.get("edge_trend") for i in infos if i.get("calibrated")],
            "calibration_stds": [i.get("calibration_std_m2") for i in infos if i.get("calibrated")],
            "area_modes": [i.get("area_mode") for i in infos if i.get("calibrated")]}


if __name__ == "__main__":
    sys.exit(main())

