"""The operator's console: its rules on numpy arrays and a stand-in for the nodes (no ROS), then the page in
Debian's headless chromium against real nodes in the confined network (test/console_scenario.py)."""

from __future__ import annotations

import json
import os
import shutil
import socket
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO
from ros_harness import run_scenario

from veg_area_ros.console_server import ConsoleServer
from veg_area_ros.console_state import (
    BUSY_RATE_HZ,
    MAX_RATE_HZ,
    MAX_WIDTH_PX,
    SERIES_POINTS,
    Access,
    AreaSeries,
    ConsoleInputError,
    ImageFeed,
    LoadGovernor,
    checked_parameters,
    cpu_pressure,
    host_allowed,
    roi_from_drag,
)

SCREENSHOTS = REPO / "docs" / "images"


# --- the rules, without ROS ------------------------------------------------------------------------------------
def test_images_to_the_page_are_bounded_in_size_and_rate():
    feed = ImageFeed()
    frame = np.random.default_rng(0).integers(0, 255, (2592, 3872, 3), dtype=np.uint8)  # a 10 MP frame
    feed.offer(frame)
    jpeg, first = feed.jpeg(100.0)
    assert first == 1
    import cv2

    shown = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert shown.shape[1] == MAX_WIDTH_PX and shown.shape[0] == round(2592 * MAX_WIDTH_PX / 3872)
    assert feed.frame_size == (3872, 2592) and feed.shown_size == (shown.shape[1], shown.shape[0])
    # new frames at 100 Hz, asked for at 100 Hz for 2 s: encoded at most MAX_RATE_HZ times a second
    for k in range(1, 201):
        feed.offer(frame[:480, :640])
        feed.jpeg(100.0 + k / 100)
    assert feed.encodings <= 1 + 2 * MAX_RATE_HZ + 1
    assert feed.encodings >= 2 * MAX_RATE_HZ - 1  # and it does keep up with the bound
    # nothing new: the same JPEG again, no encoding
    same, n = feed.jpeg(200.0)
    encodings = feed.encodings
    again, m = feed.jpeg(300.0)
    assert n == 201 and again is same and m == n and feed.encodings == encodings


def test_the_cpu_pressure_is_read_from_the_kernel_or_said_unknown(tmp_path):
    psi = tmp_path / "cpu"
    psi.write_text("some avg10=46.29 avg60=34.02 avg300=40.69 total=6970331201\n"
                   "full avg10=0.00 avg60=0.00 avg300=0.00 total=0\n")
    assert cpu_pressure(str(psi)) == pytest.approx(0.4629)
    assert cpu_pressure(str(tmp_path / "absent")) is None  # a kernel without pressure stall information
    psi.write_text("some avg10=lots\n")
    assert cpu_pressure(str(psi)) is None


def test_the_console_gives_way_while_the_cores_are_busy_and_comes_back_once_they_calm():
    load, feed = LoadGovernor(), ImageFeed()
    frame = np.zeros((480, 640, 3), np.uint8)
    steps = [(0.10, False), (0.35, True), (0.25, True), (0.15, False), (0.25, False), (None, False)]
    for pressure, slowed in steps:
        assert load.update(pressure) is slowed, (pressure, slowed)
        said = load.as_dict()
        assert said["slowed"] is slowed
        assert said["images_per_s"] == (BUSY_RATE_HZ if slowed else MAX_RATE_HZ)
        assert said["poll_s"] == (1.0 if slowed else 0.5)
    load.update(0.9)
    feed.max_rate_hz = load.image_rate_hz  # as the node sets it
    for k in range(200):  # asked at 100 Hz for 2 s, a new frame each time
        feed.offer(frame)
        feed.jpeg(10.0 + k / 100)
    assert feed.encodings <= 2 * BUSY_RATE_HZ + 1 < 2 * MAX_RATE_HZ - 1


def test_lowering_the_priority_reaches_the_threads_already_running_and_those_started_after():
    """Run in a process of its own (it cannot be undone): a thread started before, the main thread and a
    thread started after all end `increment` nicer than they began, capped at 19."""
    import subprocess
    import sys

    script = """
import os, threading, time
from veg_area_ros.ros.run import lower_priority
def niceness(): return os.getpriority(os.PRIO_PROCESS, 0)
seen = {}
before_started = threading.Event(); go = threading.Event()
def before():
    before_started.set(); go.wait(); seen["before"] = niceness()
early = threading.Thread(target=before); early.start(); before_started.wait()
start = niceness()
main = lower_priority(3)
late = threading.Thread(target=lambda: seen.__setitem__("after", niceness())); late.start(); late.join()
go.set(); early.join()
print(start, main, seen["before"], seen["after"], lower_priority(40))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": str(REPO / "veg_area_ros")})
    assert done.returncode == 0, done.stderr
    start, main, before, after, capped = map(int, done.stdout.split())
    expected = min(start + 3, 19)
    assert (main, before, after) == (expected, expected, expected), done.stdout
    assert capped == 19


def test_a_view_nobody_looks_at_is_let_go():
    feed = ImageFeed()
    assert not feed.wanted(10.0)
    feed.jpeg(10.0)
    assert feed.wanted(12.0) and not feed.wanted(20.0)


def test_parameters_from_the_page_are_typed_and_checked():
    assert checked_parameters({"threshold": 60, "open_px": 2.0, "object": "dark"}) == \
        {"threshold": 60.0, "open_px": 2, "object": "dark"}
    assert isinstance(checked_parameters({"threshold": 60})["threshold"], float)
    for bad in ({"threshold": 300}, {"threshold": "x"}, {"threshold": float("nan")}, {"open_px": 1.5},
                {"open_px": True}, {"object": "purple"}, {"targets_file": "/etc/passwd"}, {},
                {"roi": [1, 2, 3, 4]}, {"roi": [1, 2, 3, 4, 5, float("inf")]}, {"roi": "0"}):
        with pytest.raises(ConsoleInputError):
            checked_parameters(bad)
    assert checked_parameters({"roi": [0]}) == {"roi": [0.0]}


def test_a_dragged_rectangle_becomes_the_roi_in_the_nodes_pixels():
    # drawn on an 800x600 JPEG of a 3200x2400 frame, backwards, partly off the image
    roi = roi_from_drag((700, 500), (100, -50), (800, 600), (3200, 2400))
    assert roi == [400.0, 0.0, 2800.0, 0.0, 2800.0, 2000.0, 400.0, 2000.0]
    with pytest.raises(ConsoleInputError, match="less than 2 pixels"):
        roi_from_drag((10, 10), (10.2, 300), (800, 600), (3200, 2400))


def test_who_may_change_what():
    loopback = Access.for_host("127.0.0.1")
    assert loopback.loopback_only and len(loopback.token) >= 20
    assert loopback.page_token("127.0.0.1:8080") == loopback.token
    assert loopback.page_token("localhost:8080") == loopback.token
    assert loopback.page_token("attacker.example:8080") == ""  # DNS rebinding: no token, and refused
    assert not host_allowed("attacker.example:8080", loopback) and host_allowed("[::1]:8080", loopback)
    assert Access.for_host("127.0.0.1").token != loopback.token  # a new token at each start
    lab = Access.for_host("0.0.0.0", "secret-token")
    assert not lab.loopback_only and lab.page_token("127.0.0.1:8080") == ""
    assert lab.may_change("secret-token") and not lab.may_change("secret") and not lab.may_change(None)
    assert host_allowed("10.0.0.5:8080", lab)


def test_the_series_starts_over_when_a_replay_restarts():
    series = AreaSeries()
    for t in (100.0, 100.1, 100.2):
        series.add_area(t, 1e-2, 1e-5)
    series.add_area(50.0, 2e-2, 1e-5)
    assert [p[0] for p in series.as_dict()["points"]] == [0.0]


def test_a_page_is_sent_only_the_points_it_does_not_have():
    series = AreaSeries()
    for t in range(5):
        series.add_area(100.0 + t, 1e-2, 1e-5)
    first = series.as_dict()
    assert first["complete"] and len(first["points"]) == 5 and first["appended"] == 5
    shown = (first["run"], first["appended"])
    assert series.as_dict(shown)["points"] == [] and not series.as_dict(shown)["complete"]
    series.add_area(105.0, 3e-2, 1e-5)
    newer = series.as_dict(shown)
    assert newer["points"] == [(5.0, 3e-2, 1e-5)] and not newer["complete"]
    for t in range(SERIES_POINTS + 3):  # the page fell behind the whole window: it is sent the window
        series.add_area(106.0 + t, 1e-2, 1e-5)
    behind = series.as_dict(shown)
    assert behind["complete"] and len(behind["points"]) == SERIES_POINTS
    series.add_area(10.0, 1e-2, 1e-5)  # a replay that restarted: a new run, sent whole
    restarted = series.as_dict((behind["run"], behind["appended"]))
    assert restarted["complete"] and restarted["run"] != behind["run"] and len(restarted["points"]) == 1


class StandIn:
    """The nodes as the server sees them: records what it was asked."""

    def __init__(self):
        self.asked: list = []

    def set_parameters(self, values):
        checked = checked_parameters(values)
        self.asked.append(("parameters", checked))
        return True, f"set: {checked}"

    def calibration(self, action):
        self.asked.append(("calibration", action))
        return False, "calibration_node is not running: nothing was done"

    def record(self, action):
        self.asked.append(("record", action))
        return True, action


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def served():
    feeds = {"area": ImageFeed()}
    feeds["area"].offer(np.zeros((480, 640), np.uint8))
    controls, access, port = StandIn(), Access.for_host("127.0.0.1"), free_port()
    server = ConsoleServer(feeds, lambda shown: controls.asked.append(("state", shown)) or {"parameters": {}},
                           controls, access, port)
    server.start()
    yield f"http://127.0.0.1:{port}", controls, access
    server.stop()


def ask(url: str, body=None, token: str | None = None, host: str | None = None) -> tuple[int, bytes]:
    headers = {"Content-Type": "application/json"} | ({"X-Console-Token": token} if token else {}) | \
        ({"Host": host} if host else {})
    data = None if body is None else (body if isinstance(body, bytes) else json.dumps(body).encode())
    try:
        with urllib.request.urlopen(urllib.request.Request(url, data=data, headers=headers), timeout=10) as answer:
            return answer.status, answer.read()
    except urllib.error.HTTPError as error:
        return error.code, error.read()


def test_a_page_says_which_points_it_has_and_a_malformed_ask_gets_them_all(served):
    base, controls, _ = served
    assert ask(base + "/api/state?run=2&appended=7")[0] == 200
    assert ask(base + "/api/state?run=2&appended=x")[0] == 200
    assert ask(base + "/api/state")[0] == 200
    assert [shown for kind, shown in controls.asked if kind == "state"] == [(2, 7), None, None]


def test_the_server_serves_the_page_with_its_files_and_refuses_what_it_must(served):
    base, controls, access = served
    status, page = ask(base + "/")
    assert status == 200 and access.token.encode() in page and b"{{TOKEN}}" not in page
    for name in ("/console.js", "/console.css"):
        assert ask(base + name)[0] == 200
    # everything the page loads is served here: no other origin in it
    assert b"http" not in page.replace(b"http-equiv", b"")
    status, jpeg = ask(base + "/api/frame/area")
    assert status == 200 and jpeg[:2] == b"\xff\xd8"
    assert ask(base + "/api/frame/area?after=1")[0] == 304  # the page has frame 1: not sent again
    assert ask(base + "/api/frame/area?after=0")[0] == 200
    assert ask(base + "/api/frame/nothing")[0] == 404
    assert ask(base + "/api/parameters", {"threshold": 50})[0] == 403  # no token
    assert ask(base + "/api/parameters", {"threshold": 50}, "wrong")[0] == 403
    assert ask(base + "/api/state", host="attacker.example")[0] == 421
    assert ask(base + "/api/parameters", b"not json", access.token)[0] == 400
    assert ask(base + "/api/parameters", {"threshold": 500}, access.token)[0] == 400
    assert ask(base + "/api/parameters", {"roi_drag": {"view": "area", "start": [0, 0], "end": [320, 240]}},
               access.token)[0] == 200
    assert controls.asked[-1] == ("parameters", {"roi": [0.0, 0.0, 320.0, 0.0, 320.0, 240.0, 0.0, 240.0]})
    status, body = ask(base + "/api/calibration/fit", {}, access.token)
    assert status == 409 and b"not running" in body
    assert ask(base + "/api/calibration/delete-everything", {}, access.token)[0] == 404
    assert ask(base + "/api/parameters", b"x" * 100_000, access.token)[0] == 413
    state = json.loads(ask(base + "/api/state", token=access.token)[1])
    assert state["access"]["may_change"] and state["views"]["area"]["frame_size"] == [640, 480]
    assert not json.loads(ask(base + "/api/state")[1])["access"]["may_change"]


def test_a_taken_port_stops_the_start_with_the_reason():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        server = ConsoleServer({}, lambda shown: {}, StandIn(), Access.for_host("127.0.0.1"), taken.getsockname()[1])
        with pytest.raises(OSError):
            server.start()


# --- the page in a real browser against real nodes ----------------------------------------------------------
needs_browser = pytest.mark.skipif(not Path("/usr/bin/chromium").exists()
                                   and not os.environ.get("VEG_AREA_REQUIRE_INSTALL"),
                                   reason="Debian's chromium is not installed (make test installs it)")


@pytest.fixture(scope="module")
def console(tmp_path_factory):
    folder = tmp_path_factory.mktemp("console")
    result = run_scenario("console", folder, timeout=900)
    result["folder"] = folder
    if os.environ.get("VEG_AREA_UPDATE_SCREENSHOTS"):  # the docs' pictures come from this run
        for name in result["screenshots"]:
            shutil.copy(folder / name, SCREENSHOTS / name)
    return result


@needs_browser
def test_the_page_shows_the_calibration_and_its_buttons_fit_discard_and_commit(console):
    assert console["access_on_loopback"] == "control"
    assert console["views_kept_before_fit"] >= 10
    assert console["feedback_frame_size"].endswith("x480")  # the frame with the guidance's bars beside it
    assert "served but not written" in console["steps"]["fit"]  # fewer views than min_views 40
    assert console["served_after_fit"] and not console["file_after_fit"]
    assert not console["file_after_discard"]
    assert console["file_after_commit"] and console["file_fx"] == pytest.approx(console["served_fx"], rel=1e-9)


@needs_browser
def test_the_console_yields_the_cpu_to_the_measurement_unless_told_not_to(console):
    """Every thread of the console's process, its server's and DDS's too, runs 10 nicer (cpu_nice's default)
    than the nodes were started at, the area node's as started; cpu_nice:=0 leaves the console as the others."""
    niceness = console["niceness"]
    started = niceness["started_at"]  # 0 in a plain shell; a suite run under `nice` starts every node nicer
    assert len(niceness["console"]) >= 3 and set(niceness["console"]) == {min(started + 10, 19)}, niceness
    assert niceness["open_console"] and set(niceness["open_console"]) == {started}, niceness
    assert niceness["area"] and set(niceness["area"]) == {started}, niceness


@needs_browser
def test_the_page_shows_the_overlay_and_af(console):
    assert console["overlay_natural_width"] == 640
    assert "cm²" in console["af_text"] and "frames measured" in console["frames_text"]


@needs_browser
def test_a_console_taking_fewer_results_has_them_thinned_in_dds_and_still_reads_every_frames_count(console):
    """The open console takes one result a second (results_per_s): once it has read the results' rate from the
    frame counter they carry, a content filter on their stamps passes one window a second, so it takes a few
    of the 10 Hz measurement's results while the area node's counts it shows stay whole. The default console
    (30 a second) takes every result of a measurement this slow, and its page says nothing of thinning."""
    t = console["thinning"]
    rate = t["whole_measured"] / t["seconds"]  # the area node's results a second meanwhile, by its own count
    assert rate > 4.0, f"the 10 Hz camera's results came at {rate:.1f} Hz: too few to judge thinning"
    assert t["whole"]["results"] is None and t["thinned_note"] == ""
    assert abs(t["whole_received"] - t["whole_measured"]) <= 3, t
    thinned = t["open"]["results"]
    assert thinned is not None and thinned["per_s"] == 1.0, t
    assert thinned["rate_hz"] == pytest.approx(rate, rel=0.5), t
    assert 3 <= t["open_received"] < 0.5 * t["open_measured"], t
    assert t["open_measured"] >= 0.6 * t["whole_measured"], t  # the counts a thinned result brings are the node's


@needs_browser
def test_a_page_nobody_sees_asks_for_nothing_and_catches_up_once_shown(console):
    """A tab in the background or a minimised window: no image and no state is fetched while the page is
    hidden (the standard visibility API says so); shown again, both loops resume and a newer image is drawn."""
    seen, hidden, shown = console["fetches_while_seen"], console["fetches_while_hidden"], console["fetches_once_shown"]
    assert any("/api/frame/" in url for url in seen) and any("/api/state" in url for url in seen), seen
    assert hidden == [], hidden
    assert any("/api/frame/" in url for url in shown) and any("/api/state" in url for url in shown), shown


@needs_browser
def test_the_page_says_when_the_console_gives_way_to_a_busy_machine(console):
    """Whether the machine was busy during the test is not ours to choose: the note must match what the page
    was told, either way, and the state must carry the figures the note quotes."""
    load, note = console["page_load"], console["load_note"]
    assert set(load) == {"cpu_pressure", "slowed", "images_per_s", "poll_s"}
    if load["slowed"]:
        assert f"slowed to {load['images_per_s']:g} a second" in note and "busy" in note
    else:
        assert note == ""


@needs_browser
@needs_browser
def test_the_page_keeps_the_series_it_was_sent_piece_by_piece(console):
    """The page is sent only the points after those it has; what it holds is the server's series up to the
    page's last poll, each point once, in order."""
    on_page, on_server = console["series_on_page"], console["series_on_server"]
    assert len(on_page) > 20 and on_page == sorted(set(on_page))
    if on_page[0] in on_server:
        start = on_server.index(on_page[0])
        assert on_page == on_server[start:start + len(on_page)]
    else:  # the server's window moved on since the page's last poll
        start = on_page.index(on_server[0])
        assert on_page[start:] == on_server[:len(on_page) - start]


def test_the_threshold_slider_sets_the_nodes_parameter_and_the_next_af(console):
    assert console["threshold_parameters"] == {"threshold": console["threshold_wanted"], "threshold_mode": "fixed"}
    assert console["af_after_threshold"] is not None  # a frame measured with the slider's threshold
    assert console["af_after_threshold"] != console["af_before_threshold"]


@needs_browser
def test_a_roi_drawn_on_the_page_becomes_the_nodes_roi(console):
    roi = console["roi_parameter"]
    assert len(roi) == 8
    xs, ys = roi[0::2], roi[1::2]
    # dragged from 30 % to 50 % of the shown width and 30 % to 70 % of its height, on a 640x480 frame
    assert min(xs) == pytest.approx(0.3 * 640, abs=3) and max(xs) == pytest.approx(0.5 * 640, abs=3)
    assert min(ys) == pytest.approx(0.3 * 480, abs=3) and max(ys) == pytest.approx(0.7 * 480, abs=3)
    assert console["af_with_roi"] < 0.8 * console["af_before_roi"]  # the cube's right part is left out
    assert any(w.startswith("object touches the ROI's border") for w in console["warnings_with_roi"])
    assert console["roi_cleared"] == [0.0]


@needs_browser
def test_recording_starts_and_stops_from_the_page(console):
    assert "MB" in console["recording_text"]
    assert "closed" in console["steps"]["record_stop"], console["recorder_log"]
    assert console["recorder_takes_results"], console["recorder_log"]  # its log said it subscribed to them
    counts = console["bag_counts"]
    assert counts.get("/image_raw", 0) > 5 and counts.get("/projected_area", 0) > 5, \
        (counts, console["results_while_recording"])


@needs_browser
def test_beyond_loopback_nothing_changes_without_the_token(console):
    assert console["viewer_access"].startswith("view only") and console["viewer_controls_disabled"]
    assert console["viewer_post"] == 403 and console["wrong_token_post"] == 403
    assert console["viewer_calibration_post"] == 403 and console["viewer_record_post"] == 403
    assert console["threshold_after_viewer"] == console["threshold_before_viewer"]
    assert console["holder_access"] == "control" and console["holder_post"] == 200
    assert console["threshold_after_holder"] == 101.0
    assert console["rebinding_status"] == 421


@needs_browser
def test_a_missing_node_is_said_and_nothing_is_sent(console):
    assert "missing" in console["missing_badge"] and console["missing_controls_disabled"]
    status, answer = console["missing_post"]
    assert status == 409 and "not running" in answer["message"]


@needs_browser
def test_the_run_stays_on_this_machine_and_leaves_screenshots(console):
    assert console["off_machine"] == []
    for name in console["screenshots"]:
        assert (console["folder"] / name).stat().st_size > 10_000
    assert len(console["screenshots"]) == 6


def test_a_frame_is_decoded_only_when_a_page_is_shown_it():
    decoded = []

    def decode():
        decoded.append(1)
        return np.zeros((480, 640, 3), np.uint8)

    feed = ImageFeed()
    for _ in range(30):  # a second of a 30 Hz camera, nobody asking
        feed.offer(decode)
    assert decoded == [] and feed.frame_size is None
    jpeg, _ = feed.jpeg(1.0)
    assert len(decoded) == 1 and feed.frame_size == (640, 480) and jpeg[:2] == b"\xff\xd8"

    def broken():
        raise ValueError("truncated message")

    feed.offer(broken)
    assert feed.jpeg(2.0)[0] is jpeg  # the last good image stays


def test_the_newest_result_is_summarised_only_when_a_page_asks():
    """The console node hands over each result's summary as a function (results come at the camera's rate):
    made once a page reads the state, and only for the newest result."""
    series, made = AreaSeries(), []
    for k in range(50):
        series.add_info(lambda k=k: made.append(k) or {"frames_measured": k, "warnings": []})
    assert made == []
    assert series.as_dict()["frames"]["measured"] == 49 and made == [49]


def test_a_result_without_a_finite_af_is_counted_not_plotted():
    series = AreaSeries()
    series.add_area(10.0, 1e-2, 1e-5)
    series.add_area(10.1, float("nan"), 0.0)
    series.add_area(10.2, 1e-2, float("inf"))
    shown = series.as_dict()
    assert shown["received"] == 3 and shown["points"] == [(0.0, 1e-2, 1e-5)]
    json.dumps(shown, allow_nan=False)  # the page's JSON takes no NaN
