"""A user's files and measured rows survive: an output that is (by inode) or lies inside an input is refused
before any work, SIGTERM ends a run as Ctrl-C does (rows kept), and a closed stdout stops it quietly."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import pytest
import yaml
from helpers import SOURCE, children_cpu_seconds

from veg_area_ros.calib_io import write_calibration
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("kept")
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7, roll_deg=0.0)
    cv2.imwrite(str(folder / "scene.png"), frame)
    (folder / "frames").mkdir()
    for k in range(3):
        cv2.imwrite(str(folder / "frames" / f"f{k}.png"), frame)
    writer = cv2.VideoWriter(str(folder / "run.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30, ENDOSCOPE.image_size)
    for _ in range(5000):  # long enough that SIGTERM after the 30th frame surely comes in the middle
        writer.write(frame)
    writer.release()
    write_calibration(folder / "cal.yaml", ENDOSCOPE, "endoscope", {"medium": "air"})
    (folder / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    return folder


def veg_area(folder: Path, *args: str, **popen) -> subprocess.CompletedProcess | subprocess.Popen:
    command = [sys.executable, "-m", "veg_area_ros.cli", *args]
    env = dict(os.environ, PYTHONPATH=str(SOURCE))
    if popen:
        return subprocess.Popen(command, cwd=folder, env=env, text=True, **popen)
    return subprocess.run(command, cwd=folder, env=env, capture_output=True, text=True, timeout=300)


MEASURE = ("measure", "--calibration", "cal.yaml", "--targets", "targets.yaml")


@pytest.mark.parametrize("option, value, input_", [
    ("--overlay", "scene.png", "scene.png"),
    ("--csv", "run.avi", "run.avi"),
    ("--csv", "cal.yaml", "scene.png"),
    ("--csv", "targets.yaml", "scene.png"),
    ("--idealized", "frames", "frames"),
    ("--overlay", "frames/overlay.png", "frames"),
    ("--csv", "link.csv", "scene.png"),  # a symlink to the input: the same file by inode
    # the folder holding the input: each frame's overlay or idealized image is named after its input
    ("--overlay", ".", "scene.png"),
    ("--idealized", ".", "scene.png"),
    ("--overlay", "frames", "frames/f1.png"),
])
def test_an_output_over_an_input_is_refused_before_any_work(workspace, option, value, input_):
    link = workspace / "link.csv"
    if not link.is_symlink():
        link.symlink_to(workspace / "scene.png")
    before = {p: p.read_bytes() for p in workspace.rglob("*") if p.is_file() and not p.is_symlink()}
    started = children_cpu_seconds()
    done = veg_area(workspace, *MEASURE, input_, option, value)
    assert done.returncode == 2, done.stderr
    assert "would be written over; nothing was measured" in done.stderr and "Traceback" not in done.stderr
    assert children_cpu_seconds() - started < 30  # CPU seconds: refused before the work
    after = {p: p.read_bytes() for p in workspace.rglob("*") if p.is_file() and not p.is_symlink()}
    assert after == before


@pytest.mark.parametrize("options, said", [
    (("--background", "scene.png", "--csv", "scene.csv"), "--csv: its plot scene.png is the input scene.png"),
    (("--csv", "series.png"), "the series' plot is written beside it as series.png, over the CSV itself"),
])
def test_a_series_plot_is_never_written_over_an_input_or_its_own_csv(workspace, options, said):
    """The plot beside the CSV (its name with .png) replaced the background image of the empty scene (--csv
    scene.csv) or the CSV itself (--csv series.png), exit 0. Both refused before any work."""
    before = {p: p.read_bytes() for p in workspace.rglob("*") if p.is_file() and not p.is_symlink()}
    done = veg_area(workspace, *MEASURE, "frames", *options)
    assert done.returncode == 2 and said in done.stderr, done.stderr
    assert {p: p.read_bytes() for p in workspace.rglob("*") if p.is_file() and not p.is_symlink()} == before


def test_calibrate_refuses_to_write_over_its_lens_or_an_image(workspace):
    lens = workspace / "lens.yaml"
    lens.write_bytes((workspace / "cal.yaml").read_bytes())
    kept = lens.read_bytes()
    done = veg_area(workspace, "calibrate", "--port", "flat:0.02:0.006:1.49", "--lens", "lens.yaml", "-o", "lens.yaml")
    assert done.returncode == 2 and "is the input lens.yaml" in done.stderr and lens.read_bytes() == kept
    done = veg_area(workspace, "calibrate", "frames", "--board", "chessboard:9x6:0.03", "-o", "cal2.yaml",
                    "--report", "frames/report")  # its plots would be read as board photos next time
    assert done.returncode == 2 and "inside the input folder frames" in done.stderr
    assert not (workspace / "frames" / "report").exists() and not (workspace / "cal2.yaml").exists()


def test_a_calibration_beside_its_photos_is_fine_a_table_with_its_plot_is_not(workspace):
    done = veg_area(workspace, *MEASURE, "frames", "--csv", "frames/areas.csv")  # areas.png would be a frame
    assert done.returncode == 2 and "inside the input folder frames" in done.stderr
    assert not (workspace / "frames" / "areas.csv").exists()
    from veg_area_ros.cli.common import overwrites_input

    assert overwrites_input(workspace / "frames" / "cal.yaml", ["frames"]) is None  # a YAML is no frame
    assert overwrites_input(workspace / "frames" / "cal.yaml", [str(workspace / "frames")]) is None


def test_a_batch_output_folder_inside_an_input_folder_is_refused(workspace):
    done = veg_area(workspace, *MEASURE, "frames", "scene.png", "--jobs", "2", "--output-dir", "frames/results")
    assert done.returncode == 2 and "inside the input folder frames" in done.stderr
    assert not (workspace / "frames" / "results").exists()


def test_sigterm_keeps_the_rows_measured_so_far(workspace):
    process = veg_area(workspace, *MEASURE, "run.avi", "--csv", "term.csv", stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE)
    lines = 0
    while lines < 30 and process.poll() is None:  # the 30th frame's line: well into the run
        lines += process.stdout.readline().startswith("[")
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "interrupted after" in err and "Traceback" not in err
    rows = list(csv.DictReader((workspace / "term.csv").open()))
    assert 29 <= len(rows) < 5000 and all(r["area_m2"] for r in rows)  # the frame in hand is left out


def test_a_closed_stdout_stops_the_run_quietly_and_keeps_the_csv(workspace):
    done = subprocess.run(f"{sys.executable} -m veg_area_ros.cli {' '.join(MEASURE)} run.avi --json --csv pipe.csv"
                          " | head -n 1", shell=True, cwd=workspace, capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, PYTHONPATH=str(SOURCE)))
    assert done.stdout.count("\n") == 1 and '"area_m2"' in done.stdout
    assert "Traceback" not in done.stderr and "BrokenPipeError" not in done.stderr, done.stderr
    rows = list(csv.DictReader((workspace / "pipe.csv").open()))
    assert 1 <= len(rows) < 5000 and all(r["area_m2"] for r in rows)


def test_sigkill_keeps_every_row_shown_and_the_csv_stays_valid(workspace):
    """SIGKILL runs no handler: the rows must already be on disk. A frame's line is printed after its row
    reached the file, so every frame shown is in the CSV, and the last row is whole."""
    process = veg_area(workspace, *MEASURE, "run.avi", "--csv", "kill.csv", stdout=subprocess.PIPE,
                       stderr=subprocess.DEVNULL)
    shown = 0
    while shown < 30 and process.poll() is None:
        shown += process.stdout.readline().startswith("[")
    process.kill()
    process.wait(timeout=60)
    text = (workspace / "kill.csv").read_bytes().decode()
    assert text.endswith("\r\n")  # no half row
    rows = list(csv.DictReader(text.splitlines()))
    assert 30 <= len(rows) < 5000
    assert all(r["area_m2"] and r["area_mode"] == "subpixel" and None not in r for r in rows)
    assert [r["frame"] for r in rows] == [f"run.avi#{k}" for k in range(len(rows))]


def test_a_run_that_measures_nothing_keeps_an_earlier_table(workspace):
    (workspace / "earlier.csv").write_bytes(b"frame,area_m2\r\nold,1\r\n")
    (workspace / "blank.png").write_bytes(cv2.imencode(".png", 200 + 0 * cv2.imread(
        str(workspace / "scene.png")))[1].tobytes())
    done = veg_area(workspace, *MEASURE, "blank.png", "--csv", "earlier.csv")
    assert done.returncode == 1 and "is kept" in done.stderr
    assert (workspace / "earlier.csv").read_bytes() == b"frame,area_m2\r\nold,1\r\n"


def _descendants(pid: int) -> set[int]:
    children = set()
    for status in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = status.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            child = int(status.parent.name)
            children |= {child} | _descendants(child)
    return children


def test_sigterm_on_a_batch_leaves_no_worker_running(workspace):
    (workspace / "run2.avi").unlink(missing_ok=True)
    (workspace / "run2.avi").symlink_to(workspace / "run.avi")
    process = veg_area(workspace, *MEASURE, "run.avi", "run2.avi", "--jobs", "2", "--output-dir", "termbatch",
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    workers: set[int] = set()
    while time.monotonic() < deadline and process.poll() is None:
        workers = _descendants(process.pid)
        csvs = list((workspace / "termbatch").glob("*_area.csv"))
        if len(csvs) == 2 and all(len(p.read_text().splitlines()) > 5 for p in csvs):
            break
        time.sleep(0.2)
    assert process.poll() is None and workers, "the batch ended before it could be interrupted"
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    time.sleep(0.5)
    alive = {pid for pid in workers if Path(f"/proc/{pid}").exists()
             and Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"}
    assert not alive, f"workers still running after the batch's SIGTERM: {alive}"
    summary = list(csv.DictReader((workspace / "termbatch" / "batch_summary.csv").open()))
    assert [int(r["measured"]) > 5 for r in summary] == [True, True]
    for path in (workspace / "termbatch").glob("*_area.csv"):
        rows = list(csv.DictReader(path.open()))
        assert len(rows) >= 5 and all(r["area_m2"] for r in rows)


def _cut_video(workspace: Path, name: str, frames: int, keep: float) -> None:
    """An MJPG video of `frames` frames whose file is cut to `keep` of its length (a copy that stopped, a full
    card): the header still declares every frame."""
    frame = cv2.imread(str(workspace / "scene.png"))
    whole = workspace / f"whole_{name}"
    writer = cv2.VideoWriter(str(whole), cv2.VideoWriter_fourcc(*"MJPG"), 30, ENDOSCOPE.image_size)
    for _ in range(frames):
        writer.write(frame)
    writer.release()
    data = whole.read_bytes()
    (workspace / name).write_bytes(data[:int(len(data) * keep)])
    whole.unlink()


def test_a_damaged_video_says_how_many_frames_were_read_and_exits_1(workspace):
    _cut_video(workspace, "cut.avi", 40, 0.5)
    done = veg_area(workspace, *MEASURE, "cut.avi", "--csv", "cut.csv")
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr
    read = int(done.stderr.split(" of 40 frames read")[0].rsplit("(", 1)[1])
    assert 10 <= read < 40
    # the last frame read is cut inside its JPEG: refused with the decoder's words (it was measured with a grey
    # bottom before), and counted with the frames that could not be decoded
    assert f"{40 - read + 1} of 40 frames could not be read" in done.stderr and "damaged or cut short" in done.stderr
    rows = list(csv.DictReader((workspace / "cut.csv").open()))
    assert len(rows) == read + 1 and all(r["area_m2"] for r in rows[:-2])  # every whole frame read is kept
    assert "this frame is corrupt (the decoder reported: mjpeg: " in rows[-2]["error"] and not rows[-2]["area_m2"]
    assert rows[-1]["frame"] == f"cut.avi#{read}" and "could not be decoded" in rows[-1]["error"]


def test_a_whole_video_and_a_stepped_read_lose_nothing(workspace):
    _cut_video(workspace, "whole.avi", 12, 1.0)
    done = veg_area(workspace, *MEASURE, "whole.avi", "--csv", "whole.csv", "--video-step", "5")
    assert done.returncode == 0, done.stderr
    assert [r["frame"] for r in csv.DictReader((workspace / "whole.csv").open())] == [
        "whole.avi#0", "whole.avi#5", "whole.avi#10"]


def test_a_folder_with_an_unreadable_image_keeps_the_others_and_exits_1(workspace):
    folder = workspace / "some_bad"
    folder.mkdir()
    frame = (workspace / "scene.png").read_bytes()
    (folder / "a.png").write_bytes(frame)
    (folder / "b.png").write_bytes(frame[:len(frame) // 3])
    (folder / "c.png").write_bytes(frame)
    done = veg_area(workspace, *MEASURE, "some_bad", "--csv", "some_bad.csv")
    assert done.returncode == 1 and "1 of 3 frames could not be read (b.png:" in done.stderr, done.stderr
    rows = list(csv.DictReader((workspace / "some_bad.csv").open()))
    assert [bool(r["area_m2"]) for r in rows] == [True, False, True]


def test_a_batch_names_the_damaged_input_and_finishes_the_others(workspace):
    _cut_video(workspace, "cut_b.avi", 30, 0.5)
    _cut_video(workspace, "fine_b.avi", 6, 1.0)
    done = veg_area(workspace, *MEASURE, "cut_b.avi", "fine_b.avi", "--jobs", "2", "--output-dir", "damaged")
    assert done.returncode == 1 and "1 of 2 inputs lost frames" in done.stderr, done.stderr
    summary = {r["input"]: r for r in csv.DictReader((workspace / "damaged" / "batch_summary.csv").open())}
    assert "of 30 frames could not be read" in summary["cut_b.avi"]["error"]
    assert int(summary["cut_b.avi"]["measured"]) >= 5
    assert summary["fine_b.avi"]["error"] == "" and summary["fine_b.avi"]["measured"] == "6"


@pytest.mark.parametrize("args, message", [
    (("-o", "scene.png"), "-o scene.png exists already; a recording never overwrites a bag or a file"),
    (("-o", "frames"), "-o frames exists already"),
    (("-o", "scene.png/bag"), "scene.png is a file, not a folder; nothing was recorded"),
    (("/bad//name", "-o", "new_bag"), "'//' (an empty part)"),
    (("2topic", "-o", "new_bag"), "a part may not start with a digit"),
    (("image raw", "-o", "new_bag"), "' ' not allowed"),
    (("~name", "-o", "new_bag"), "'~' must be followed by '/'"),
])
def test_record_refuses_a_bad_output_or_topic_before_ros_starts(workspace, args, message):
    done = veg_area(workspace, "record", *args)
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and "transport:" not in done.stderr  # no node was started
    assert not (workspace / "new_bag").exists()


@pytest.mark.parametrize("bag, message", [
    ("no_such_bag", "no such bag"),
    ("scene.png", "not a rosbag2 bag"),
    ("frames", "not a readable rosbag2 bag"),
])
def test_play_names_what_is_wrong_with_the_bag(workspace, bag, message):
    done = veg_area(workspace, "play", bag)
    assert done.returncode == 1 and message in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_topic_names_follow_the_ros_rules():
    from veg_area_ros.bags import topic_name_problem

    for good in ("image_raw", "/camera/image_raw", "~/debug", "projected_area/info", "{node}/x", "a1/b_2"):
        assert topic_name_problem(good) is None, good
    for bad in ("", "a//b", "a/", "1a", "a/2b", "é", "a b", "a~b", "~x", "a{b"):
        assert topic_name_problem(bad), bad


def test_a_bag_with_a_damaged_chunk_says_how_many_images_were_read_and_exits_1(workspace):
    import struct

    from veg_area_ros.bags import BagRecorder
    from veg_area_ros.cdr import encode_image

    recorder = BagRecorder(workspace / "damaged_bag", "mcap")
    recorder.add_topic("/image_raw", "sensor_msgs/msg/Image")
    frame = cv2.imread(str(workspace / "scene.png"))
    for k in range(12):
        recorder.write("/image_raw", 1000 + k, encode_image(frame, k, 0, "camera"))
    recorder.close()
    mcap = next((workspace / "damaged_bag").glob("*.mcap"))
    data, offset, chunks = bytearray(mcap.read_bytes()), 8, []
    while offset + 9 <= len(data):  # the chunk records (opcode 0x06)
        opcode, (length,) = data[offset], struct.unpack_from("<Q", data, offset + 1)
        if opcode == 0x06:
            chunks.append(offset)
        offset += 9 + length
    middle = chunks[len(chunks) // 2]
    data[middle + 69:middle + 89] = b"\xff" * 20  # a record's header inside the chunk
    mcap.write_bytes(bytes(data))
    done = veg_area(workspace, *MEASURE, "damaged_bag", "--csv", "damaged_bag.csv")
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert "could not be read: the bag is damaged" in done.stderr and "of 12 frames could not be read" in done.stderr
    rows = list(csv.DictReader((workspace / "damaged_bag.csv").open()))
    measured = [r for r in rows if r["area_m2"]]
    assert 1 <= len(measured) < 12 and "bag-recover" in rows[-1]["error"]
