"""The console scenario (run by ros_scenarios.py, confined): real camera, calibration, area and console nodes,
and the page driven in Debian's headless chromium (Playwright, the system browser: nothing downloaded). Each
step is judged here against the nodes themselves (their parameters, topics and files) and reported; the
screenshots are written to the working folder."""

from __future__ import annotations

import json
import os
import signal
import time
import urllib.error
import urllib.request
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
# as root in a network namespace: no sandbox; nothing that would try the internet
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"]
CONSOLE = "http://127.0.0.1:8080"
OPEN_CONSOLE = "http://127.0.0.1:8081"  # a second console bound to 0.0.0.0, with a token
OPEN_TOKEN = "lab-token-for-the-test"
# the page has drawn an image of this view (the image is a canvas: drawn once its JPEG is decoded)
SHOWN = ("(() => { const f = document.getElementById('frame');"
         " return f.dataset.shown === '1' && f.dataset.view === '%s'; })()")

# the standard page visibility a background tab or a minimised window gives a page, set by hand: headless pages
# are always visible
SET_VISIBILITY = ("""(() => {
    const hidden = '%s' === 'hidden';
    Object.defineProperty(document, 'hidden', { configurable: true, get: () => hidden });
    const visibility = hidden ? 'hidden' : 'visible';
    Object.defineProperty(document, 'visibilityState', { configurable: true, get: () => visibility });
    document.dispatchEvent(new Event('visibilitychange'));
})()""")


def api_state(base: str = CONSOLE) -> dict:
    with urllib.request.urlopen(base + "/api/state", timeout=10) as answer:
        return json.load(answer)


def thread_niceness(pid: int) -> list[int]:
    """The niceness of each thread of a process (/proc/PID/task/*/stat, the 19th field)."""
    values = []
    for stat in Path(f"/proc/{pid}/task").glob("*/stat"):
        try:
            values.append(int(stat.read_text().rsplit(")", 1)[1].split()[16]))
        except (OSError, IndexError, ValueError):  # a thread that ended meanwhile
            continue
    return values


def post(base: str, path: str, body: dict, token: str | None = None) -> tuple[int, dict]:
    headers = {"Content-Type": "application/json"} | ({"X-Console-Token": token} if token else {})
    request = urllib.request.Request(base + path, data=json.dumps(body).encode(), headers=headers, method="POST")
    try:
        with urllib.request.urlopen(request, timeout=30) as answer:
            return answer.status, json.load(answer)
    except urllib.error.HTTPError as error:
        return error.code, json.load(error)


def scenario_console(options: dict, nodes) -> dict:
    import rclpy
    from playwright.sync_api import sync_playwright
    from rcl_interfaces.srv import GetParameters
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import CameraInfo
    from std_msgs.msg import String

    from veg_area_ros.calib_io import read_calibration
    from veg_area_ros.ros.qos import LATCHED_QOS, RESULT_QOS

    served = Path("console_served.yaml").resolve()
    bags = Path("bags").resolve()
    # the diver's board on a camera of its own (looping board views) for the calibration node; the cube on the
    # measured camera. The same synthetic camera behind the same port: the fit holds for both.
    nodes.start("camera_node", name="board_camera", remap={"image_raw": "board/image_raw",
                                                             "camera_info": "board/camera_info"},
                rate_hz=4.0, synthetic_scene="board")
    nodes.start("camera_node", rate_hz=10.0, synthetic_scene="cube")
    nodes.start("calibration_node", remap={"image_raw": "board/image_raw"}, camera_info_url=f"file://{served}",
                min_views=40, auto_calibrate=False)
    area = nodes.start("area_node")
    console = nodes.start("console_node", record_folder=str(bags))
    open_console = nodes.start("console_node", name="open_console", host="0.0.0.0", port=8081, token=OPEN_TOKEN,
                               cpu_nice=0, results_per_s=1.0)  # thins the 10 Hz results in DDS
    rclpy.init()
    probe = Node("console_probe")
    infos: list[dict] = []
    camera_infos: list[CameraInfo] = []
    probe.create_subscription(String, "projected_area/info", lambda m: infos.append(json.loads(m.data)), RESULT_QOS)
    probe.create_subscription(CameraInfo, "camera_info", camera_infos.append, LATCHED_QOS)
    get_parameters = probe.create_client(GetParameters, "/area_node/get_parameters")
    out: dict = {"steps": {}}
    shots: list[str] = []

    def spin(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(probe, timeout_sec=0.02)

    def spin_until(condition, seconds: float) -> bool:
        end = time.monotonic() + seconds
        while not condition() and time.monotonic() < end:
            rclpy.spin_once(probe, timeout_sec=0.05)
        return bool(condition())

    def node_parameters(*names: str) -> dict:
        if not get_parameters.wait_for_service(timeout_sec=10):
            return {}
        future = get_parameters.call_async(GetParameters.Request(names=list(names)))
        rclpy.spin_until_future_complete(probe, future, timeout_sec=10)
        from rcl_interfaces.msg import Parameter as ParameterMsg

        values = {}
        for name, value in zip(names, future.result().values, strict=True):
            v = Parameter.from_parameter_msg(ParameterMsg(name=name, value=value)).value
            values[name] = list(v) if hasattr(v, "tolist") or isinstance(v, tuple) else v
        return values

    def shot(page, name: str) -> None:
        page.screenshot(path=f"{name}.png")
        shots.append(f"{name}.png")

    def status(page) -> str:
        return page.inner_text("#status")

    def click_and_wait(page, selector: str, contains: str, seconds: float = 60.0, strict: bool = True) -> str:
        before = status(page)
        page.click(selector)
        page.wait_for_function("([before]) => { const s = document.getElementById('status').textContent; "
                               "return s !== before && !s.endsWith('...'); }", arg=[before],
                               timeout=seconds * 1000)
        said = status(page)
        if strict and contains not in said:
            raise AssertionError(f"{selector}: {said!r} does not say {contains!r}")
        return said

    def console_up(base: str) -> bool:
        try:
            api_state(base)
            return True
        except OSError:
            return False

    try:
        out["consoles_up"] = spin_until(lambda: console_up(CONSOLE) and console_up(OPEN_CONSOLE), 60)
        out["niceness"] = {"console": thread_niceness(console.pid), "open_console": thread_niceness(open_console.pid),
                           "area": thread_niceness(area.pid), "started_at": os.getpriority(os.PRIO_PROCESS, 0)}
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1360, "height": 960})
            page.goto(CONSOLE + "/")
            page.wait_for_function("document.body.dataset.polls > 1", timeout=30000)
            out["access_on_loopback"] = page.inner_text("#access")

            # --- calibration: the feedback image, views collected, fit / discard / fit / commit ---------------
            page.click("button[data-view=calibration]")
            page.wait_for_function(SHOWN % "calibration", timeout=60000)
            spin_until(lambda: (api_state()["calibration"]["progress"].get("views_kept") or 0) >= 10, 90)
            page.wait_for_timeout(1500)  # the page's next poll shows the views
            out["views_kept_before_fit"] = api_state()["calibration"]["progress"].get("views_kept")
            out["feedback_frame_size"] = page.get_attribute("#frame", "data-frame-size")
            shot(page, "console-calibration")
            out["steps"]["fit"] = click_and_wait(page, "#fit", "calibrated", 600)
            out["file_after_fit"] = served.exists()
            spin_until(lambda: bool(camera_infos), 20)
            out["served_after_fit"] = bool(camera_infos)
            out["steps"]["discard"] = click_and_wait(page, "#discard", "discarded")
            out["file_after_discard"] = served.exists()
            out["steps"]["fit_again"] = click_and_wait(page, "#fit", "~/commit", 600)
            out["steps"]["commit"] = click_and_wait(page, "#commit", "committed")
            out["file_after_commit"] = served.exists()
            if served.exists():
                out["file_fx"] = read_calibration(served).camera.fx
            spin(1.0)
            out["served_fx"] = camera_infos[-1].k[0] if camera_infos else None
            shot(page, "console-calibration-committed")

            # --- measurement: the overlay and Af --------------------------------------------------------------
            page.click("button[data-view=area]")
            spin_until(lambda: len([i for i in infos if i.get("calibrated")]) >= 5, 90)
            page.wait_for_function(SHOWN % "area" + " && document.getElementById('frame').dataset.frameSize === "
                                   "'640x480'", timeout=60000)
            page.wait_for_function("document.getElementById('af-now').textContent.includes('cm²')", timeout=30000)
            out["af_text"] = page.inner_text("#af-now")
            # what the page was last told about the machine's load, and the note it shows, read together
            out["page_load"], out["load_note"] = page.evaluate(
                "[state.load, document.getElementById('load-note').textContent]")
            out["frames_text"] = page.inner_text("#frames")
            # the page asks for the points it does not have: its copy is the server's window, in order
            page.wait_for_timeout(3000)
            on_page = page.evaluate("series.points.map((p) => p[0])")
            on_server = [p[0] for p in api_state()["area"]["points"]]
            out["series_on_page"], out["series_on_server"] = on_page, on_server
            out["overlay_natural_width"] = page.evaluate("document.getElementById('frame').width")
            # the open console takes one result a second (results_per_s), thinned by their stamps in DDS; this one
            # takes 30 a second, so every result of a 10 Hz measurement
            before = {"open": api_state(OPEN_CONSOLE)["area"], "whole": api_state()["area"]}
            started = time.monotonic()
            spin(8.0)
            after_open, after_whole = api_state(OPEN_CONSOLE), api_state()
            out["thinning"] = {"seconds": time.monotonic() - started, "open": after_open["thinned"],
                               "whole": after_whole["thinned"], "thinned_note": page.inner_text("#thinned")}
            for name, series in (("open", after_open["area"]), ("whole", after_whole["area"])):
                out["thinning"][f"{name}_received"] = series["received"] - before[name]["received"]
                out["thinning"][f"{name}_measured"] = (series["frames"]["measured"]
                                                       - before[name]["frames"]["measured"])
            shot(page, "console-measurement")

            # --- a page nobody sees asks for nothing, and catches up once shown -------------------------------
            page.evaluate("""() => {
                window.fetchesSeen = [];
                const plain = window.fetch.bind(window);
                window.fetch = (url, options) => { window.fetchesSeen.push(String(url)); return plain(url, options); };
            }""")
            page.wait_for_timeout(2000)
            out["fetches_while_seen"] = page.evaluate("window.fetchesSeen")
            page.evaluate(SET_VISIBILITY % "hidden")
            page.wait_for_timeout(2000)  # what was in flight when it went hidden has ended
            hidden_at = page.evaluate("Number(document.getElementById('frame').dataset.frameNumber)")
            page.evaluate("window.fetchesSeen = []")
            page.wait_for_timeout(4000)
            out["fetches_while_hidden"] = page.evaluate("window.fetchesSeen")
            page.evaluate(SET_VISIBILITY % "visible")
            page.wait_for_function(f"Number(document.getElementById('frame').dataset.frameNumber) > {hidden_at}",
                                   timeout=30000)
            out["fetches_once_shown"] = page.evaluate("window.fetchesSeen")

            # --- the threshold slider: the node's parameter, then the next Af --------------------------------
            before = infos[-1]
            out["threshold_before"] = before["threshold"]
            wanted = float(round(before["threshold"]) - 25)
            page.eval_on_selector("#threshold", "(e, v) => { e.value = v; e.dispatchEvent(new Event('input')); }",
                                  wanted)
            page.wait_for_function("document.getElementById('status').textContent.startsWith('set:')", timeout=30000)
            out["threshold_parameters"] = node_parameters("threshold", "threshold_mode")
            mark = len(infos)
            spin_until(lambda: any(i["threshold"] == wanted for i in infos[mark:]), 30)
            after = next((i for i in infos[mark:] if i["threshold"] == wanted), None)
            out["threshold_wanted"] = wanted
            out["af_before_threshold"] = before["area_m2"]
            out["af_after_threshold"] = after["area_m2"] if after else None

            # --- a ROI dragged on the image -------------------------------------------------------------------
            spin(0.5)
            out["af_before_roi"] = infos[-1]["area_m2"]  # the threshold's frames: the probe spins while it waits
            page.click("#draw-roi")  # shows the area view: its image is drawn on once it has loaded
            page.wait_for_function(SHOWN % "area", timeout=30000)
            box = page.locator("#frame").bounding_box()
            # between the targets (a ROI over a marker counts its print: said in the result), through the cube
            start = (box["x"] + 0.3 * box["width"], box["y"] + 0.3 * box["height"])
            end = (box["x"] + 0.5 * box["width"], box["y"] + 0.7 * box["height"])
            page.mouse.move(*start)
            page.mouse.down()
            page.mouse.move((start[0] + end[0]) / 2, (start[1] + end[1]) / 2)
            page.mouse.move(*end)
            page.mouse.up()
            page.wait_for_function("document.getElementById('status').textContent.startsWith('set: roi')",
                                   timeout=30000)
            out["roi_parameter"] = node_parameters("roi")["roi"]
            mark = len(infos)
            spin(2.0)
            out["af_with_roi"] = infos[-1]["area_m2"] if len(infos) > mark else None
            out["warnings_with_roi"] = infos[-1]["warnings"] if len(infos) > mark else None
            page.wait_for_timeout(1200)
            shot(page, "console-roi")
            out["steps"]["clear_roi"] = click_and_wait(page, "#clear-roi", "set: roi")
            out["roi_cleared"] = node_parameters("roi")["roi"]

            # --- recording -----------------------------------------------------------------------------------
            out["steps"]["record_start"] = click_and_wait(page, "#record-start", "recording into")
            # the recorder subscribes to each topic as its discovery finds it, seconds apart on a busy machine:
            # the results it can hold are counted from when its log says it records them
            def recorder_takes_the_results() -> bool:
                said = "".join(p.read_text(errors="replace") for p in bags.glob("*.log"))
                return "recording /projected_area (" in said and "recording /projected_area/info (" in said

            out["recorder_takes_results"] = spin_until(recorder_takes_the_results, 90)
            recording_from = len(infos)
            # a few seconds of frames (a latched camera_info reaches the recorder after discovery)
            page.wait_for_function("(t => t.startsWith('recording into') && parseFloat(t.split(': ').pop()) >= 8)"
                                   "(document.getElementById('recording').textContent)", timeout=60000)
            # and a dozen results seen while it records: a busy machine measures fewer frames in the same seconds
            spin_until(lambda: len(infos) - recording_from >= 12, 90)
            out["results_while_recording"] = len(infos) - recording_from
            out["recording_text"] = page.inner_text("#recording")
            out["steps"]["record_stop"] = click_and_wait(page, "#record-stop", "closed", 90, strict=False)
            out["recorder_log"] = "".join(p.read_text()[-3000:] for p in bags.glob("*.log"))
            out["bags"] = [str(p) for p in bags.glob("veg_area_*") if p.is_dir()]
            if out["bags"]:
                from rosbags.highlevel import AnyReader

                with AnyReader([Path(out["bags"][0])]) as reader:
                    out["bag_counts"] = {c.topic: c.msgcount for c in reader.connections}

            # --- beyond loopback: no token, no control; with it, control ---------------------------------------
            parameters_before = node_parameters("threshold")
            viewer = browser.new_page(viewport={"width": 1360, "height": 960})
            viewer.goto(OPEN_CONSOLE + "/")
            viewer.wait_for_function("document.body.dataset.polls > 1", timeout=30000)
            viewer.wait_for_function(SHOWN % "area", timeout=30000)
            out["viewer_access"] = viewer.inner_text("#access")
            out["viewer_controls_disabled"] = viewer.evaluate(
                "[...document.querySelectorAll('.control')].every((c) => c.disabled)")
            out["viewer_post"] = viewer.evaluate(
                "fetch('/api/parameters', {method: 'POST', headers: {'Content-Type': 'application/json'}, "
                "body: JSON.stringify({threshold: 7})}).then((r) => r.status)")
            out["viewer_calibration_post"] = post(OPEN_CONSOLE, "/api/calibration/fit", {})[0]
            out["viewer_record_post"] = post(OPEN_CONSOLE, "/api/record/start", {})[0]
            out["wrong_token_post"] = post(OPEN_CONSOLE, "/api/parameters", {"threshold": 7}, "guess")[0]
            out["threshold_after_viewer"] = node_parameters("threshold")["threshold"]
            out["threshold_before_viewer"] = parameters_before.get("threshold")
            shot(viewer, "console-view-only")
            holder = browser.new_page(viewport={"width": 1360, "height": 960})
            holder.goto(f"{OPEN_CONSOLE}/?token={OPEN_TOKEN}")
            holder.wait_for_function("document.body.dataset.polls > 1", timeout=30000)
            out["holder_access"] = holder.inner_text("#access")
            out["holder_post"] = holder.evaluate(
                "(token) => fetch('/api/parameters', {method: 'POST', headers: {'Content-Type': 'application/json', "
                "'X-Console-Token': token}, body: JSON.stringify({threshold: 101})}).then((r) => r.status)", OPEN_TOKEN)
            out["threshold_after_holder"] = node_parameters("threshold")["threshold"]
            # a page on loopback fetched under a foreign host name (DNS rebinding) gets no token and no state
            rebinding = urllib.request.Request(CONSOLE + "/api/state", headers={"Host": "attacker.example:8080"})
            try:
                urllib.request.urlopen(rebinding, timeout=10)
                out["rebinding_status"] = 200
            except urllib.error.HTTPError as error:
                out["rebinding_status"] = error.code

            # --- a node that is gone: the page says so and nothing is changed ----------------------------------
            area.send_signal(signal.SIGINT)
            area.wait(30)
            # the node's goodbye to the graph is one best-effort announcement: where a busy machine loses it, the
            # others drop the node only when its DDS lease (20 s) runs out, and the page learns it at its next poll
            page.wait_for_function("document.getElementById('node-area').textContent.includes('missing')",
                                   timeout=90000)
            out["missing_badge"] = page.inner_text("#node-area")
            out["missing_controls_disabled"] = page.evaluate("document.getElementById('threshold').disabled")
            token = page.evaluate("window.CONSOLE_TOKEN")
            out["missing_post"] = post(CONSOLE, "/api/parameters", {"threshold": 90}, token)
            page.click("button[data-view=calibration]")
            page.wait_for_timeout(1500)
            shot(page, "console-node-missing")
            browser.close()
    finally:
        out["screenshots"] = shots
        out["info_count"] = len(infos)
        probe.destroy_node()
        rclpy.try_shutdown()
    return out
