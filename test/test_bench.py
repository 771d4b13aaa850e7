"""The benchmarks still run and print their figures (bench/ is not otherwise exercised, so it would rot
unseen). Short settings; nothing here judges speed, only that every case produced a sane figure."""

from __future__ import annotations

import math
import re
import subprocess
import sys

import pytest
from helpers import REPO
from ros_harness import netns_available

pytestmark = pytest.mark.timeout(300)


def run_bench(script: str, *args: str, timeout: float = 240) -> str:
    done = subprocess.run([sys.executable, str(REPO / "bench" / script), *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    return done.stdout


def numbers(line: str) -> list[float]:
    return [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?", line)]


@pytest.mark.timeout(960)
def test_area_speed_prints_the_core_beside_a_copy_for_both_cameras():
    out = run_bench("area_speed.py", "--repeats", "1", "--video-frames", "30", "--video-runs", "2",
                    "--dslr-video-frames", "4", timeout=900)
    cores = [line for line in out.splitlines() if "area core" in line]
    assert len(cores) == 4, out  # count and sub-pixel mode at each size
    for line in cores:
        milliseconds, ratio = numbers(line)[:2]
        assert math.isfinite(ratio) and milliseconds > 0 and ratio > 0, line
    for line in cores[1::2]:
        assert "sub-pixel" in line and numbers(line.split("copy,")[1])[0] > 0, line  # its cost against count's
    noisy = [line for line in out.splitlines() if "DN: sub-pixel core" in line]
    assert len(noisy) == 6 and all(re.search(r"rebuilt \d+ of \d+ frames", line) for line in noisy), out
    videos = [line for line in out.splitlines() if "veg-area measure of a 30-frame" in line]
    assert len(videos) == 2 and all(numbers(video.split("(")[-1])[0] > 0 for video in videos), out
    spread = re.search(r"over 2 run\(s\): min ([\d.]+)x, median ([\d.]+)x, max ([\d.]+)x; at most 3x in (\d) of 2", out)
    ratios = sorted(numbers(video.split("(")[-1])[0] for video in videos)
    assert spread and float(spread[1]) == round(ratios[0], 2) and float(spread[3]) == round(ratios[1], 2), out
    dslr = [line for line in out.splitlines() if "veg-area measure of a 4-frame 3872x2592 video" in line]
    assert len(dslr) == 2 and re.search(r"at most 2x in \d of 2", out), out
    memory = re.findall(r"peak memory of the command as its own process: (\d+) MB \(exit 0\)", out)
    assert len(memory) == 2 and all(int(m) > 50 for m in memory), out


def test_area_speed_measures_the_video_with_a_fitted_calibrations_extras():
    out = run_bench("area_speed.py", "--skip-cores", "--video-frames", "10", "--video-runs", "1",
                    "--dslr-video-frames", "0", "--fitted-calibration", timeout=900)
    videos = [line for line in out.splitlines() if "veg-area measure of a 10-frame" in line]
    assert len(videos) == 1 and "the calibration with an edge trend and covariance" in videos[0], out
    assert numbers(videos[0].split("(")[-1])[0] > 0, out
    assert re.search(r"peak memory of the command as its own process: \d+ MB \(exit 0\)", out), out


def test_calibration_speed_ours_fits_no_worse_than_opencv():
    out = run_bench("calibration_speed.py", "--repeats", "1", "--large-views", "20",
                    "--real", str(REPO / "test" / "data" / "opencv-left"), "chessboard:9x6:0.03")
    rows = [numbers(line) for line in out.splitlines() if re.match(r"\s+\d+\s+\d", line)]
    assert [int(r[0]) for r in rows] == [15, 50], out
    for views, opencv_s, ours_s, _, opencv_rms, ours_rms in rows:
        assert opencv_s > 0 and ours_s > 0
        assert ours_rms <= opencv_rms + 1e-4, (views, opencv_rms, ours_rms)
    large = next(line for line in out.splitlines() if "rendered views" in line)
    assert "every fit converged: True" in large and numbers(large.split("(")[1])[0] > 0, large
    real = next(line for line in out.splitlines() if "real photos in opencv-left" in line)
    assert "views used 13 (the script's 13)" in real, real
    ours, on_the_same_points = (float(v) for v in re.findall(r"plumb_bob on the very points our fit kept: ours "
                                                             r"([\d.]+) px, calibrateCamera's ([\d.]+) px", real)[0])
    assert abs(ours - on_the_same_points) <= 1e-3, real  # the same least-squares problem: the same minimum
    assert f"RMS of the command's plumb_bob {ours:.4f} px" in real, real  # auto's model for it: the same fit


@pytest.mark.skipif(not netns_available(), reason="the ROS benches' fixed domains need a private network namespace")
def test_ros_pipeline_measures_ours_and_plain_rclpy():
    out = run_bench("ros_pipeline.py", "--seconds", "1", "--transports", "shm", "--sizes", "640x480",
                    "--noise", "0,4")
    rows = [line for line in out.splitlines() if line.startswith(("veg_area_ros", "plain rclpy"))]
    assert sorted(line.split()[0] for line in rows) == ["plain", "veg_area_ros", "veg_area_ros"], out
    for line in rows:
        af_per_s = numbers(line.split("640x480")[1])[2]  # after the noise and the camera rate
        assert af_per_s > 0, line
        if line.startswith("veg_area_ros"):
            assert re.search(r" \d+/\d+ ", line), line  # the weights' rebuilds over the frames taken
            assert re.search(r" \d+% +\d+% +[\d.]+ +[\d.]+ ", line), line  # CPU shares, ms per Af (all, main)
    assert re.search(r"noise 4 DN, 640x480 shm: Af/s [\d.]+x the noise-free figure of the same round", out), out


@pytest.mark.skipif(not netns_available(), reason="the ROS benches' fixed domains need a private network namespace")
def test_ros_transport_delivers_in_every_case():
    out = run_bench("ros_transport.py", "--seconds", "0.5", "--transports", "shm", "--modes", "processes")
    rows = [line.split() for line in out.splitlines() if line.startswith("shm ")]
    assert len(rows) == 8, out  # two QoS kinds x four loads
    for row in rows:
        sent, got = int(row[5]), int(row[6])
        assert 0 < got <= sent, row


def test_the_guidance_bench_runs():
    out = run_bench("guidance_speed.py", "--repeats", "1")
    assert "640x480: a frame looked at" in out and "3872x2592: a frame looked at" in out


def test_the_video_bag_bench_reads_every_frame_in_both_storages():
    out = run_bench("video_bag_speed.py", "--frames", "40", "--runs", "1")
    rows = [line.split() for line in out.splitlines() if line.split()[:1] in (["mcap"], ["sqlite3"])]
    assert [row[0] for row in rows] == ["mcap", "sqlite3"], out
    for row in rows:
        file_s, single_s, bag_s, ratio, to_single, held_mb = (float(x) for x in row[1:7])
        assert min(file_s, single_s, bag_s, ratio, to_single, held_mb) > 0, row
        for shown, over, under in ((ratio, bag_s, file_s), (to_single, bag_s, single_s)):
            # the seconds are printed to 0.01 s, each ratio (to 0.01) from the unrounded times
            assert (over - 0.005) / (under + 0.005) - 0.005 <= shown <= (over + 0.005) / (under - 0.005) + 0.005, row
