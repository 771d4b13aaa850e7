"""The installed package has the ament layout `ros2 run veg_area_ros <node>` resolves, and package.xml is
a proper format-3 ament_python manifest."""

import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from helpers import REPO

NODES = ["camera_node", "calibration_node", "area_node"]
PREFIX = Path(os.environ.get("VEG_AREA_PREFIX", REPO / ".venv"))


@pytest.fixture(scope="module")
def prefix():
    if not (PREFIX / "share" / "ament_index").exists():
        if os.environ.get("VEG_AREA_REQUIRE_INSTALL"):
            pytest.fail(f"{PREFIX} has no ament layout: the install step did not run")
        pytest.skip(f"{PREFIX} is not installed; `make test` installs it")
    return PREFIX


def test_ament_index_finds_the_package_and_its_executables(prefix):
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix))
    code = ("from ament_index_python import get_package_prefix, get_package_share_directory;"
            "print(get_package_prefix('veg_area_ros')); print(get_package_share_directory('veg_area_ros'))")
    out = subprocess.run([str(prefix / "bin" / "python"), "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=60).stdout.split()
    assert Path(out[0]).resolve() == prefix.resolve()
    assert (Path(out[1]) / "package.xml").is_file()
    for node in NODES:  # what `ros2 run veg_area_ros <node>` executes
        exe = Path(out[0]) / "lib" / "veg_area_ros" / node
        assert exe.is_file() and os.access(exe, os.X_OK), exe


def test_installed_command_line_runs(prefix):
    result = subprocess.run([str(prefix / "bin" / "veg-area"), "--version"], capture_output=True, text=True,
                            timeout=60, env=dict(os.environ, HOME=os.environ.get("HOME", "/tmp")))
    assert result.returncode == 0 and result.stdout.startswith("veg_area_ros "), result.stderr


def test_package_xml_is_an_ament_python_manifest():
    root = ET.parse(REPO / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == "veg_area_ros"
    assert root.find("export/build_type").text == "ament_python"
    depends = {e.text for e in root.findall("exec_depend")}
    assert depends >= {"rclpy", "sensor_msgs", "std_msgs", "std_srvs", "python3-opencv", "python3-numpy",
                       "python3-scipy", "python3-yaml"}
    assert (REPO / "resource" / "veg_area_ros").is_file()
    setup_cfg = (REPO / "setup.cfg").read_text()
    assert "script_dir=$base/lib/veg_area_ros" in setup_cfg and "install_scripts=$base/lib/veg_area_ros" in setup_cfg
