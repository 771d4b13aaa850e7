"""ROS camera_calibration's saved archive (`/tmp/calibrationdata.tar.gz`, its SAVE button) as a user brings it:
its views calibrated on, its ost.yaml measured with, a stereo pair's refused naming the cameras."""

import io
import json
import tarfile
import time

import cv2
import pytest
import yaml
from helpers import OPENCV_LEFT, OST_YAML, run_cli

from veg_area_ros.calib_io import CalibrationFileError, read_calibration
from veg_area_ros.sim.synthetic import scene_targets_content

BOARD = "chessboard:9x6:1"


def _archive(path, members: dict[str, bytes]) -> None:
    """A tar.gz as camera_calibration's do_tarfile_save writes it: each member added from memory, owner
    'calibrator'."""
    with tarfile.open(path, "w:gz") as archive:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size, info.uname, info.mtime = len(data), "calibrator", int(time.time())
            archive.addfile(info, io.BytesIO(data))


def _views(side: str = "left") -> dict[str, bytes]:
    """OpenCV's 13 real webcam photos as the calibrator keeps them: grey PNGs named left-NNNN.png."""
    photos = sorted(OPENCV_LEFT.glob("*.jpg"))
    return {f"{side}-{k:04d}.png": cv2.imencode(".png", cv2.imread(str(photo), cv2.IMREAD_GRAYSCALE))[1].tobytes()
            for k, photo in enumerate(photos)}


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    folder = tmp_path_factory.mktemp("saved")
    views = _views()
    _archive(folder / "calibrationdata.tar.gz", {**views, "ost.yaml": OST_YAML.encode(), "ost.txt": b"ignored"})
    (folder / "views").mkdir()
    for name, data in views.items():
        (folder / "views" / name).write_bytes(data)
    return folder


def test_calibrate_takes_camera_calibrations_saved_views_as_the_same_photos_in_a_folder(saved, tmp_path):
    """The views camera_calibration kept, calibrated again here (for the uncertainty, the edge trend, the
    model by evidence) without unpacking: the same fit as the same PNGs in a folder, each view named
    ARCHIVE#MEMBER."""
    fits = {}
    for source in ("calibrationdata.tar.gz", "views"):
        out = tmp_path / f"{source}.yaml"
        result = run_cli("calibrate", str(saved / source), "--board", BOARD, "-o", str(out), "--json",
                         "--medium", "air")
        assert result.returncode == 0, result.stderr
        fits[source] = json.loads(result.stdout)
    assert fits["calibrationdata.tar.gz"]["views_used"] == fits["views"]["views_used"] == 13
    for key in ("rms_px", "fx", "fy", "cx", "cy", "dist"):
        assert fits["calibrationdata.tar.gz"][key] == pytest.approx(fits["views"][key], rel=1e-6, abs=1e-9), key
    named = run_cli("calibrate", str(saved / "calibrationdata.tar.gz"), "--board", BOARD, "-o",
                    str(tmp_path / "again.yaml"), "--medium", "air")
    assert "calibrationdata.tar.gz#left-0012.png: 54 board points" in named.stderr, named.stderr


def test_its_ost_yaml_is_the_calibration_it_holds(saved, tmp_path):
    archived = read_calibration(saved / "calibrationdata.tar.gz").camera
    (tmp_path / "ost.yaml").write_text(OST_YAML)
    assert archived == read_calibration(tmp_path / "ost.yaml").camera
    assert (archived.fx, archived.xp, archived.dist[0]) == (536.07, 342.37, -0.2651)
    ini_only = tmp_path / "ros1.tar.gz"  # ROS 1's archive: ost.txt in the INI form of ost.ini
    ini = ("[image]\n\nwidth\n640\n\nheight\n480\n\n[narrow_stereo]\n\ncamera matrix\n536.07 0 342.37\n"
           "0 536.02 235.54\n0 0 1\n\ndistortion\n-0.2651 -0.0467 0.0018 -0.0003 0.2523\n")
    _archive(ini_only, {"left-0000.png": b"", "ost.txt": ini.encode()})
    assert read_calibration(ini_only).camera == archived


def test_a_stereo_pairs_archive_two_sessions_a_broken_one_or_one_given_to_measure_are_refused(saved, tmp_path):
    stereo = tmp_path / "stereo.tar.gz"
    _archive(stereo, {**_views("left"), **_views("right"), "left.yaml": OST_YAML.encode(),
                      "right.yaml": OST_YAML.encode(), "ost.txt": b"[image]\n"})
    result = run_cli("calibrate", str(stereo), "--board", BOARD, "-o", str(tmp_path / "c.yaml"))
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert "stereo pair's views (left-NNNN.png and right-NNNN.png)" in result.stderr.splitlines()[-1], result.stderr
    assert not (tmp_path / "c.yaml").exists()
    with pytest.raises(CalibrationFileError, match=r"stereo pair's calibrations \(left.yaml and right.yaml\)"):
        read_calibration(tmp_path / "stereo.tar.gz")  # its ost.txt is the pair's: not one camera's
    twice = tmp_path / "two_sessions.tar.gz"
    _archive(twice, {f"{session}/{name}": data for session in ("monday", "tuesday")
                     for name, data in list(_views().items())[:2]})
    result = run_cli("calibrate", str(twice), "--board", BOARD, "-o", str(tmp_path / "c.yaml"))
    assert result.returncode != 0 and "holds monday/left-0000.png and tuesday/left-0000.png" in result.stderr, (
        result.stderr)
    broken = tmp_path / "broken.tar.gz"
    broken.write_bytes((saved / "calibrationdata.tar.gz").read_bytes()[:5000])
    with pytest.raises(CalibrationFileError, match="not a readable tar archive"):
        read_calibration(broken)
    result = run_cli("calibrate", str(broken), "--board", BOARD, "-o", str(tmp_path / "c.yaml"))
    assert result.returncode != 0 and "not a readable tar archive" in result.stderr.splitlines()[-1], result.stderr
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    result = run_cli("measure", str(saved / "calibrationdata.tar.gz"), "--calibration",
                     str(saved / "calibrationdata.tar.gz"), "--targets", str(tmp_path / "targets.yaml"))
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert "calibrate on its views" in result.stderr, result.stderr


def test_the_camera_node_plays_its_views_into_the_calibration_node(saved):
    """The camera node's file source takes the archive as a folder of its views (to show them to the calibration
    node again), in their order, each the saved PNG's pixels."""
    from veg_area_ros.sources import FileSource

    source = FileSource([saved / "calibrationdata.tar.gz"])
    frames = []
    while (frame := source.read()) is not None:
        frames.append(frame)
    first = cv2.imread(str(saved / "views" / "left-0000.png"))
    assert len(frames) == 13 and (frames[0] == first).all()
