"""Does the operator's console slow the measurement? The area node's Af rate with no page open and with two
pages open on the measurement view (the area node then draws its overlay for the console, the console decodes
it and makes small JPEGs, and two headless chromium pages show them), alternated in rounds in one run, confined
to this machine like the tests. Two camera rates: a real camera's (the area node keeps up) and as fast as the
camera node can (any CPU the console takes shows). Two cameras: the synthetic one (it adds fresh noise to each
frame it renders, and at full rate that, not the area node, is what fills a core) and a recorded video of the same
scene (120 frames, 3 DN of fresh noise each, MJPG as a cheap camera's) played by the camera node as a real
camera's frames arrive: cheap to read, so at full rate the area node is what cannot keep up.
Each round measures the rate without pages in two windows in a row before opening the pages: their ratio is what
the same conditions scatter by, the floor under any single round's ratio.

    .venv/bin/python bench/console_load.py [--seconds 10] [--rounds 3] [--rates 30,200] [--cameras synthetic,video]
                                           [--console-nice N]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "veg_area_ros"))
sys.path.insert(0, str(REPO / "test"))

from veg_area_ros.ros.confine import confined, netns_available, ros_environment  # noqa: E402

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"]


def start(module: str, **parameters) -> subprocess.Popen:
    args = [sys.executable, "-m", f"veg_area_ros.ros.{module}", "--ros-args"]
    for key, value in parameters.items():
        args += ["-p", f"{key}:={value}"]
    return subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def spin(probe, seconds: float) -> None:
    import rclpy

    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(probe, timeout_sec=0.02)


def count_areas(probe, stamps: list[float], seconds: float) -> float:
    """Af results per second of frames the camera stamped within the window (a result that arrives after it
    still counts; a backlog of earlier frames does not)."""
    start = time.time()
    spin(probe, seconds)
    end = time.time()
    spin(probe, 1.5)
    return sum(start <= s < end for s in stamps) / (end - start)


def cpu_ticks(pids: dict[str, list[int]]) -> dict[str, int]:
    """user + system clock ticks of each role's processes."""
    ticks = {}
    for role, group in pids.items():
        total = 0
        for pid in group:
            try:
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                total += int(fields[11]) + int(fields[12])
            except (OSError, IndexError, ValueError):
                continue
        ticks[role] = total
    return ticks


def chromium_pids() -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if "chrom" in (entry / "comm").read_text():
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


def recorded_video(path: Path, frames: int = 120, noise_dn: float = 3.0) -> Path:
    """The synthetic camera's cube scene (under water, behind its port) as an MJPG video, fresh noise per frame:
    more frames than the camera node keeps decoded for a loop, so every frame is decoded as it is played."""
    import cv2
    import numpy as np

    from veg_area_ros.sim.synthetic import DISTANCE_M, cube_scene, render_scene
    from veg_area_ros.sources import SyntheticSource

    source = SyntheticSource(scene="cube")
    clean = render_scene(source.camera, cube_scene(), DISTANCE_M, source.port, noise_sigma=0.0).astype(float)
    rng = np.random.default_rng(5)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, source.camera.image_size)
    for _ in range(frames):
        writer.write(np.clip(clean + rng.normal(0.0, noise_dn, clean.shape), 0, 255).astype(np.uint8))
    writer.release()
    return path


def measure_rate(rate_hz: float, seconds: float, rounds: int, calibration: Path, console_nice: int | None,
                 video: Path | None = None) -> dict:
    import rclpy
    from playwright.sync_api import sync_playwright
    from rclpy.node import Node

    from veg_area_msgs.msg import ProjectedArea
    from veg_area_ros.ros.qos import RESULT_QOS

    source = {"synthetic_scene": "cube"} if video is None else {"source": str(video), "loop": True}
    processes = [start("camera_node", rate_hz=rate_hz, camera_info_url=f"file://{calibration}", **source),
                 start("area_node"),
                 start("console_node", **({} if console_nice is None else {"cpu_nice": console_nice}))]
    stamps: list[float] = []
    rclpy.init()
    probe = Node("console_load_probe")
    probe.create_subscription(ProjectedArea, "projected_area",
                              lambda m: stamps.append(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9), RESULT_QOS)
    roles = {"camera": [processes[0].pid], "area": [processes[1].pid], "console": [processes[2].pid]}
    without, with_pages, cpu, loads, again = [], [], [], [], []
    try:
        spin(probe, 15.0)  # discovery, the first frames' weights
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            for _ in range(rounds):
                again.append(count_areas(probe, stamps, seconds))  # the same conditions twice: the noise floor
                without.append(count_areas(probe, stamps, seconds))
                pages = [browser.new_page() for _ in range(2)]
                for page in pages:
                    page.goto("http://127.0.0.1:8080/")
                for page in pages:
                    page.wait_for_function("document.getElementById('frame').dataset.shown === '1'", timeout=60000)
                spin(probe, 2.0)
                roles["chromium"] = chromium_pids()
                before, started = cpu_ticks(roles), time.monotonic()
                with_pages.append(count_areas(probe, stamps, seconds))
                after, elapsed = cpu_ticks(roles), time.monotonic() - started
                cpu.append({role: (after[role] - before[role]) / os.sysconf("SC_CLK_TCK") / elapsed for role in roles})
                shown = [page.evaluate("Number(document.getElementById('frame').dataset.frameNumber)")
                         for page in pages]
                loads.append(pages[0].evaluate("state.load"))  # whether the console was giving way
                for page in pages:
                    page.close()
                spin(probe, 6.0)  # the console lets the preview go after 5 s unasked
            browser.close()
    finally:
        probe.destroy_node()
        rclpy.try_shutdown()
        for process in processes:
            process.send_signal(signal.SIGINT)
        for process in processes:
            try:
                process.wait(15)
            except subprocess.TimeoutExpired:
                process.kill()
    if not all(without) or not all(again):
        raise SystemExit("the area node gave no result in a window without pages (is the installed package this "
                         "checkout's? make install)")
    ratios = [w / n for w, n in zip(with_pages, without, strict=True)]
    same = [n / a for n, a in zip(without, again, strict=True)]
    return {"camera": "synthetic" if video is None else "video", "camera_hz": rate_hz,
            "without_pages_hz": without, "with_two_pages_hz": with_pages, "ratios": ratios,
            "without_pages_before_hz": again, "no_pages_twice_ratios": same,
            "last_frame_numbers_shown": shown, "console_load_per_round": loads,
            "cpu_cores_with_pages": {role: statistics.median(c[role] for c in cpu) for role in cpu[0]}}


def inside(args: argparse.Namespace) -> int:
    from veg_area_ros.calib_io import write_calibration
    from veg_area_ros.sources import SyntheticSource

    calibration = Path("true_camera.yaml").resolve()
    write_calibration(calibration, SyntheticSource(scene="cube").camera, "synthetic")
    cases = []
    for camera in args.cameras.split(","):
        if camera not in ("synthetic", "video"):
            raise SystemExit(f"--cameras takes synthetic and/or video, got {camera!r}")
        video = None if camera == "synthetic" else recorded_video(Path("cube.avi").resolve())
        cases += [(camera, video, float(rate)) for rate in args.rates.split(",")]
    print(f"{'camera':>9} {'Hz':>4}  {'Af/s without pages':>24}  {'Af/s with two pages':>24}  "
          "ratio min / median / max; pooled")
    for camera, video, rate in cases:
        result = measure_rate(rate, args.seconds, args.rounds, calibration, args.console_nice, video)
        ratios = result["ratios"]
        pooled = sum(result["with_two_pages_hz"]) / sum(result["without_pages_hz"])
        print(f"{camera:>9} {rate:4.0f}  {' '.join(f'{v:7.1f}' for v in result['without_pages_hz']):>24}  "
              f"{' '.join(f'{v:7.1f}' for v in result['with_two_pages_hz']):>24}  "
              f"{min(ratios):.3f} / {statistics.median(ratios):.3f} / {max(ratios):.3f}; {pooled:.3f}", flush=True)
        same = result["no_pages_twice_ratios"]
        print(f"           no pages in two windows in a row (the noise floor): {min(same):.3f} / "
              f"{statistics.median(same):.3f} / {max(same):.3f}", flush=True)
        print("           CPU (cores) with the pages open: " + ", ".join(
            f"{role} {value:.2f}" for role, value in result["cpu_cores_with_pages"].items()), flush=True)
        loads = result["console_load_per_round"]
        print(f"           the console gave way in {sum(bool(load and load['slowed']) for load in loads)} of "
              f"{len(loads)} rounds (CPU pressure at each round's end: "
              + ", ".join("-" if not load or load["cpu_pressure"] is None else f"{100 * load['cpu_pressure']:.0f} %"
                          for load in loads) + ")", flush=True)
        print("RESULT " + json.dumps(result), flush=True)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--rates", default="30,200")
    parser.add_argument("--cameras", default="synthetic,video", help="the synthetic camera's frames and/or a video's")
    parser.add_argument("--console-nice", type=int, default=None,
                        help="the console node's cpu_nice (default: the node's own default)")
    parser.add_argument("--inside", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.inside:
        return inside(args)
    print("confinement:", "private network namespace (loopback only)" if netns_available() else
          "none available: loopback transport", flush=True)
    with tempfile.TemporaryDirectory(prefix="veg_area_console_bench_") as home:
        env = ros_environment(Path(home), 3)
        return subprocess.run(confined([sys.executable, __file__, "--inside", *sys.argv[1:]]), env=env,
                              cwd=home).returncode


if __name__ == "__main__":
    sys.exit(main())
