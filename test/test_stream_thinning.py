"""The console's thinning of a fast stream by its stamps (stream_thinning): about the wanted number a second at
any rate and phase, never an empty window for a steady stream, the rate still known from the thinned messages,
and no filter where it would pass half the stream. (The DDS side: test_console's open console thins a 10 Hz
measurement to one result a second.)"""

from __future__ import annotations

import numpy as np
import pytest

from veg_area_ros.stream_thinning import (
    NS_PER_S,
    StreamRate,
    Thinning,
    passes,
    stamp_windows,
    window_bounds,
)


def stamps(rate_hz: float, seconds: float, phase_s: float, jitter_s: float = 0.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    times = 1_700_000_000 + phase_s + np.arange(int(rate_hz * seconds)) / rate_hz
    return np.round((times + rng.normal(0.0, jitter_s, times.size)) * NS_PER_S).astype(np.int64)


@pytest.mark.parametrize("rate_hz", [65.0, 90.0, 120.0, 200.0, 300.0, 400.0, 1000.0])
@pytest.mark.parametrize("phase_s", [0.0, 0.0004, 0.0123, 0.049, 0.5])
def test_about_the_wanted_number_pass_at_any_rate_and_phase_and_no_window_is_empty(rate_hz, phase_s):
    """Cameras at exact rates (their stamps at fixed phases of each second) and with jitter: every window of
    every second holds a message, and 30 wanted a second give 20 to 40 (twenty windows a second, each 1.5 periods
    wide: one or two frames, which at an exact rate depends on its phase)."""
    expression, parameters = stamp_windows(rate_hz, 30.0)
    count = expression.count(" OR ") + 1
    assert len(parameters) == 2 * count
    for jitter in (0.0, 0.1 / rate_hz):
        times = stamps(rate_hz, 10.0, phase_s, jitter)
        kept = np.array([passes(int(t), parameters) for t in times])
        per_s = kept.sum() / 10.0
        assert 20.0 <= per_s <= 40.0, (rate_hz, phase_s, per_s)
        width = int(parameters[1]) - int(parameters[0])
        for second in np.unique(times[kept] // NS_PER_S)[1:-1]:  # whole seconds
            inside = (times // NS_PER_S == second)
            for start, end in window_bounds(width, count):
                nanosec = times[inside] % NS_PER_S
                assert np.any((nanosec >= start) & (nanosec < end)), (rate_hz, phase_s, second, start)


@pytest.mark.parametrize("rate_hz", [None, 0.0, float("nan"), 1.0, 10.0, 30.0, 59.0])
def test_a_slow_stream_or_an_unknown_rate_is_taken_whole(rate_hz):
    """At 30 wanted a second, windows 1.5 periods wide twenty times a second would pass half or more of a stream
    slower than 60 Hz: no filter (the console takes every result, as it did)."""
    assert stamp_windows(rate_hz, 30.0) is None


def test_few_wanted_thin_a_slow_stream_too():
    """2 a second of a 10 Hz camera: two windows of 150 ms a second."""
    _, parameters = stamp_windows(10.0, 2.0)
    assert parameters == ["0", "150000000", "500000000", "650000000"]
    kept = [passes(int(t), parameters) for t in stamps(10.0, 10.0, 0.03)]
    assert 2.0 <= sum(kept) / 10.0 <= 4.0


def test_the_rate_is_read_from_the_counter_the_thinned_messages_carry():
    rate = StreamRate()
    _, parameters = stamp_windows(300.0, 30.0)
    times = stamps(300.0, 6.0, 0.2, 0.0002)
    for measured, t in enumerate(times):
        if passes(int(t), parameters):
            rate.add(t / NS_PER_S, measured)
    assert rate.rate_hz == pytest.approx(300.0, rel=0.02)
    # a node that restarted counts from 0 again: measured afresh, the old rate kept meanwhile
    assert rate.add(times[-1] / NS_PER_S + 0.1, 3) == pytest.approx(300.0, rel=0.02)
    assert rate.add(times[-1] / NS_PER_S + 2.1, 3 + 200) == pytest.approx(100.0, rel=0.01)
    assert StreamRate().add(0.0, 5) is None  # an unstamped stream tells no rate


def test_the_filter_moves_only_when_the_rate_changed_enough():
    thinning = Thinning(30.0)
    assert thinning.change(None) is False  # nothing applied, nothing to change
    first = thinning.change(300.0)
    assert first and thinning.filtered and thinning.applied_rate_hz == 300.0
    assert thinning.change(330.0) is False  # within REFILTER_CHANGE
    assert thinning.change(200.0) and thinning.applied_rate_hz == 200.0
    assert thinning.change(20.0) is None and not thinning.filtered  # slow: taken whole again
    assert thinning.change(25.0) is False
