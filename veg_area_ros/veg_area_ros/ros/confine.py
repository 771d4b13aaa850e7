"""Running ROS 2 processes confined to this machine, for the tests and the benchmarks alike.

As root with `unshare` (CI): a private network namespace that has only loopback and a private /dev/shm
(tmpfs), so no traffic can leave and nothing is left in the host's /dev/shm; every node started lives and dies
in there, and chooses its transport itself as in a user's shell. Elsewhere (fallback): VEG_AREA_TRANSPORT=local
(shared memory, UDP on 127.0.0.1 only, so discovery stays on loopback), and what a run added to /dev/shm is
removed after it. No rclpy here.
"""

from __future__ import annotations

import functools
import itertools
import os
import subprocess
from pathlib import Path

SOURCE_ROOT = Path(__file__).resolve().parents[2]  # the folder holding veg_area_ros: PYTHONPATH of the children
_domains = itertools.count((os.getpid() % 50) * 4 + 1)


@functools.cache
def netns_available() -> bool:
    try:
        probe = ["unshare", "--net", "--mount", "sh", "-c", "ip link set lo up && mount -t tmpfs tmpfs /dev/shm"]
        return subprocess.run(probe, capture_output=True, timeout=10).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def next_domain() -> int:
    """A ROS_DOMAIN_ID no other run of this process has used (0..229, the ids Fast DDS maps to ports)."""
    return next(_domains) % 230


def ros_environment(home: Path, domain: int) -> dict[str, str]:
    """This environment without the caller's ROS/DDS settings, plus a home (where ROS logs), a domain and this
    source tree on PYTHONPATH. No transport setting where a private namespace confines the run: every node
    chooses its transport itself, as in a user's shell. Without one, VEG_AREA_TRANSPORT=local is the
    confinement (UDP on 127.0.0.1 only)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "RMW_", "VEG_AREA_"))}
    env.update(HOME=str(home), PYTHONPATH=str(SOURCE_ROOT), ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1")
    if not netns_available():
        env["VEG_AREA_TRANSPORT"] = "local"
    return env


def confined(command: list[str]) -> list[str]:
    """`command` inside a private network namespace (loopback only) with a private /dev/shm, when allowed."""
    if not netns_available():
        return command
    script = 'ip link set lo up && mount -t tmpfs -o size=4g tmpfs /dev/shm && exec "$@"'
    return ["unshare", "--net", "--mount", "--kill-child", "--fork", "sh", "-c", script, "sh", *command]


def shm_files() -> set[str]:
    """Fast DDS's files in the host's /dev/shm."""
    return {name for name in os.listdir("/dev/shm") if "fast" in name.lower()}


def remove_new_shm(before: set[str]) -> None:
    """Remove the Fast DDS files a run added to the host's /dev/shm (a killed node leaves its own). Inside a
    private namespace there are none: its /dev/shm went with it, and what is new on the host belongs to
    someone else (a test beside this one), so nothing is touched."""
    if netns_available():
        return
    for leftover in shm_files() - before:
        Path("/dev/shm", leftover).unlink(missing_ok=True)


def run_confined(command: list[str], cwd: Path, timeout: float,
                 environment: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """`command` confined to this machine with a unique ROS_DOMAIN_ID, in `cwd` (also its HOME); /dev/shm
    cleaned after. `environment` adds variables (e.g. a user's ROS settings)."""
    env = ros_environment(cwd, next_domain()) | (environment or {})
    before = shm_files()
    try:
        return subprocess.run(confined(command), env=env, capture_output=True, text=True, timeout=timeout,
                              cwd=cwd)
    finally:
        remove_new_shm(before)
