"""`veg-area measure --scheduler`: a real Dask scheduler and two workers on loopback (inside the tests' private
network namespace where the machine allows one), against the same runs on this machine: identical rows, a long
video split over the workers identical to measuring it whole, a worker SIGKILLed mid-batch, an input the
workers cannot open, an unreachable scheduler and Ctrl-C. Plus the one batch behaviour whatever runs it."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import cv2
import pytest
import yaml
from helpers import REPO, SOURCE, run_cli

from veg_area_ros.calib_io import write_calibration
from veg_area_ros.ros.confine import confined
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content

MEASURE = ("measure", "--calibration", "cal.yaml", "--targets", "targets.yaml", "--threshold", "120")


def _video(path: Path, frames: int, first_seed: int) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, ENDOSCOPE.image_size)
    for k in range(frames):  # noise and a slowly changing distance: every frame's numbers differ
        writer.write(render_scene(ENDOSCOPE, cube_scene(), 0.69 + 0.004 * (k % 6), noise_sigma=3,
                                  seed=first_seed + k))
    writer.release()


@pytest.fixture(scope="module")
def scenario(tmp_path_factory) -> tuple[Path, dict]:
    folder = tmp_path_factory.mktemp("cluster")
    write_calibration(folder / "cal.yaml", ENDOSCOPE, "endoscope", {"medium": "air"})
    (folder / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    for k in range(6):
        _video(folder / f"v{k}.avi", 12, 100 * k)
    _video(folder / "long.avi", 40, 1000)
    capture = cv2.VideoCapture(str(folder / "long.avi"))
    frames = [capture.read()[1] for _ in range(40)]
    capture.release()
    writer = cv2.VideoWriter(str(folder / "longer.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10, ENDOSCOPE.image_size)
    for k in range(120):
        writer.write(frames[k % 40])
    writer.release()
    env = dict(os.environ, PYTHONPATH=str(SOURCE), HOME=str(folder), PYTHONUNBUFFERED="1",
               DASK_DISTRIBUTED__DIAGNOSTICS__NVML="False")
    done = subprocess.run(confined([sys.executable, str(REPO / "test" / "dask_scenario.py"), str(folder)]),
                          env=env, capture_output=True, text=True, timeout=1500, cwd=folder)
    assert (folder / "scenario.json").exists(), done.stderr[-3000:]
    return folder, json.loads((folder / "scenario.json").read_text())


def rows(path: Path) -> list[dict]:
    return list(csv.DictReader(path.open()))


def test_six_videos_on_the_cluster_give_the_rows_of_jobs_1(scenario):
    folder, results = scenario
    assert results["six"]["code"] == 0, results["six"]["stderr"]
    assert "2 workers" in results["six"]["stderr"]
    local = run_cli(*MEASURE, *(f"v{k}.avi" for k in range(6)), "--output-dir", "local_six", "-q", cwd=folder)
    assert local.returncode == 0, local.stderr
    for k in range(6):
        name = f"v{k}_area.csv"
        assert (folder / "cluster_six" / name).read_bytes() == (folder / "local_six" / name).read_bytes()
        assert len(rows(folder / "cluster_six" / name)) == 12
    summary = rows(folder / "cluster_six" / "batch_summary.csv")
    assert summary == rows(folder / "local_six" / "batch_summary.csv") or [
        {k: v for k, v in r.items() if k != "csv"} for r in summary] == [
        {k: v for k, v in r.items() if k != "csv"} for r in rows(folder / "local_six" / "batch_summary.csv")]


def test_a_long_video_split_over_the_workers_equals_measuring_it_whole(scenario):
    folder, results = scenario
    assert results["long"]["code"] == 0, results["long"]["stderr"]
    whole = run_cli(*MEASURE, "long.avi", "--segment-frames", "10", "--csv", "long_whole.csv", "-q", cwd=folder)
    assert whole.returncode == 0, whole.stderr
    split = folder / "cluster_long" / "long_area.csv"
    assert split.read_bytes() == (folder / "long_whole.csv").read_bytes()
    assert [r["frame"] for r in rows(split)] == [f"long.avi#{k}" for k in range(40)]


def test_segments_begin_afresh_so_carried_state_cannot_change_a_row(scenario):
    """The reason the split is identical: each segment is measured as a first frame would be. Without that,
    carried weights give rows that differ (within their bound) from a fresh start."""
    folder, _ = scenario
    run_cli(*MEASURE, "long.avi", "--segment-frames", "40", "--csv", "one_segment.csv", "-q", cwd=folder)
    run_cli(*MEASURE, "long.avi", "--segment-frames", "10", "--csv", "four_segments.csv", "-q", cwd=folder)
    one, four = rows(folder / "one_segment.csv"), rows(folder / "four_segments.csv")
    assert [r["area_m2"] for r in one[:10]] == [r["area_m2"] for r in four[:10]]  # the first segment alike
    for k in (10, 20, 30):  # a segment's first frame measured afresh: as frame 0 of a run started there
        alone = run_cli(*MEASURE, "long.avi", "--segment-frames", "10", "--csv", f"from{k}.csv", "-q", cwd=folder)
        assert alone.returncode == 0
        assert rows(folder / f"from{k}.csv")[k]["area_m2"] == four[k]["area_m2"]


def test_a_worker_killed_mid_batch_does_not_lose_an_input(scenario):
    folder, results = scenario
    killed = results["killed"]
    assert killed["worker_killed"] and killed["worker_exit"] != 0
    assert killed["code"] == 0, killed["stderr"]
    assert "Remove worker" in (folder / "scheduler.log").read_text()  # the scheduler saw it go mid-batch
    done = [line for line in killed["stderr"].splitlines() if " done: " in line]
    assert len(done) == 6 and "12 frames measured" in done[-1]  # five inputs still to come when it died
    for k in range(6):
        name = f"v{k}_area.csv"
        assert (folder / "cluster_killed" / name).read_bytes() == (folder / "cluster_six" / name).read_bytes()


def test_an_input_the_workers_cannot_open_fails_alone(scenario):
    folder, results = scenario
    missing = results["missing"]
    assert missing["code"] == 1 and "not_on_the_workers.avi" in missing["stderr"].splitlines()[-1]
    summary = {r["input"]: r for r in rows(folder / "cluster_missing" / "batch_summary.csv")}
    assert "no such file or folder" in summary["not_on_the_workers.avi"]["error"]
    assert summary["v0.avi"]["measured"] == "12" and summary["v0.avi"]["error"] == ""


def test_an_unreachable_scheduler_is_said_within_10_s_and_nothing_is_written(scenario):
    folder, results = scenario
    unreachable = results["unreachable"]
    assert unreachable["code"] == 1 and "cannot be reached" in unreachable["stderr"], unreachable["stderr"]
    # said by the immediate probe of the port, not after Dask's connection timeout (no wall-clock bound: a busy
    # machine stretches the interpreter's start, which is not the wait being judged)
    assert "Connection refused" in unreachable["stderr"] and "Traceback" not in unreachable["stderr"]
    assert not (folder / "cluster_unreachable").exists()


@pytest.mark.parametrize("name, said", [("silent", "accepted the connection but said nothing in 4 s"),
                                        ("ssh", "is not a Dask scheduler: it answered 'SSH-2.0-'")])
def test_a_listener_that_is_not_dask_is_refused_in_one_line(scenario, name, said):
    """A silent listener hung the command until it closed (60 s); an SSH port ended in a traceback."""
    folder, results = scenario
    refused = results[f"not_dask_{name}"]
    assert refused["code"] == 1 and said in refused["stderr"].splitlines()[-1], refused["stderr"]
    assert "Traceback" not in refused["stderr"] and not (folder / f"cluster_{name}").exists()


def test_a_scheduler_without_workers_is_said_and_nothing_is_submitted(scenario):
    folder, results = scenario
    alone = results["no_workers"]
    assert alone["code"] == 1 and "has no workers after 30 s" in alone["stderr"].splitlines()[-1], alone["stderr"]
    assert "dask worker tcp://" in alone["stderr"] and "Traceback" not in alone["stderr"]
    assert not (folder / "cluster_no_workers").exists()


def test_a_scheduler_lost_mid_run_keeps_what_was_received(scenario):
    """The scheduler SIGKILLed after the first input is done: that input's files stay, the long input's
    segments received so far are written in frame order and its summary says how many of the 60; one line on
    stderr for it, no traceback, and the command ends."""
    folder, results = scenario
    lost = results["scheduler_lost"]
    assert lost["code"] == 1, lost
    assert "Traceback" not in lost["stderr"] and "writing what was measured" in lost["stderr"], lost["stderr"]
    summary = {r["input"]: r for r in rows(folder / "cluster_lost" / "batch_summary.csv")}
    assert summary["v0.avi"]["measured"] == "12" and summary["v0.avi"]["error"] == ""
    kept, whole = rows(folder / "cluster_lost" / "v0_area.csv"), rows(folder / "cluster_six" / "v0_area.csv")
    # in 2-frame segments each begun afresh: the same frames, Af equal but for what carrying state changes
    assert [r["frame"] for r in kept] == [r["frame"] for r in whole]
    assert all(abs(float(a["area_m2"]) - float(b["area_m2"])) <= float(b["area_std_m2"])
               for a, b in zip(kept, whole, strict=True))
    longer = summary["longer.avi"]
    said = re.search(r"(stopped answering for 10 s|was lost): (\d+) of 60 segments measured \((\d+) frames",
                     longer["error"])
    assert said, longer
    frames = int(said.group(3))
    assert frames == int(longer["frames"]) and frames <= 2 * int(said.group(2))
    if frames:
        written = rows(folder / "cluster_lost" / "longer_area.csv")
        order = [int(r["frame"].rsplit("#", 1)[1]) for r in written]  # "longer.avi#12"
        assert len(written) == frames and order == sorted(order), order


def test_ctrl_c_cancels_the_rest_and_keeps_what_finished(scenario):
    folder, results = scenario
    interrupted = results["interrupted"]
    assert interrupted["code"] == 130, interrupted["stderr"]
    summary = {r["input"]: r for r in rows(folder / "cluster_interrupted" / "batch_summary.csv")}
    # the earlier input's tasks go first: the short one is done, the long one (60 segments) cut short
    assert "cluster: v0.avi done: 12 frames measured" in interrupted["stderr"]
    assert summary["v0.avi"]["measured"] == "12", summary
    assert summary["longer.avi"]["error"] == "interrupted before it finished"
    assert len(rows(folder / "cluster_interrupted" / "v0_area.csv")) == 12
    assert not (folder / "cluster_interrupted" / "longer_area.csv").exists()
    assert "Traceback" not in interrupted["stderr"] and "Exception ignored" not in interrupted["stderr"]


def test_one_batch_behaviour_whatever_runs_it(scenario, tmp_path):
    folder, _ = scenario
    sequential = run_cli(*MEASURE, "v0.avi", "v1.avi", "--output-dir", str(tmp_path / "one"), "-q", cwd=folder)
    parallel = run_cli(*MEASURE, "v0.avi", "v1.avi", "--jobs", "2", "--output-dir", str(tmp_path / "two"), "-q",
                       cwd=folder)
    assert sequential.returncode == parallel.returncode == 0
    for name in ("v0_area.csv", "v1_area.csv"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes()
    assert (tmp_path / "one" / "batch_summary.csv").exists()


@pytest.mark.parametrize("extra, message", [
    (("v0.avi", "--output-dir", "x"), "--output-dir is where several inputs"),
    (("v0.avi", "--jobs", "2"), "--jobs spreads several inputs"),
    (("v0.avi", "v1.avi", "--scheduler", "tcp://127.0.0.1:9", "--jobs", "2"), "with --scheduler the cluster's"),
    (("v0.avi", "v1.avi", "--csv", "one.csv"), "--csv names one file"),
])
def test_an_option_that_does_not_apply_is_refused(scenario, extra, message):
    folder, _ = scenario
    done = run_cli(*MEASURE, *extra, cwd=folder)
    assert done.returncode == 2 and message in done.stderr, done.stderr
