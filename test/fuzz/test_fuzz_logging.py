"""Throttled node warnings account for every refusal: what the throttle hid is counted in a later line."""

from __future__ import annotations

from veg_area_ros.ros.health import CountedWarnings


class FakeLogger:
    def __init__(self):
        self.lines: list[tuple[str, str]] = []

    def warning(self, text: str) -> None:
        self.lines.append(("warning", text))

    def error(self, text: str) -> None:
        self.lines.append(("error", text))


def test_every_refusal_is_a_line_or_counted_in_a_later_one():
    logger, now = FakeLogger(), [0.0]
    warn = CountedWarnings(logger, period_s=5.0, clock=lambda: now[0])
    for k in range(22):  # 22 bad frames, 0.5 s apart: 11 s
        now[0] = 0.5 * k
        warn("frame refused", "encoding 16UC1 is not supported")
    now[0] = 20.0
    warn("frame refused", "encoding 16UC1 is not supported")
    texts = [text for _, text in logger.lines]
    detail = "frame refused: encoding 16UC1 is not supported"
    assert texts == [f"{detail} (1 so far)",
                     f"{detail} (11 so far, 9 like it not shown since its last line)",
                     f"{detail} (21 so far, 9 like it not shown since its last line)",
                     f"{detail} (23 so far, 1 like it not shown since its last line)"]
    assert warn.total("frame refused") == 23


def test_a_new_problem_is_shown_at_once_and_levels_are_kept():
    logger = FakeLogger()
    warn = CountedWarnings(logger, period_s=5.0, clock=lambda: 1.0)
    warn("frame refused", "320x240 differs from 640x480")
    warn("frame refused", "empty data")
    warn("frame not measured", "only 1 target(s) found", "error")
    assert logger.lines == [("warning", "frame refused: 320x240 differs from 640x480 (1 so far)"),
                            ("warning", "frame refused: empty data (2 so far)"),
                            ("error", "frame not measured: only 1 target(s) found (1 so far)")]
