"""Hostile YAML in the files users give (targets, calibrations): refused at once with the reason, never
expanded, never silently half-read."""

from __future__ import annotations

import time

import pytest

from veg_area_ros.calib_io import CalibrationFileError, read_calibration, write_calibration
from veg_area_ros.sim.synthetic import ENDOSCOPE
from veg_area_ros.strict_yaml import MAX_BYTES
from veg_area_ros.targets import TargetsError, TargetsSpec

# "billion laughs": 416 bytes that plain PyYAML expands to 10^9 list items (9 GB, minutes, MemoryError)
BOMB = "".join(f"l{k}: &l{k} [" + ",".join([f"*l{k - 1}"] * 10 if k else ["x"] * 10) + "]\n" for k in range(10))


@pytest.mark.parametrize("reader, error", [(TargetsSpec.load, TargetsError), (read_calibration, CalibrationFileError)])
def test_an_alias_bomb_is_refused_at_once(tmp_path, reader, error):
    path = tmp_path / "bomb.yaml"
    path.write_text(BOMB)
    started = time.process_time()  # CPU time: a busy machine does not stretch it
    with pytest.raises(error, match=r"bomb.yaml: aliases \(\*l0\) are not allowed, at line 2"):
        reader(path)
    assert time.process_time() - started < 2


def test_a_calibration_with_a_key_twice_is_refused(tmp_path):
    """The last camera_matrix used silently measured Af 5.8 % off."""
    path = tmp_path / "calib.yaml"
    write_calibration(path, ENDOSCOPE, "endoscope", {"medium": "water"})
    text = path.read_text()
    matrix = text[text.index("camera_matrix:"):text.index("distortion_model:")]
    path.write_text(text + matrix.replace("520", "490", 1))
    with pytest.raises(CalibrationFileError, match="duplicate key 'camera_matrix' at line"):
        read_calibration(path)


@pytest.mark.parametrize("reader, error", [(TargetsSpec.load, TargetsError), (read_calibration, CalibrationFileError)])
def test_a_huge_file_is_refused_unread(tmp_path, reader, error):
    path = tmp_path / "huge.yaml"
    path.write_text("# " + "x" * (MAX_BYTES + 10) + "\n")
    with pytest.raises(error, match="larger than any such file"):
        reader(path)
