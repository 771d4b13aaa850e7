"""`veg-area doctor`: each problem made on purpose is reported with its fix (exit 1), a healthy set-up gives
none (exit 0). Processes run with a scrubbed environment (only what the test sets), confined where possible."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import REPO, SOURCE

from veg_area_ros import doctor
from veg_area_ros.ros.confine import confined, netns_available
from veg_area_ros.transport import SOCKET_BUFFER_BYTES


def fake_sysctl(folder: Path, value: int) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for key in ("rmem_max", "wmem_max"):
        (folder / key).write_text(f"{value}\n")
    return folder


def scrubbed(home: Path, **extra: str) -> dict[str, str]:
    """A newcomer's shell: PATH without any virtual environment, a fresh HOME, LANG; plus `extra`."""
    path = os.pathsep.join(p for p in os.environ["PATH"].split(os.pathsep) if not (Path(p) / "activate").exists())
    return {"PATH": path, "HOME": str(home), "LANG": "C.UTF-8", **extra}


def run_doctor(tmp_path: Path, *options: str, confine: bool = False, before: str = "", **extra: str) -> dict:
    """`veg-area doctor --json` as a process; its findings by check and its exit code."""
    command = [sys.executable, "-m", "veg_area_ros.cli", "doctor", "--json", *options]
    if confine:  # made inside a private namespace: a /dev/shm of its own that the test may fill or shrink
        command = confined(["sh", "-c", f'{before}\nexec "$@"', "sh", *command])
    # the working tree's package (the folder holding it first on the path), as the other tests run it
    done = subprocess.run(command, env=scrubbed(tmp_path / "home", **({"PYTHONPATH": str(SOURCE)} | extra)), cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode in (0, 1), done.stderr
    report = json.loads(done.stdout)
    report["code"] = done.returncode
    report["problems_by_check"] = {}
    for finding in report["findings"]:
        if not finding["ok"]:
            report["problems_by_check"].setdefault(finding["check"], []).append(finding)
    return report


def healthy(tmp_path: Path) -> list[str]:
    return ["--sysctl-dir", str(fake_sysctl(tmp_path / "sysctl", SOCKET_BUFFER_BYTES)),
            "--shm-dir", str(tmp_path / "shm")]


@pytest.fixture
def shm(tmp_path):
    (tmp_path / "shm").mkdir()
    return tmp_path / "shm"


def test_a_healthy_set_up_has_no_problems(tmp_path, shm):
    report = run_doctor(tmp_path, *healthy(tmp_path))
    assert report["code"] == 0 and report["problems"] == 0, report["problems_by_check"]
    checks = {f["check"] for f in report["findings"]}
    assert {"rclpy", "veg_area_msgs", "transport", "socket buffers", "shared memory", "ament index", "video"} <= checks
    transport = next(f for f in report["findings"] if f["check"] == "transport")
    assert "found via" in transport["message"]


def test_low_socket_buffers_are_a_problem_with_the_sysctl_fix(tmp_path, shm):
    report = run_doctor(tmp_path, "--sysctl-dir", str(fake_sysctl(tmp_path / "low", 212992)), "--shm-dir", str(shm))
    assert report["code"] == 1
    (problem,) = report["problems_by_check"]["socket buffers"]
    assert "212992" in problem["message"] and "sysctl -w net.core.rmem_max=33554432" in problem["fix"]


@pytest.mark.parametrize("variable, value, check, words", [
    ("ROS_DOMAIN_ID", "abc", "ROS_DOMAIN_ID", "not a domain"),
    ("ROS_DOMAIN_ID", "240", "ROS_DOMAIN_ID", "not a domain"),
    ("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST", "ROS_AUTOMATIC_DISCOVERY_RANGE", "other PCs"),
    ("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF", "ROS_AUTOMATIC_DISCOVERY_RANGE", "not even each other"),
    ("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNETT", "ROS_AUTOMATIC_DISCOVERY_RANGE", "none of"),
    ("ROS_LOCALHOST_ONLY", "1", "ROS_LOCALHOST_ONLY", "other PCs"),
    ("RMW_IMPLEMENTATION", "rmw_cyclonedds_cpp", "RMW_IMPLEMENTATION", "profile does not apply"),
    ("VEG_AREA_TRANSPORT", "fast", "transport", "must be one of"),
    ("VEG_AREA_TRANSPORT", "default", "transport", "mostly lost"),
    ("FASTDDS_DEFAULT_PROFILES_FILE", "/nonexistent/profile.xml", "transport", "does not exist"),
])
def test_each_setting_that_hides_nodes_is_a_problem(tmp_path, shm, variable, value, check, words):
    report = run_doctor(tmp_path, *healthy(tmp_path), **{variable: value})
    assert report["code"] == 1
    problems = report["problems_by_check"]
    # an RMW the wheels do not carry also keeps rclpy from starting: two problems, both real
    assert set(problems) == {check} | ({"rclpy"} if variable == "RMW_IMPLEMENTATION" else set()), problems
    assert words in problems[check][0]["message"] and problems[check][0]["fix"]


def test_a_valid_domain_is_a_note_not_a_problem(tmp_path, shm):
    report = run_doctor(tmp_path, *healthy(tmp_path), ROS_DOMAIN_ID="7")
    assert report["code"] == 0
    assert any(f["check"] == "ROS_DOMAIN_ID" and "same ROS_DOMAIN_ID" in f["message"] for f in report["findings"])


def test_a_broken_rclpy_is_a_problem(tmp_path, shm):
    fake = tmp_path / "broken" / "rclpy"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('librcl.so: cannot open shared object file')\n")
    report = run_doctor(tmp_path, *healthy(tmp_path), PYTHONPATH=f"{fake.parent}{os.pathsep}{SOURCE}")
    (problem,) = report["problems_by_check"]["rclpy"]
    assert "librcl.so" in problem["message"] and "make install" in problem["fix"]


def test_messages_not_built_are_a_problem(tmp_path, shm):
    fake = tmp_path / "unbuilt" / "veg_area_msgs"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("")  # the source folder without the generated msg module
    report = run_doctor(tmp_path, *healthy(tmp_path), PYTHONPATH=f"{fake.parent}{os.pathsep}{SOURCE}")
    (problem,) = report["problems_by_check"]["veg_area_msgs"]
    assert "ProjectedArea does not load" in problem["message"] and "make install" in problem["fix"], problem
    assert "rclpy" not in report["problems_by_check"]


def test_ros2_without_the_package_on_the_ament_path_is_a_problem(tmp_path, shm):
    bin_dir = tmp_path / "ros" / "bin"
    bin_dir.mkdir(parents=True)
    (bin_dir / "ros2").write_text("#!/bin/sh\n")
    (bin_dir / "ros2").chmod(0o755)
    path = f"{bin_dir}{os.pathsep}{scrubbed(tmp_path)['PATH']}"
    report = run_doctor(tmp_path, *healthy(tmp_path), PATH=path)
    (problem,) = report["problems_by_check"]["ament index"]
    assert "will not find it" in problem["message"] and "source" in problem["fix"]
    prefix = REPO / ".venv"
    if not (prefix / "share" / "ament_index" / "resource_index" / "packages" / "veg_area_ros").is_file():
        pytest.skip(f"{prefix} has no ament layout; `make test` installs it")
    report = run_doctor(tmp_path, *healthy(tmp_path), PATH=path, AMENT_PREFIX_PATH=str(prefix))
    assert report["code"] == 0 and "ament index" not in report["problems_by_check"]


def test_fast_dds_files_of_dead_processes_are_named_with_the_command_that_removes_them(tmp_path, shm):
    (shm / "fastrtps_port7411").write_bytes(b"\0" * 4096)
    (shm / "fastrtps_0f1e2d3c4b5a6978").write_bytes(b"\0" * 4096)
    (shm / "unrelated").write_text("kept")
    findings = doctor.check_shared_memory(shm, in_use=lambda: set())
    (problem,) = [f for f in findings if not f.ok]
    assert "2 Fast DDS file(s)" in problem.message and str(shm / "fastrtps_port7411") in problem.fix
    assert all(f.ok for f in doctor.check_shared_memory(shm, in_use=lambda: {"fastrtps_port7411",
                                                                            "fastrtps_0f1e2d3c4b5a6978"}))


@pytest.mark.skipif(not netns_available(), reason="needs a private mount namespace (unshare as root) to make a "
                    "small /dev/shm and leftovers without touching the host's")
def test_a_small_dev_shm_with_leftovers_is_found_in_the_confined_environment(tmp_path):
    sysctl = fake_sysctl(tmp_path / "sysctl", SOCKET_BUFFER_BYTES)
    before = ("mount -o remount,size=64m /dev/shm && head -c 1048576 /dev/zero > /dev/shm/fastrtps_port7400 "
              "&& touch /dev/shm/fastrtps_port7400_el")
    report = run_doctor(tmp_path, "--sysctl-dir", str(sysctl), confine=True, before=before)
    messages = [p["message"] for p in report["problems_by_check"]["shared memory"]]
    assert report["code"] == 1 and len(messages) == 2, messages
    assert any("64 MB" in m for m in messages) and any("2 Fast DDS file(s)" in m for m in messages)
    clean = run_doctor(tmp_path, "--sysctl-dir", str(sysctl), confine=True)
    assert clean["code"] == 0, clean["problems_by_check"]


def test_video_without_ffmpeg_is_a_problem(monkeypatch):
    import cv2

    assert all(f.ok for f in doctor.check_video_backends())
    monkeypatch.setattr(cv2.videoio_registry, "getStreamBackends", lambda: [cv2.CAP_V4L2])
    problems = [f for f in doctor.check_video_backends() if not f.ok]
    assert len(problems) == 1 and "MP4/H.264" in problems[0].message
