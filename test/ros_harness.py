"""Runs a ROS scenario (test/ros_scenarios.py) confined to this machine and reaped.

As root with `unshare` (CI): the scenario runs in a private network namespace that has only loopback and
a private /dev/shm (tmpfs), so no traffic can leave and nothing is left in the host's /dev/shm; every node
it starts lives and dies in there. Elsewhere (fallback): the nodes use the shipped Fast DDS profile
(shared memory, UDP on 127.0.0.1 only, so discovery stays on loopback), and the harness removes from
/dev/shm what the run added. Either way the scenario checks the sockets of its namespace and reports them.
"""

from __future__ import annotations

import functools
import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

from helpers import REPO

# the nodes' default profile (shared memory + UDP on every interface) where the namespace confines it; this
# machine only (shared memory + UDP on 127.0.0.1) where there is no private namespace
PROFILE = REPO / "config" / "fastdds.xml"
LOCAL_PROFILE = REPO / "config" / "fastdds_local.xml"
_domains = itertools.count((os.getpid() % 50) * 4 + 1)


@functools.cache
def netns_available() -> bool:
    try:
        probe = ["unshare", "--net", "--mount", "sh", "-c", "ip link set lo up && mount -t tmpfs tmpfs /dev/shm"]
        return subprocess.run(probe, capture_output=True, timeout=10).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def ros_environment(home: Path, domain: int) -> dict[str, str]:
    """This environment without the caller's ROS/DDS settings, plus a log home, a domain, Fast DDS with the
    shipped profile (the local one outside a private namespace), and this source tree on PYTHONPATH."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "RMW_", "VEG_AREA_"))}
    env.update(HOME=str(home), ROS_LOG_DIR=str(home / "ros_log"), PYTHONPATH=str(REPO), ROS_DOMAIN_ID=str(domain),
               RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
               FASTDDS_DEFAULT_PROFILES_FILE=str(PROFILE if netns_available() else LOCAL_PROFILE),
               PYTHONUNBUFFERED="1")
    return env


def confined(command: list[str]) -> list[str]:
    """`command` inside a private network namespace (loopback only) with a private /dev/shm, when allowed."""
    if not netns_available():
        return command
    script = 'ip link set lo up && mount -t tmpfs -o size=4g tmpfs /dev/shm && exec "$@"'
    return ["unshare", "--net", "--mount", "--kill-child", "--fork", "sh", "-c", script, "sh", *command]


def remove_new_shm(before: set[str]) -> None:
    """Fast DDS files a killed node left in the host's /dev/shm (the fallback without a private one)."""
    if netns_available():
        return
    for leftover in set(os.listdir("/dev/shm")) - before:
        if "fast" in leftover.lower():
            Path("/dev/shm", leftover).unlink(missing_ok=True)


def run_confined(command: list[str], tmp_path: Path, timeout: float,
                 environment: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """`command` confined to this machine with a unique ROS_DOMAIN_ID, in `tmp_path`; /dev/shm cleaned after.
    `environment` adds variables (e.g. a user's ROS settings)."""
    env = ros_environment(tmp_path, next(_domains) % 230) | (environment or {})
    before = set(os.listdir("/dev/shm"))
    try:
        return subprocess.run(confined(command), env=env, capture_output=True, text=True, timeout=timeout,
                              cwd=tmp_path)
    finally:
        remove_new_shm(before)


def run_scenario(name: str, tmp_path: Path, timeout: float = 240.0, environment: dict[str, str] | None = None,
                 **options) -> dict:
    """Run scenario `name` with `options` (JSON); returns its JSON result."""
    done = run_confined([sys.executable, str(REPO / "test" / "ros_scenarios.py"), name, json.dumps(options)],
                        tmp_path, timeout, environment)
    lines = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    if done.returncode != 0 or not lines:
        raise AssertionError(f"scenario {name} failed (exit {done.returncode}):\n{done.stdout[-3000:]}\n"
                             f"{done.stderr[-6000:]}")
    result = json.loads(lines[-1][len("RESULT "):])
    result["isolated"] = netns_available()
    result["log"] = done.stderr[-4000:]
    return result
