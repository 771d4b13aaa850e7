"""Runs a ROS scenario (test/ros_scenarios.py) confined to this machine (veg_area_ros.ros.confine) and reaped;
the scenario checks the sockets of its namespace and reports them."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from helpers import REPO

from veg_area_ros.ros.confine import netns_available, run_confined

__all__ = ["netns_available", "run_confined", "run_scenario"]


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
    result["whole_log"] = done.stderr
    return result
