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
    /dev/shm (as root with unshare); without one, runs share the host's and go one at a time."""
    return max(1, min(os.cpu_count() or 1, 4)) if netns_available() else 1


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items) -> None:
    """With `--dist loadgroup` a module runs whole on one worker (its module fixtures are made once), unless
    it is marked with a group of its own; the modules known to be slowest are handed out first so the workers
    finish together."""
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(item.path.name))
    rank = {name: k for k, name in enumerate(SLOWEST_MODULES)}
    items.sort(key=lambda item: rank.get(_group(item), len(rank)))


def _group(item) -> str:
    mark = item.get_closest_marker("xdist_group")
    return str(mark.args[0] if mark.args else mark.kwargs.get("name", ""))


SLOWEST_MODULES: list[str] = []
