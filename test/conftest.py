"""Shared fixtures: synthetic board views rendered once per session."""

from __future__ import annotations

import signal

import pytest
from helpers import render_views

from veg_area_ros.calibration import View


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
