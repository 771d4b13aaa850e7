"""Shared fixtures: synthetic board views rendered once per session."""

from __future__ import annotations

import os
import signal

import pytest
from helpers import render_views

from veg_area_ros.calibration import View
from veg_area_ros.ros.confine import netns_available


@pytest.fixture(scope="session")
def air_views():
    """15 rendered chessboard views in air and their detections (seed 0)."""
    board, poses, images = render_views(seed=0)
    views = [View(f"v{i}", board.detect(image)) for i, image in enumerate(images)]
    assert all(v.detection is not None for v in views)
    return board, poses, images, views


# A shell without job control starts a background job (`make test &`) with SIGINT ignored, and an ignored signal
# is inherited across exec: every command the tests start would then ignore the Ctrl-C they are sent (the
# interrupt tests saw runs finish with exit 0). A terminal's shell does not ignore it; neither do the tests.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_xdist_auto_num_workers(config) -> int:
    """`-n auto` (make test): a worker per core, where every ROS run gets its own network namespace and
    /dev/shm (as root with unshare); without one, runs share the host's and go one at a time. Each module runs
    whole on one worker (`--dist loadfile`): its module fixtures are made once, and test_layout.py's nodes on
    the host's /dev/shm never run beside its check of the host's /dev/shm."""
    return max(1, min(os.cpu_count() or 1, 4)) if netns_available() else 1


# the modules that take longest (seconds on 2 cores, 2026-12-03), handed out first (`--no-loadscope-reorder`
# keeps this order) so the workers finish together; a module not listed comes after them
SLOWEST_MODULES = {
    "test/test_ros_graph.py": 515, "test/test_subpixel.py": 250, "test/test_bench.py": 240,
    "test/test_measure.py": 150, "test/test_flat_port.py": 140, "test/test_cluster.py": 135,
    "test/test_lens_models.py": 110, "test/test_other_bags.py": 105, "test/fuzz/test_fuzz_plausibility.py": 100,
    "test/test_plausibility.py": 100, "test/test_record_drag.py": 85, "test/test_console.py": 65,
    "test/test_golden_area.py": 62,
}


def pytest_collection_modifyitems(config, items) -> None:
    ranked = sorted(SLOWEST_MODULES, key=SLOWEST_MODULES.get, reverse=True)
    rank = {module: k for k, module in enumerate(ranked)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))
