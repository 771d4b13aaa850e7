"""`veg-area doctor`: what makes a lab PC fail silently, each problem with its fix (the `ros2 doctor` of this
package). No ROS imported here: rclpy is tried in a child process, so a broken install is a finding, not a
crash.

Each check returns Findings; a finding is a problem (exit 1) or a note (how things stand, exit 0).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .transport import (
    INDEX_MARKER,
    PROFILES,
    SOCKET_BUFFER_BYTES,
    ament_prefix,
    choose_transport,
    config_locations,
    low_socket_buffers,
)

SHM_MIN_BYTES = 256 * 2**20  # three nodes' segments at 3872x2592 took 134 MB; docker's default is 64 MB
DISCOVERY_RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")


@dataclass(frozen=True)
class Finding:
    check: str  # short name: rclpy, transport, socket buffers, ...
    ok: bool  # False: a problem
    message: str
    fix: str = ""

    def lines(self) -> list[str]:
        head = f"{'ok     ' if self.ok else 'PROBLEM'} {self.check}: {self.message}"
        return [head] + ([f"        fix: {self.fix}"] if self.fix and not self.ok else [])


def check_rclpy(python: str = sys.executable) -> list[Finding]:
    """rclpy and the Fast DDS RMW load in a fresh interpreter (a missing shared library shows only there)."""
    code = "import rclpy, rclpy.executors, sensor_msgs.msg, std_msgs.msg; print(rclpy.__file__)"
    try:
        done = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return [Finding("rclpy", False, f"could not start {python}: {exc}", "run `make install` again")]
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        return [Finding("rclpy", False, f"import failed: {last}",
                        "in this repository `make install` (the pinned ROS 2 Kilted wheels); on a ROS 2 install "
                        "`source /opt/ros/<distro>/setup.bash` first")]
    found = [Finding("rclpy", True, f"imports ({done.stdout.strip()})")]
    code = "from rclpy.serialization import serialize_message; from veg_area_msgs.msg import ProjectedArea; " \
           "serialize_message(ProjectedArea())"
    try:
        typed = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return [*found, Finding("veg_area_msgs", False, f"could not start {python}: {exc}", "run `make install` again")]
    if typed.returncode != 0:
        last = (typed.stderr.strip().splitlines() or ["no message"])[-1]
        return [*found, Finding("veg_area_msgs", False, f"ProjectedArea does not load: {last}",
                                "in this repository `make install` (builds veg_area_msgs); on a ROS 2 install "
                                "`colcon build` with both packages in the workspace, then source install/setup.bash")]
    return [*found, Finding("veg_area_msgs", True, "ProjectedArea loads and serializes")]


def check_transport(environ: dict, sysctl_dir: Path) -> list[Finding]:
    """Which Fast DDS profile the nodes will load, what it does, and the socket buffers it needs."""
    try:
        transport = choose_transport(environ)
    except ValueError as exc:
        return [Finding("transport", False, str(exc), f"export VEG_AREA_TRANSPORT={'|'.join(PROFILES)} or unset it")]
    findings = []
    if transport.name == "default" and environ.get("VEG_AREA_TRANSPORT", "auto") != "default":
        looked = ", ".join(str(path) for path, _ in config_locations(PROFILES["auto"], environ))
        findings.append(Finding("transport", False, f"no veg_area_ros profile found (looked in {looked}): Fast DDS's "
                                "defaults lose most camera-sized best-effort images",
                                "run `make install` (or `colcon build`) so share/veg_area_ros/config is installed"))
    elif transport.profile and not Path(transport.profile).is_file():
        findings.append(Finding("transport", False, f"FASTDDS_DEFAULT_PROFILES_FILE={transport.profile} does not exist",
                                "point it at an existing XML profile, or unset it to use veg_area_ros's"))
    elif transport.name == "default":
        findings.append(Finding("transport", False, transport.description, "unset VEG_AREA_TRANSPORT"))
    else:
        findings.append(Finding("transport", True, transport.description))
    low = low_socket_buffers(sysctl_dir) if transport.name == "auto" else {}
    if low:
        now = ", ".join(f"{k} {v}" for k, v in low.items())
        findings.append(Finding("socket buffers", False, f"net.core {now} caps the UDP socket buffers below "
                                f"{SOCKET_BUFFER_BYTES}: camera-sized images to other PCs may be lost",
                                f"sudo sysctl -w net.core.rmem_max={SOCKET_BUFFER_BYTES} "
                                f"net.core.wmem_max={SOCKET_BUFFER_BYTES} (and in /etc/sysctl.d/ to keep it)"))
    elif transport.name == "auto":
        findings.append(Finding("socket buffers", True, f"net.core rmem_max and wmem_max allow {SOCKET_BUFFER_BYTES}"))
    return findings


def _open_shm_files() -> set[str]:
    """Names in /dev/shm that some process has mapped or open (a living Fast DDS participant's)."""
    used = set()
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            for line in Path(f"/proc/{pid}/maps").read_text().splitlines():
                if "/dev/shm/" in line:
                    used.add(line.rsplit("/dev/shm/", 1)[1].split()[0])
            for fd in os.listdir(f"/proc/{pid}/fd"):
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
                if target.startswith("/dev/shm/"):
                    used.add(target[len("/dev/shm/"):])
        except OSError:
            continue
    return used


def check_shared_memory(shm_dir: Path, in_use: Callable[[], set[str]] = _open_shm_files) -> list[Finding]:
    """/dev/shm large enough for camera-sized segments, and no Fast DDS files of processes that died."""
    findings = []
    try:
        stat = os.statvfs(shm_dir)
    except OSError as exc:
        return [Finding("shared memory", False, f"{shm_dir}: {exc}", "mount a tmpfs on /dev/shm")]
    size = stat.f_frsize * stat.f_blocks
    if size < SHM_MIN_BYTES:
        findings.append(Finding("shared memory", False, f"{shm_dir} holds {size / 2**20:.0f} MB, less than the "
                                f"{SHM_MIN_BYTES / 2**20:.0f} MB camera-sized images need between nodes",
                                "in docker: --shm-size=1g; elsewhere: sudo mount -o remount,size=1G /dev/shm"))
    else:
        findings.append(Finding("shared memory", True, f"{shm_dir} holds {size / 2**30:.1f} GB"))
    try:
        fast = {p.name: p for p in shm_dir.iterdir() if "fast" in p.name.lower()}
    except OSError:
        fast = {}
    dead = sorted(set(fast) - in_use()) if fast else []
    if dead:
        megabytes = sum(fast[name].stat().st_size for name in dead if fast[name].exists()) / 2**20
        shown = " ".join(str(shm_dir / name) for name in dead[:6]) + (" ..." if len(dead) > 6 else "")
        findings.append(Finding("shared memory", False, f"{len(dead)} Fast DDS file(s) ({megabytes:.0f} MB) of "
                                "processes that are gone (a killed node leaves them; they fill /dev/shm)",
                                f"with no ROS node running: rm {shown}"))
    return findings


def check_ros_environment(environ: dict) -> list[Finding]:
    """Settings that keep the nodes from other PCs or from each other."""
    findings = []
    domain = environ.get("ROS_DOMAIN_ID", "")
    if domain and not (domain.isdigit() and 0 <= int(domain) <= 232):
        findings.append(Finding("ROS_DOMAIN_ID", False, f"{domain!r} is not a domain (0..232; 0..101 is safe on "
                                "Linux); rclpy will refuse to start", "export ROS_DOMAIN_ID=0, or unset it"))
    elif domain:
        findings.append(Finding("ROS_DOMAIN_ID", True, f"{domain}: only nodes with the same ROS_DOMAIN_ID (on every "
                                "PC and in every shell) see these"))
    reach = environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "")
    if reach and reach not in DISCOVERY_RANGES:
        findings.append(Finding("ROS_AUTOMATIC_DISCOVERY_RANGE", False, f"{reach!r} is none of "
                                f"{', '.join(DISCOVERY_RANGES)}", "unset it (SUBNET, the default)"))
    elif reach == "OFF":
        findings.append(Finding("ROS_AUTOMATIC_DISCOVERY_RANGE", False, "OFF: nodes discover nobody, not even each "
                                "other on this PC (unless ROS_STATIC_PEERS lists them)",
                                "unset ROS_AUTOMATIC_DISCOVERY_RANGE"))
    elif reach == "LOCALHOST":
        findings.append(Finding("ROS_AUTOMATIC_DISCOVERY_RANGE", False, "LOCALHOST: nodes on other PCs (a flume's "
                                "force-balance driver, a recording PC) are not seen",
                                "unset it where the nodes run on several PCs (it may stay on a single PC)"))
    if environ.get("ROS_LOCALHOST_ONLY", "") == "1":
        findings.append(Finding("ROS_LOCALHOST_ONLY", False, "1: nodes on other PCs are not seen (deprecated since "
                                "Jazzy for ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)", "unset ROS_LOCALHOST_ONLY"))
    rmw = environ.get("RMW_IMPLEMENTATION", "")
    if rmw and rmw != "rmw_fastrtps_cpp":
        findings.append(Finding("RMW_IMPLEMENTATION", False, f"{rmw}: veg_area_ros's transport profile does not apply, "
                                "and nodes on another RMW may not exchange images with these",
                                "unset RMW_IMPLEMENTATION (rmw_fastrtps_cpp), or set it alike on every node"))
    return findings


def check_ament_index(environ: dict, python_prefix: Path = Path(sys.prefix)) -> list[Finding]:
    """Whether `ros2 run veg_area_ros <node>` finds the package (the ament index on AMENT_PREFIX_PATH)."""
    found = ament_prefix(environ)
    if found:
        return [Finding("ament index", True, f"ros2 run finds veg_area_ros in {found}")]
    here = python_prefix if (python_prefix / INDEX_MARKER).is_file() else None
    node = f"{here}/lib/veg_area_ros/<node>" if here else "lib/veg_area_ros/<node> of its install"
    if shutil.which("ros2", path=environ.get("PATH")):
        source = f"source {here}/setup.bash" if here and (here / "setup.bash").is_file() else \
            "source the install's setup.bash (colcon build ... then source install/setup.bash)"
        return [Finding("ament index", False, "ros2 is installed but AMENT_PREFIX_PATH holds no veg_area_ros: "
                        "`ros2 run veg_area_ros <node>` will not find it", source)]
    return [Finding("ament index", True, f"no ros2 command here (ROS 2 from pip wheels): start a node as {node}")]


def check_video_backends(work_dir: Path | None = None) -> list[Finding]:
    """OpenCV reads what labs record: an MJPG AVI (written and read back here) and MP4/H.264 (FFmpeg)."""
    import cv2
    import numpy as np

    backends = {cv2.videoio_registry.getBackendName(b) for b in cv2.videoio_registry.getStreamBackends()}
    findings = []
    with tempfile.TemporaryDirectory(dir=work_dir) as folder:
        path = str(Path(folder) / "probe.avi")
        writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
        for k in range(3):
            writer.write(np.full((48, 64, 3), 60 * k, np.uint8))
        writer.release()
        capture = cv2.VideoCapture(path)
        frames = 0
        while capture.read()[0]:
            frames += 1
        capture.release()
    if frames == 3:
        findings.append(Finding("video", True, f"MJPG AVI written and read back (OpenCV {cv2.__version__})"))
    else:
        findings.append(Finding("video", False, f"an MJPG AVI of 3 frames read back as {frames}",
                                "reinstall opencv-python-headless from requirements.txt (it carries FFmpeg)"))
    if "FFMPEG" in backends:
        findings.append(Finding("video", True, "FFmpeg backend present: MP4/H.264, MKV and AVI files decode"))
    else:
        findings.append(Finding("video", False, f"no FFmpeg backend (only {', '.join(sorted(backends))}): MP4/H.264 "
                                "videos will not open", "use the opencv-python-headless wheel of requirements.txt, "
                                "or convert videos to MJPG AVI (ffmpeg -i in.mp4 -c:v mjpeg out.avi)"))
    return findings


def diagnose(environ: dict, sysctl_dir: Path = Path("/proc/sys/net/core"), shm_dir: Path = Path("/dev/shm"),
             in_use: Callable[[], set[str]] = _open_shm_files) -> list[Finding]:
    """Every check, in the order a person would fix them."""
    return (check_rclpy() + check_transport(environ, sysctl_dir) + check_shared_memory(shm_dir, in_use)
            + check_ros_environment(environ) + check_ament_index(environ) + check_video_backends())
