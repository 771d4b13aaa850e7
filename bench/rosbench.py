"""What the ROS 2 benchmarks share: running confined to this machine exactly as the tests do (a private
network namespace with only loopback and a private /dev/shm, veg_area_ros.ros.confine), child processes that are
always reaped, the two transport configurations, latency figures and memory per process."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "veg_area_ros"))  # the source tree's package, not an installed copy

from veg_area_ros.ros.confine import confined, netns_available, remove_new_shm, ros_environment, shm_files  # noqa: E402

INSIDE = "--inside"
TRANSPORTS = ("shm", "default")


def run_confined(script: Path, argv: list[str]) -> int:
    """Run `script --inside argv...` confined to this machine and stream what it prints; returns its exit code."""
    print("confinement:", "private network namespace (loopback only) and private /dev/shm" if netns_available()
          else "none available: shared-memory profile only, /dev/shm cleaned afterwards", flush=True)
    before = shm_files()
    with tempfile.TemporaryDirectory(prefix="veg_area_bench_") as home:
        env = ros_environment(Path(home), 1)
        command = confined([sys.executable, str(script), INSIDE, *argv])
        try:
            return subprocess.run(command, env=env, cwd=home).returncode
        finally:
            remove_new_shm(before)


def bench_main(script: Path, roles: tuple[str, ...], role_main, parser: argparse.ArgumentParser, inside) -> int:
    """A ROS bench's entry point: `script ROLE SPEC` is one of its child processes; `script --inside ...` is the
    run itself, already confined; anything else is the user's call, re-run confined."""
    if len(sys.argv) > 2 and sys.argv[1] in roles:
        return role_main(sys.argv[1], json.loads(sys.argv[2]))
    parser.add_argument(INSIDE, action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    return inside(args) if args.inside else run_confined(script, sys.argv[1:])


def role_command(script: Path, role: str, spec: dict) -> list[str]:
    """The command that runs `script` as one of its child roles with `spec`."""
    return [sys.executable, str(script), role, json.dumps(spec)]


def transport_environment(transport: str, domain: int) -> dict[str, str]:
    """`shm`: the shipped shared-memory profile (what the nodes use by default); `default`: Fast DDS as it comes,
    discovery limited to this host (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    if transport == "default":
        env.pop("FASTDDS_DEFAULT_PROFILES_FILE", None)
        env.update(VEG_AREA_TRANSPORT="default", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env


class Children:
    """Child processes (spawned, never forked) whose last stdout line is a JSON result; always reaped."""

    def __init__(self) -> None:
        self.processes: list[subprocess.Popen] = []

    def start(self, args: list[str], env: dict[str, str]) -> subprocess.Popen:
        process = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        self.processes.append(process)
        return process

    @staticmethod
    def result(process: subprocess.Popen, timeout: float) -> dict | None:
        try:
            out, _ = process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None
        lines = [line for line in out.splitlines() if line.startswith("{")]
        return json.loads(lines[-1]) if lines else None

    def reap(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for process in self.processes:
            try:
                process.wait(10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        self.processes.clear()


def latency_ms(latencies_s: list[float]) -> dict[str, float | None]:
    if not latencies_s:
        return {"mean": None, "p99": None, "max": None}
    values = 1000 * np.asarray(latencies_s)
    return {"mean": float(values.mean()), "p99": float(np.percentile(values, 99)), "max": float(values.max())}


def memory_mb(pid: int) -> dict[str, float]:
    """Resident (RSS) and proportional (PSS: shared pages split among their users) memory of a process."""
    fields = {}
    try:
        lines = Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines()[1:]
    except OSError:  # it ended meanwhile
        return {"rss": 0.0, "pss": 0.0}
    for line in lines:
        key, value = line.split(":", 1)
        fields[key] = int(value.split()[0]) / 1024
    return {"rss": fields.get("Rss", 0.0), "pss": fields.get("Pss", 0.0)}


def cpu_seconds(pid: int, main_thread_only: bool = False) -> float | None:
    """CPU time a process has used so far (user + system; all its threads, or only its main thread, where
    rclpy's executor runs the callbacks), None once it has ended."""
    try:
        stat = Path(f"/proc/{pid}/task/{pid}/stat" if main_thread_only else f"/proc/{pid}/stat")
        fields = stat.read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime: fields 14, 15


def cpu_over(samples: list[tuple[float, float]], start: float, end: float) -> float | None:
    """CPU seconds used between two wall-clock times, from (time, cpu_seconds) samples taken meanwhile."""
    inside = [cpu for at, cpu in samples if start <= at <= end]
    return inside[-1] - inside[0] if len(inside) >= 2 else None


def shm_mb() -> float:
    """What the transport holds in /dev/shm (this confinement's own when private)."""
    total = 0
    for path in Path("/dev/shm").iterdir():
        with contextlib.suppress(OSError):  # a participant going away meanwhile
            total += path.stat().st_size
    return total / 2**20


def figure(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"
