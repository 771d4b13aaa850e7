import dataclasses
import os
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers import OST_YAML

from veg_area_ros import calib_io
from veg_area_ros.calib_io import CalibrationFileError, read_calibration, write_calibration
from veg_area_ros.sim.synthetic import ENDOSCOPE

STANDARD_KEYS = ["image_width", "image_height", "camera_name", "camera_matrix", "distortion_model",
                 "distortion_coefficients", "rectification_matrix", "projection_matrix"]


def test_round_trip_is_exact_and_in_ros_layout(tmp_path):
    path = tmp_path / "calib.yaml"
    write_calibration(path, ENDOSCOPE, "endoscope", {"medium": "water", "rms_px": np.float64(0.05),
                                                     "std": {"fx": np.float32(0.2)}})
    content = yaml.safe_load(path.read_text())
    assert list(content)[: len(STANDARD_KEYS)] == STANDARD_KEYS
    assert content["camera_matrix"]["rows"] == 3 and len(content["camera_matrix"]["data"]) == 9
    assert content["distortion_model"] == "plumb_bob" and len(content["distortion_coefficients"]["data"]) == 5
    P = np.array(content["projection_matrix"]["data"]).reshape(3, 4)
    assert P[0, 2] == 319.5 and P[1, 2] == 239.5 and P[0, 0] == P[1, 1] == ENDOSCOPE.c  # the idealized camera
    loaded = read_calibration(path)
    assert loaded.camera == ENDOSCOPE
    assert loaded.camera_name == "endoscope"
    assert loaded.metadata["medium"] == "water" and loaded.metadata["rms_px"] == 0.05
    assert calib_io.quality_rms(loaded) == 0.05


def test_reads_a_file_as_camera_calibration_writes_it(tmp_path):
    # the layout ROS's camera_calibration writes (ost.yaml), from a real 640x480 camera (helpers.OST_YAML)
    text = OST_YAML
    path = tmp_path / "ost.yaml"
    path.write_text(text)
    camera = read_calibration(path).camera
    assert (camera.fx, camera.fy, camera.xp, camera.yp) == pytest.approx((536.07, 536.02, 342.37, 235.54))
    assert camera.k3 == 0.2523


@pytest.mark.parametrize("text,problem", [
    ("image_width: [640\n", "not valid YAML at line"),
    ("just a string\n", "expected a YAML mapping"),
    ("image_width: 640\nimage_height: 480\n", "'camera_matrix' is missing"),
    ("image_width: -5\nimage_height: 480\n", "'image_width' must be a positive integer"),
])
def test_corrupt_files_name_the_file_and_the_problem(tmp_path, text, problem):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(CalibrationFileError) as info:
        read_calibration(path)
    assert str(path) in str(info.value) and problem in str(info.value)


def _valid(tmp_path) -> dict:
    write_calibration(tmp_path / "ok.yaml", ENDOSCOPE)
    return yaml.safe_load((tmp_path / "ok.yaml").read_text())


@pytest.mark.parametrize("edit,problem", [
    (lambda c: c["camera_matrix"].update(data=[1.0] * 8), "should hold 9 numbers"),
    (lambda c: c["camera_matrix"]["data"].__setitem__(0, float("nan")), "NaN"),
    (lambda c: c["distortion_coefficients"].update(data=["a", "b"]), "not a list of numbers"),
    (lambda c: c.update(distortion_model="double_sphere"), "'double_sphere' is not supported"),
    (lambda c: c.update(distortion_model="equidistant"), "do not fit equidistant's four"),
    (lambda c: c["camera_matrix"]["data"].__setitem__(0, -100.0), "positive"),
])
def test_invalid_values_are_refused(tmp_path, edit, problem):
    content = _valid(tmp_path)
    edit(content)
    path = tmp_path / "edited.yaml"
    path.write_text(yaml.safe_dump(content))
    with pytest.raises(CalibrationFileError, match=problem):
        read_calibration(path)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(CalibrationFileError, match="no such calibration file"):
        read_calibration(tmp_path / "nope.yaml")


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "calib.yaml"
    write_calibration(path, ENDOSCOPE)
    before = path.read_bytes()

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        write_calibration(path, ENDOSCOPE.ideal())
    assert path.read_bytes() == before
    assert sorted(p.name for p in Path(tmp_path).iterdir()) == ["calib.yaml"]


@pytest.mark.parametrize("url, expected", [
    ("", None),
    ("file:///data/calib.yaml", "/data/calib.yaml"),
    ("/data/calib.yaml", "/data/calib.yaml"),
])
def test_camera_info_urls_as_camera_info_manager_reads_them(url, expected):
    from veg_area_ros.calib_io import camera_info_url_to_path

    path = camera_info_url_to_path(url)
    assert (None if path is None else str(path)) == expected


@pytest.mark.parametrize("url, reason", [
    ("file://sub/calib.yaml", "needs an absolute path"),  # was taken as /calib.yaml
    ("file://calib_here.yaml", "needs an absolute path"),  # was taken as the current folder
    ("file:/abs/x.yaml", "only file:///absolute/path"),  # made a relative 'file:' folder tree
    ("http://example.org/c.yaml", "only file:///absolute/path"),
    ("calib.yaml", "give an absolute path"),
    ("package://no_such_package_here/c.yaml", "not found"),
])
def test_camera_info_urls_that_cannot_be_meant_are_refused(url, reason):
    from veg_area_ros.calib_io import camera_info_url_to_path

    with pytest.raises(ValueError, match=reason):
        camera_info_url_to_path(url)


def test_camera_info_managers_url_variables_are_put_in_as_it_puts_them(monkeypatch, tmp_path):
    """usb_cam's and camera_info_manager's default URL, file://${ROS_HOME}/camera_info/${NAME}.yaml, was refused
    ("needs an absolute path"): ${ROS_HOME} is $ROS_HOME or ~/.ros and ${NAME} the camera's name."""
    from veg_area_ros.calib_io import camera_info_url_to_path

    url = "file://${ROS_HOME}/camera_info/${NAME}.yaml"
    monkeypatch.setenv("ROS_HOME", str(tmp_path / "ros"))
    assert camera_info_url_to_path(url, "endoscope") == tmp_path / "ros" / "camera_info" / "endoscope.yaml"
    monkeypatch.delenv("ROS_HOME")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert camera_info_url_to_path(url) == tmp_path / ".ros" / "camera_info" / "camera.yaml"
    with pytest.raises(ValueError, match=r"\$\{CAMERA\} is not put in by camera_info_manager"):
        camera_info_url_to_path("file://${ROS_HOME}/${CAMERA}.yaml")


def test_a_package_url_points_into_the_installed_share_folder(monkeypatch):
    from helpers import REPO

    from veg_area_ros.calib_io import camera_info_url_to_path

    monkeypatch.setenv("AMENT_PREFIX_PATH", str(REPO / ".venv"))
    assert camera_info_url_to_path("package://veg_area_ros/config/x.yaml") == (
        REPO / ".venv" / "share" / "veg_area_ros" / "config" / "x.yaml")


def _filestorage(path: Path) -> dict:
    """What OpenCV's FileStorage reads of a YAML file: its top-level keys and the metadata block's."""
    import cv2

    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        metadata = storage.getNode(calib_io.METADATA_KEY)
        return {"keys": list(storage.root().keys()), "metadata_keys": list(metadata.keys()),
                "matrix": storage.getNode("camera_matrix").getNode("data"), "storage": storage}
    except cv2.error as exc:
        pytest.fail(f"FileStorage cannot read {path.name}: {exc}")


def test_opencvs_filestorage_reads_every_calibration_file_the_package_writes(tmp_path):
    """`veg-area calibrate` on real photos writes the fit's whole metadata (board spec, warnings, per-view
    residuals, dates): FileStorage (as OpenCV's tools, and yaml-cpp as ROS's parsers, read YAML) reads every key
    and the same values PyYAML reads. Unquoted, `board: chessboard:9x6:1` stopped it ("Incorrect indentation")."""
    from helpers import OPENCV_LEFT, run_cli

    path = tmp_path / "left.yaml"
    done = run_cli("calibrate", str(OPENCV_LEFT), "--board", "chessboard:9x6:1", "--medium", "air", "-o", str(path))
    assert done.returncode == 0, done.stderr
    content = yaml.safe_load(path.read_text())
    read = _filestorage(path)
    assert read["keys"] == list(content)
    assert read["metadata_keys"] == list(content[calib_io.METADATA_KEY])
    metadata = read["storage"].getNode(calib_io.METADATA_KEY)
    assert metadata.getNode("board").string() == content[calib_io.METADATA_KEY]["board"] == "chessboard:9x6:1"
    matrix = [read["matrix"].at(k).real() for k in range(9)]
    assert matrix == content["camera_matrix"]["data"]


@pytest.mark.parametrize("text", ["a: b", "x:y", "- a", "null", "true", "No", "0.5", "", "a 'quote' \"and\" more",
                                  "°, ü and ∑", "#hash", "line\nbreak", "  spaces  "])
def test_every_string_is_written_so_every_reader_reads_it_back(tmp_path, text):
    import cv2

    path = tmp_path / "calib.yaml"
    write_calibration(path, ENDOSCOPE, "endoscope", {"note": text, "list": [text, 1.5, None], "n": {"x": text}})
    assert read_calibration(path).metadata == {"note": text, "list": [text, 1.5, None], "n": {"x": text}}
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    note = storage.getNode(calib_io.METADATA_KEY).getNode("note")
    if text.strip() and "\n" not in text:  # FileStorage's own reading of empty and multi-line strings differs
        assert note.string() == text


OST_INI = """# oST version 5.0 parameters


[image]

width
640

height
480

[narrow_stereo]

camera matrix
520.000000 0.000000 326.000000
0.000000 522.080000 236.500000
0.000000 0.000000 1.000000

distortion
-0.320000 0.120000 0.001200 -0.000800 -0.020000

rectification
1.000000 0.000000 0.000000
0.000000 1.000000 0.000000
0.000000 0.000000 1.000000

projection
520.000000 0.000000 319.500000 0.000000
0.000000 520.000000 239.500000 0.000000
0.000000 0.000000 1.000000 0.000000
"""


@pytest.mark.parametrize("name", ["ost.ini", "endoscope.txt"])
def test_ros1_cameracalibrators_ost_ini_is_read(tmp_path, name):
    """The INI that ROS 1's cameracalibrator writes beside ost.yaml (any file name: its [image] section says it)."""
    path = tmp_path / name
    path.write_text(OST_INI)
    calibration = read_calibration(path)
    assert calibration.camera_name == "narrow_stereo"
    camera = calibration.camera
    assert (camera.width, camera.height, camera.fx, camera.fy, camera.xp, camera.yp) == (640, 480, 520.0, 522.08,
                                                                                         326.0, 236.5)
    assert (camera.k1, camera.k2, camera.p1, camera.p2, camera.k3) == (-0.32, 0.12, 0.0012, -0.0008, -0.02)


def test_a_stereo_pairs_ost_ini_is_refused_naming_both_cameras(tmp_path):
    left = OST_INI.replace("[narrow_stereo]", "[narrow_stereo/left]")
    right = OST_INI.replace("[narrow_stereo]", "[narrow_stereo/right]").replace("# oST version 5.0 parameters", "")
    path = tmp_path / "ost.ini"
    path.write_text(left + right)
    with pytest.raises(CalibrationFileError, match=r"2 camera sections \(narrow_stereo/left, narrow_stereo/right\)"):
        read_calibration(path)


@pytest.mark.parametrize("edit, problem", [
    (lambda t: t.replace("width\n640", "width\n640.5"), "one whole 'width'"),
    (lambda t: t.replace("[image]", "[imagery]"), r"2 camera sections \(imagery, narrow_stereo\)"),
    (lambda t: "camera matrix\n1 2 3\n" + t, "before any"),
    (lambda t: t.replace("-0.320000 0.120000", "-0.32 0.12 0.1 0.2 0.3 0.4"), "distortion coefficients"),
    (lambda t: t.replace("520.000000 0.000000 326.000000\n", ""), "'camera_matrix' should hold 9 numbers, found 6"),
])
def test_a_broken_ost_ini_is_refused_with_its_reason(tmp_path, edit, problem):
    path = tmp_path / "ost.ini"
    path.write_text(edit(OST_INI))
    with pytest.raises(CalibrationFileError, match=problem):
        read_calibration(path)


# as OpenCV 4's calibration sample writes it (cv::FileStorage, '%YAML:1.0', which a YAML parser refuses)
OPENCV_SAMPLE = """%YAML:1.0
---
calibration_time: "Sat 05 Dec 2026 07:58:00 UTC"
nr_of_frames: 13
image_width: 640
image_height: 480
board_width: 9
board_height: 6
square_size: 2.5e-02
fix_aspect_ratio: 1.
flags: 2
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 520., 0., 326., 0., 522.08, 236.5, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -0.32, 0.12, 1.2e-03, -8.0e-04, -0.02 ]
avg_reprojection_error: 0.41
"""
# OpenCV's interactive calibrator (opencv_interactive-calibration) names them otherwise
OPENCV_INTERACTIVE = ("%YAML:1.0\n---\ncalibrationDate: \"Sat Dec  5 07:58:00 2026\"\nframesCount: 20\n"
                      "cameraResolution: [ 640, 480 ]\n" + OPENCV_SAMPLE[OPENCV_SAMPLE.index("camera_matrix:"):]
                      .replace("camera_matrix:", "cameraMatrix:").replace("distortion_coefficients:", "dist_coeffs:")
                      .replace("rows: 5\n   cols: 1", "rows: 1\n   cols: 5"))


def test_opencvs_own_calibration_files_are_read(tmp_path):
    """OpenCV's calibration sample and interactive calibrator, and a script's cv2.FileStorage (YAML or XML), save
    K and the distortion as '!!opencv-matrix': "not valid YAML at line 6" or "not a camera_info calibration"
    before; read as the same camera the camera_info file holds. A file whose model cannot be told or whose size
    is missing is refused with what to add."""
    import cv2

    files = {"sample.yml": OPENCV_SAMPLE, "interactive.yaml": OPENCV_INTERACTIVE}
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    K = np.array([[520.0, 0, 326.0], [0, 522.08, 236.5], [0, 0, 1]])
    for name in ("script.yml", "script.xml"):
        storage = cv2.FileStorage(str(tmp_path / name), cv2.FILE_STORAGE_WRITE)
        storage.write("image_width", 640)
        storage.write("image_height", 480)
        storage.write("camera_matrix", K)
        storage.write("distortion_coefficients", np.array([[-0.32, 0.12, 0.0012, -0.0008, -0.02]]))
        storage.release()
        files[name] = ""
    for name in files:
        camera = read_calibration(tmp_path / name).camera
        assert (camera.width, camera.height, camera.fx, camera.fy, camera.xp, camera.yp) == \
            (640, 480, 520.0, 522.08, 326.0, 236.5), name
        assert (camera.k1, camera.k2, camera.p1, camera.p2, camera.k3) == (-0.32, 0.12, 0.0012, -0.0008, -0.02), name
        assert camera.model == "plumb_bob" and camera == read_calibration(tmp_path / "sample.yml").camera
    eight = OPENCV_SAMPLE.replace("rows: 5", "rows: 8").replace("-0.02 ]", "-0.02, 0.01, 0.002, 0.001 ]")
    (tmp_path / "rational.yml").write_text(eight)
    assert read_calibration(tmp_path / "rational.yml").camera.model == "rational_polynomial"
    for edit, problem in [
        (lambda t: t.replace("rows: 5", "rows: 4").replace(", -0.02 ]", " ]"), "k1 k2 p1 p2 or cv2.fisheye's"),
        (lambda t: t.replace("image_width: 640\n", ""), "without the image size: add image_width"),
        (lambda t: t.replace("camera_matrix:", "intrinsics:"), "without 'camera_matrix'"),
        (lambda t: t.replace("rows: 5", "rows: 14").replace("-0.02 ]", "-0.02" + ", 0." * 9 + " ]"),
         "14 distortion coefficients"),
        (lambda t: t.replace("   rows: 3\n   cols: 3", "   rows: 3\n   cols: [3"), "not a readable OpenCV"),
        (lambda t: t.replace("   rows: 3\n   cols: 3", "   rows: 30000\n   cols: 30000"), "declares 30000x30000"),
    ]:
        (tmp_path / "broken.yml").write_text(edit(OPENCV_SAMPLE))
        with pytest.raises(CalibrationFileError, match=problem):
            read_calibration(tmp_path / "broken.yml")


def test_an_empty_distortion_list_is_refused_as_a_missing_one_is(tmp_path):
    """`distortion_coefficients: {data: []}` was read as no distortion (Af +6 % on the endoscope) while a
    missing key was refused."""
    content = _valid(tmp_path)
    content["distortion_coefficients"].update(data=[], cols=0)
    path = tmp_path / "empty.yaml"
    path.write_text(yaml.safe_dump(content))
    with pytest.raises(CalibrationFileError, match="'distortion_coefficients' holds no numbers"):
        read_calibration(path)


def test_a_calibrations_metadata_travels_beside_camera_info_and_applies_to_that_calibration_only():
    from veg_area_ros.calib_io import metadata_for, metadata_message
    from veg_area_ros.camera_info import camera_from_info, camera_info_fields
    from veg_area_ros.sim.synthetic import DSLR

    recorded = {"medium": "water", "calibration_distance_m": 0.7, "tone_curve": "srgb", "rms_px": np.float64(0.2)}
    text = metadata_message(ENDOSCOPE, recorded)
    fields = camera_info_fields(ENDOSCOPE)
    through_camera_info = camera_from_info(**{n: fields[n] for n in ("width", "height", "distortion_model", "d", "k")})
    assert metadata_for(through_camera_info, text) == {**recorded, "rms_px": 0.2}
    assert metadata_for(DSLR, text) is None  # another calibration: not this one's metadata
    refitted = dataclasses.replace(ENDOSCOPE, k1=ENDOSCOPE.k1 * 1.001 + 1e-6)
    assert metadata_for(refitted, text) is None
    for broken in ("", "[]", '{"calibration": {}}', '{"calibration": {}, "metadata": 3}'):
        with pytest.raises(ValueError, match="not a calibration metadata message"):
            metadata_for(ENDOSCOPE, broken)


KALIBR_CAMCHAIN = """cam0:
  cam_overlaps: []
  camera_model: pinhole
  distortion_coeffs: [-0.32, 0.12, 0.0012, -0.0008]
  distortion_model: radtan
  intrinsics: [520.0, 522.08, 326.0, 236.5]
  resolution: [640, 480]
  rostopic: /endoscope/image_raw
"""


def test_kalibrs_camchain_is_read_for_its_one_camera(tmp_path):
    """Kalibr (the robotics field's multi-camera calibrator) writes camchain YAML: read for a pinhole camera with
    radtan (plumb_bob with k3 = 0), equidistant or no distortion; two cameras, or its omnidirectional model,
    refused with their names (it was "'image_width' must be a positive integer, found None")."""
    path = tmp_path / "camchain.yaml"
    path.write_text(KALIBR_CAMCHAIN)
    calibration = read_calibration(path)
    camera = calibration.camera
    assert (camera.width, camera.height, camera.fx, camera.fy, camera.xp, camera.yp) == (640, 480, 520.0, 522.08,
                                                                                         326.0, 236.5)
    assert (camera.model, camera.k1, camera.k2, camera.p1, camera.p2, camera.k3) == ("plumb_bob", -0.32, 0.12,
                                                                                     0.0012, -0.0008, 0.0)
    assert calibration.camera_name == "/endoscope/image_raw"
    path.write_text(KALIBR_CAMCHAIN.replace("radtan", "equidistant"))
    assert read_calibration(path).camera.model == "equidistant"
    for text, problem in [
        (KALIBR_CAMCHAIN + KALIBR_CAMCHAIN.replace("cam0", "cam1"), r"2 cameras \(cam0, cam1\)"),
        (KALIBR_CAMCHAIN.replace("camera_model: pinhole", "camera_model: omni"), "omni camera with radtan"),
        (KALIBR_CAMCHAIN.replace(", -0.0008]", "]"), "radtan distortion has 4 coefficients, found 3"),
        (KALIBR_CAMCHAIN.replace("  resolution: [640, 480]\n", ""), "resolution"),
    ]:
        path.write_text(text)
        with pytest.raises(CalibrationFileError, match=problem):
            read_calibration(path)


METASHAPE_XML = """<?xml version="1.0" encoding="UTF-8"?>
<calibration>
  <projection>frame</projection>
  <width>6000</width>
  <height>4000</height>
  <f>4418.62</f>
  <cx>21.37</cx>
  <cy>-14.92</cy>
  <b1>3.25</b1>
  <k1>-0.0712</k1>
  <k2>0.0935</k2>
  <k3>-0.0427</k3>
  <p1>0.00041</p1>
  <p2>-0.00087</p2>
  <date>2026-11-30T09:12:44Z</date>
</calibration>
"""


def _metashape_pixels(points: np.ndarray, text: str) -> np.ndarray:
    """Metashape's frame camera as its manual writes it (Appendix C): pixels from the image's top-left corner."""
    import xml.etree.ElementTree as ElementTree

    root = ElementTree.fromstring(text)
    value = {child.tag: float(child.text) for child in root if child.tag not in ("projection", "date")}
    x, y = points[:, 0] / points[:, 2], points[:, 1] / points[:, 2]
    r2 = x * x + y * y
    radial = 1 + value["k1"] * r2 + value["k2"] * r2**2 + value["k3"] * r2**3
    xd = x * radial + value["p1"] * (r2 + 2 * x * x) + 2 * value["p2"] * x * y
    yd = y * radial + value["p2"] * (r2 + 2 * y * y) + 2 * value["p1"] * x * y
    u = value["width"] * 0.5 + value["cx"] + xd * value["f"] + xd * value["b1"]
    v = value["height"] * 0.5 + value["cy"] + yd * value["f"]
    return np.column_stack([u, v])


def test_metashapes_calibration_xml_projects_as_metashape_does(tmp_path):
    """A photogrammetrist's calibration from Agisoft Metashape (the field's self-calibrating bundle adjustment,
    the Brown model) was "not valid YAML": read, every point projects where Metashape's own formula puts it
    (its principal point from the image's centre and pixels from the top-left pixel's corner, b1 in fx, p1 and
    p2 in the other order than OpenCV's); terms camera_info's models lack are refused unless 0."""
    import cv2

    path = tmp_path / "camera_calibration.xml"
    path.write_text(METASHAPE_XML)
    camera = read_calibration(path).camera
    assert (camera.width, camera.height, camera.model) == (6000, 4000, "plumb_bob")
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(-0.6, 0.6, 200), rng.uniform(-0.4, 0.4, 200), np.ones(200)])
    matrix = np.array([[camera.fx, 0, camera.xp], [0, camera.fy, camera.yp], [0, 0, 1]])
    ours, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), matrix, np.array(camera.dist))
    metashape_corner_origin = _metashape_pixels(points, METASHAPE_XML)
    assert np.abs(ours.reshape(-1, 2) + 0.5 - metashape_corner_origin).max() < 1e-6
    path.write_text(METASHAPE_XML.replace("<width>6000</width>\n  <height>4000</height>",
                                          '<resolution width="6000" height="4000"/>'))
    assert read_calibration(path).camera == camera  # Metashape 1.x and 2.x write the size either way
    for text, problem in [
        (METASHAPE_XML.replace("frame", "fisheye"), "a Metashape fisheye camera: only frame cameras"),
        (METASHAPE_XML.replace("<k3>", "<k4>0.001</k4><k3>"), r"k4 \(r⁸\) is not 0"),
        (METASHAPE_XML.replace("<b1>", "<b2>0.4</b2><b1>"), r"b2 \(skew\) is not 0"),
        (METASHAPE_XML.replace("<f>4418.62</f>", ""), "without <f>"),
        (METASHAPE_XML.replace("<width>6000</width>", "<width>nan</width>"), "image size must be two whole"),
        (METASHAPE_XML.replace("<height>4000</height>", ""), "image size must be two whole"),
        (METASHAPE_XML.replace("<f>4418.62", "<f>inf"), "finite|positive"),
        (METASHAPE_XML.replace("<k1>-0.0712", "<k1>abc"), "<k1> is not a number: 'abc'"),
        ('<?xml version="1.0"?><!DOCTYPE c [<!ENTITY a "aaaa">]>' + METASHAPE_XML.split("?>", 1)[1], "DOCTYPE"),
    ]:
        path.write_text(text)
        with pytest.raises(CalibrationFileError, match=problem):
            read_calibration(path)
    path.write_text(METASHAPE_XML.replace("<k3>", "<k4>0</k4><p3>0</p3><k3>"))  # written as 0: nothing lost
    assert read_calibration(path).camera == camera


def test_metashapes_cameras_xml_gives_its_one_sensors_adjusted_calibration(tmp_path):
    """Export Cameras writes the whole chunk: the one sensor's adjusted calibration is read (not its initial
    one); a chunk of two cameras is refused with their labels."""
    calibration = METASHAPE_XML.split("?>", 1)[1].replace("<calibration>",
                                                          '<calibration type="frame" class="adjusted">')
    initial = ('<calibration type="frame" class="initial"><resolution width="6000" height="4000"/><f>4400</f>'
               '</calibration>')
    sensor = ('<sensor id="{id}" label="{label}" type="frame"><resolution width="6000" height="4000"/>'
              '<property name="pixel_width" value="0.0039"/>' + initial + calibration + '</sensor>')
    document = ('<?xml version="1.0" encoding="UTF-8"?>\n<document version="1.5.0"><chunk label="Chunk 1">'
                '<sensors next_id="1">{sensors}</sensors><cameras next_id="0"/></chunk></document>')
    path = tmp_path / "cameras.xml"
    path.write_text(document.format(sensors=sensor.format(id=0, label="ILCE-7RM3 (35mm)")))
    (tmp_path / "alone.xml").write_text(METASHAPE_XML)
    assert read_calibration(path).camera == read_calibration(tmp_path / "alone.xml").camera
    path.write_text(document.format(sensors=sensor.format(id=0, label="left") + sensor.format(id=1, label="right")))
    with pytest.raises(CalibrationFileError, match=r"2 calibrated sensors \('left', 'right'\)"):
        read_calibration(path)


COLMAP_CAMERAS = """# Camera list with one line of data per camera:
#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]
# Number of cameras: 2
1 OPENCV 640 480 536.07 536.02 342.87 236.04 -0.2651 -0.0467 0.0018 -0.0003
2 OPENCV 640 480 536.07 536.02 342.87 236.04 -0.2651 -0.0467 0.0018 -0.0003
"""


def test_colmaps_cameras_txt_is_read_with_its_principal_point_moved_half_a_pixel(tmp_path):
    """A structure-from-motion user's calibration: COLMAP's cameras.txt (its sparse model as text) was "not a
    camera_info calibration". Read for its camera (two identical lines, one per photo, are one camera), the
    principal point moved by half a pixel (COLMAP counts from the top-left pixel's corner), its OpenCV, full
    OpenCV and fisheye models as camera_info's; cameras that differ or a model camera_info lacks refused."""
    path = tmp_path / "cameras.txt"
    path.write_text(COLMAP_CAMERAS)
    camera = read_calibration(path).camera
    assert (camera.width, camera.height, camera.model) == (640, 480, "plumb_bob")
    assert (camera.fx, camera.fy, camera.xp, camera.yp) == pytest.approx((536.07, 536.02, 342.37, 235.54))
    assert camera.dist == pytest.approx([-0.2651, -0.0467, 0.0018, -0.0003, 0.0])
    for line, model, dist in [
        ("1 SIMPLE_RADIAL 640 480 530 320.5 240.5 -0.21", "plumb_bob", [-0.21, 0, 0, 0, 0]),
        ("1 FULL_OPENCV 640 480 530 531 320 240 -0.2 0.05 0.001 0.002 0.01 0.1 0.02 0.003", "rational_polynomial",
         [-0.2, 0.05, 0.001, 0.002, 0.01, 0.1, 0.02, 0.003]),
        ("1 OPENCV_FISHEYE 1280 960 600 601 640 480 0.05 -0.01 0.002 -0.0005", "equidistant",
         [0.05, -0.01, 0.002, -0.0005]),
    ]:
        path.write_text(line + "\n")
        camera = read_calibration(path).camera
        assert camera.model == model and camera.dist == pytest.approx(dist), line
    for text, problem in [
        (COLMAP_CAMERAS.replace("2 OPENCV 640 480 536.07", "2 OPENCV 640 480 900"), "2 different cameras"),
        ("1 FOV 640 480 500 500 320 240 0.9\n", "FOV model has no camera_info counterpart"),
        ("1 OPENCV 640 480 536 536 320 240 -0.2 0.05\n", "OPENCV has 8 parameters"),
        ("1 PINHOLE 640 480 536 536 320 x\n", "not all numbers"),
    ]:
        path.write_text(text)
        with pytest.raises(CalibrationFileError, match=problem):
            read_calibration(path)


def _colmap_binary(*cameras: tuple[int, int, int, int, list[float]]) -> bytes:
    """cameras.bin as COLMAP's format documents it: a uint64 count, then per camera int32 id, int32 model id,
    uint64 width and height and the model's parameters as float64, all little-endian."""
    data = struct.pack("<Q", len(cameras))
    for camera_id, model_id, width, height, params in cameras:
        data += struct.pack("<iiQQ", camera_id, model_id, width, height) + struct.pack(f"<{len(params)}d", *params)
    return data


def test_colmaps_binary_cameras_bin_reads_as_its_text_export(tmp_path):
    """COLMAP's mapper writes its sparse model as cameras.bin unless told otherwise; it was "cannot be read
    ('utf-8' codec can't decode ...)". Read as the same model's cameras.txt is (the half-pixel shift, models),
    whatever the file's name; a model camera_info lacks, a file cut short or one that runs on refused."""
    opencv = [536.07, 536.02, 342.87, 236.04, -0.2651, -0.0467, 0.0018, -0.0003]
    binary, text = tmp_path / "cameras.bin", tmp_path / "cameras.txt"
    binary.write_bytes(_colmap_binary((1, 4, 640, 480, opencv), (2, 4, 640, 480, opencv)))
    text.write_text(COLMAP_CAMERAS)
    from_binary, from_text = read_calibration(binary).camera, read_calibration(text).camera
    assert (from_binary.width, from_binary.height, from_binary.model) == (640, 480, "plumb_bob")
    assert (from_binary.fx, from_binary.fy, from_binary.xp, from_binary.yp, *from_binary.dist) == (
        from_text.fx, from_text.fy, from_text.xp, from_text.yp, *from_text.dist)
    renamed = tmp_path / "sparse0_cameras"
    renamed.write_bytes(_colmap_binary((3, 5, 1280, 960, [600, 601, 640, 480, 0.05, -0.01, 0.002, -0.0005])))
    fisheye = read_calibration(renamed).camera
    assert fisheye.model == "equidistant" and (fisheye.xp, fisheye.yp) == (639.5, 479.5)
    assert fisheye.dist == pytest.approx([0.05, -0.01, 0.002, -0.0005])
    whole = _colmap_binary((1, 4, 640, 480, opencv))
    for data, problem in [
        (_colmap_binary((1, 7, 640, 480, [500, 500, 320, 240, 0.9])), r"FOV model \(camera 1\) has no camera_info"),
        (_colmap_binary((1, 4, 640, 480, opencv), (2, 4, 640, 480, [900, *opencv[1:]])),
         "cameras.bin with 2 different"),
        (whole[:-8], "ends inside camera 1's parameters"),
        (whole + bytes(16), "16 bytes after its 1 cameras"),
        (struct.pack("<Q", 2) + whole[8:], "ends after 1 of its 2 cameras"),
    ]:
        binary.write_bytes(data)
        with pytest.raises(CalibrationFileError, match=problem):
            read_calibration(binary)


BOUGUET_RESULTS = """% Intrinsic and Extrinsic Camera Parameters
%
% This script file can be directly executed under Matlab to recover the camera intrinsic and extrinsic parameters.

%-- Focal length:
fc = [ 657.464248165001490 ; 657.944634300328010 ];

%-- Principal point:
cc = [ 303.137587634543620 ; 242.564356758838330 ];

%-- Skew coefficient:
alpha_c = 0.000000000000000;

%-- Distortion coefficients:
kc = [ -0.255822003929106 ; 0.128128004017738 ; -0.000209289155519 ; 0.000033219592815 ; 0.000000000000000 ];

%-- Focal length uncertainty:
fc_error = [ 0.342147089426758 ; 0.366812106226208 ];

%-- Image size:
nx = 640;
ny = 480;

%-- Various other variables (may be ignored if you do not use the Matlab Calibration Toolbox):
n_ima = 20;						% Number of calibration images
est_dist = [ 1 ; 1 ; 1 ; 1 ; 0 ];	% Estimation indicator of the distortion coefficients

%-- Image #1:
omc_1 = [ 1.654173e+00 ; 1.651803e+00 ; -6.715856e-01 ];
"""


def test_the_bouguet_toolboxs_calib_results_m_projects_as_the_toolbox_does(tmp_path):
    """The Camera Calibration Toolbox for Matlab's saved Calib_Results.m (common in older flume and PIV work) was
    "not valid YAML". Read: every point lands where the toolbox's own projection puts it (kc(3), kc(4) tangential,
    pixels from the upper-left pixel's centre, as OpenCV's); a skew, no image size or a short kc refused."""
    path = tmp_path / "Calib_Results.m"
    path.write_text(BOUGUET_RESULTS)
    camera = read_calibration(path).camera
    assert (camera.width, camera.height, camera.model) == (640, 480, "plumb_bob")
    fc, cc = (657.464248165001490, 657.944634300328010), (303.137587634543620, 242.564356758838330)
    kc = (-0.255822003929106, 0.128128004017738, -0.000209289155519, 0.000033219592815, 0.0)
    rays = np.random.default_rng(3).uniform(-0.45, 0.45, (200, 2))
    a, b = rays.T
    r2 = a * a + b * b
    radial = 1 + kc[0] * r2 + kc[1] * r2**2 + kc[4] * r2**3
    xx = a * radial + 2 * kc[2] * a * b + kc[3] * (r2 + 2 * a * a)
    yy = b * radial + kc[2] * (r2 + 2 * b * b) + 2 * kc[3] * a * b
    toolbox = np.column_stack([fc[0] * xx + cc[0], fc[1] * yy + cc[1]])
    assert np.abs(camera.normalized_to_pixels(rays) - toolbox).max() < 1e-9
    for change, problem in [
        (("alpha_c = 0.000000000000000;", "alpha_c = 0.0012;"), "skew"),
        (("nx = 640;\nny = 480;", ""), "without nx, ny .*add nx = WIDTH"),
        ((" ; 0.000000000000000 ];", " ];"), "kc holds 4 numbers, not 5"),
        (("fc = [ 657.464248165001490 ;", "fc = [ 657.4x ;"), "fc is not numbers"),
    ]:
        path.write_text(BOUGUET_RESULTS.replace(*change))
        with pytest.raises(CalibrationFileError, match=problem):
            read_calibration(path)
