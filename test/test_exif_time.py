"""A timelapse's photos (a DSLR's intervalometer, a GoPro's timelapse) as a time series: each row's time_s is
when its photo was taken, from the EXIF that Pillow (not this package) writes as cameras do."""

from __future__ import annotations

import csv
import datetime as dt
import io
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from helpers import run_cli
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from veg_area_ros.calib_io import write_calibration
from veg_area_ros.exif import capture_time
from veg_area_ros.orientation import stored_orientation
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content

OPENCV_LEFT = Path(__file__).parent / "data" / "opencv-left"


def _exif(taken: str, fraction: str = "", zone: str = "", orientation: int = 1) -> Image.Exif:
    exif = Image.Exif()
    exif[0x0112] = orientation
    directory = exif.get_ifd(0x8769)
    for tag, text in ((0x9003, taken), (0x9291, fraction), (0x9011, zone)):
        if text:
            directory[tag] = text
    return exif


def _saved(image: np.ndarray, fmt: str, exif: Image.Exif) -> bytes:
    out = io.BytesIO()
    Image.fromarray(image).save(out, format=fmt, exif=exif.tobytes(), **({"lossless": True} if fmt == "WEBP" else {}))
    return out.getvalue()


@pytest.mark.parametrize("fmt", ["JPEG", "PNG", "WEBP", "TIFF"])
def test_the_time_taken_is_read_from_each_formats_exif_with_its_fraction_and_zone(fmt):
    image = np.zeros((32, 48, 3), np.uint8)
    data = _saved(image, fmt, _exif("2026:05:02 10:00:03", "25", "+02:00", orientation=6))
    utc = dt.datetime(2026, 5, 2, 8, 0, 3, 250000, tzinfo=dt.UTC).timestamp()
    assert capture_time(data) == (pytest.approx(utc, abs=1e-6), True)
    assert stored_orientation(data) == 6  # read from the same directory as before
    local = _saved(image, fmt, _exif("2026:05:02 10:00:03"))  # most cameras: no zone, the clock as it shows
    assert capture_time(local) == (dt.datetime(2026, 5, 2, 10, 0, 3, tzinfo=dt.UTC).timestamp(), False)
    for unset in ("0000:00:00 00:00:00", "    :  :     :  :  ", ""):  # a clock never set; no tag
        assert capture_time(_saved(image, fmt, _exif(unset))) is None, unset


def test_a_timelapses_photos_are_a_series_in_the_time_they_were_taken(tmp_path):
    """Three photos of the cube 2.5 s apart (the last with a zone): the CSV's time_s is each photo's time taken
    (it was empty, and the plot's axis counted frames), in name order as before; a photo without EXIF has none."""
    write_calibration(tmp_path / "endoscope.yaml", ENDOSCOPE, "endoscope", {"medium": "air"})
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    cube = cv2.cvtColor(render_scene(ENDOSCOPE, cube_scene(), 0.7), cv2.COLOR_BGR2RGB)
    folder = tmp_path / "timelapse"
    folder.mkdir()
    for k, (taken, fraction) in enumerate([("2026:05:02 10:00:00", "0"), ("2026:05:02 10:00:02", "5"),
                                           ("2026:05:02 10:00:05", "00")]):
        (folder / f"IMG_{k + 1:04d}.JPG").write_bytes(_saved(cube, "JPEG", _exif(taken, fraction)))
    done = run_cli("measure", str(folder), "--calibration", str(tmp_path / "endoscope.yaml"), "--targets",
                   str(tmp_path / "targets.yaml"), "--csv", str(tmp_path / "timelapse.csv"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    with open(tmp_path / "timelapse.csv", newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert [row["frame"] for row in rows] == ["IMG_0001.JPG", "IMG_0002.JPG", "IMG_0003.JPG"]
    times = np.array([float(row["time_s"]) for row in rows])
    assert times[0] == dt.datetime(2026, 5, 2, 10, 0, 0, tzinfo=dt.UTC).timestamp()
    assert np.allclose(times - times[0], [0.0, 2.5, 5.0])
    assert all(float(row["area_m2"]) > 0 for row in rows)
    assert (tmp_path / "timelapse.png").stat().st_size > 1000
    cv2.imwrite(str(folder / "IMG_0004.JPG"), cv2.cvtColor(cube, cv2.COLOR_RGB2BGR))  # OpenCV writes no EXIF
    done = run_cli("measure", str(folder / "IMG_0004.JPG"), "--calibration", str(tmp_path / "endoscope.yaml"),
                   "--targets", str(tmp_path / "targets.yaml"), "--csv", str(tmp_path / "one.csv"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    with open(tmp_path / "one.csv", newline="", encoding="utf-8") as handle:
        assert next(csv.DictReader(handle))["time_s"] == ""


def test_timed_photos_of_a_board_are_views_not_a_videos_held_pose(tmp_path):
    """A video's frames of a board held still count once (`same pose as the view before it`); photos carry a
    time now, and are still photos: the same fit as without their times, a photo repeated said as a repeat
    (calibrate tells a video's frames by their position in it, no longer by their having a time)."""
    timed = tmp_path / "timed"
    timed.mkdir()
    for k, photo in enumerate(sorted(OPENCV_LEFT.glob("*.jpg"))):
        grey = cv2.imread(str(photo), cv2.IMREAD_GRAYSCALE)
        (timed / photo.with_suffix(".png").name).write_bytes(_saved(grey, "PNG", _exif(f"2026:05:02 10:00:{k:02d}")))
        cv2.imwrite(str(tmp_path / photo.with_suffix(".png").name), grey)
    plain = tmp_path / "plain"
    plain.mkdir()
    for photo in tmp_path.glob("*.png"):
        shutil.move(photo, plain / photo.name)
    for folder in (plain, timed):  # the same shot twice in a row: a repeated photo, not a held pose
        shutil.copy(folder / "left01.png", folder / "left01a.png")
    fits = {}
    for folder in (plain, timed):
        done = run_cli("calibrate", str(folder), "--board", "chessboard:9x6:0.025", "--medium", "air", "--json",
                       "--output", str(tmp_path / f"{folder.name}.yaml"), cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        assert "1 view(s) repeat a view already counted" in done.stderr, done.stderr
        fits[folder.name] = yaml.safe_load((tmp_path / f"{folder.name}.yaml").read_text())
    for key in ("camera_matrix", "distortion_coefficients"):  # bit for bit: a calibration is repeatable
        assert fits["timed"][key]["data"] == fits["plain"][key]["data"]


@settings(max_examples=300, deadline=None, derandomize=True)
@given(prefix=st.sampled_from([b"\xff\xd8", b"\x89PNG\r\n\x1a\n", b"RIFF\x00\x00\x00\x00WEBP", b"II*\x00", b"MM\x00*"]),
       body=st.binary(max_size=200))
def test_any_bytes_give_a_time_or_none_never_an_error(prefix, body):
    taken = capture_time(prefix + body)
    assert taken is None or np.isfinite(taken[0])
