"""Property-based fuzzing of every parser that meets outside input: whatever the bytes or the YAML, each one
answers with its result or its own error class (the one the CLI and the nodes turn into a one-line message),
never another exception. Derandomized, so CI sees the same examples every run."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from veg_area_ros.calib_io import CalibrationFileError, from_camera_info_dict, to_camera_info_dict
from veg_area_ros.camera_info import info_to_camera
from veg_area_ros.cdr import ImageMessageError, decode_camera_info, decode_image, encode_image
from veg_area_ros.frames import header_size, jpeg_structure_problem
from veg_area_ros.sim.synthetic import ENDOSCOPE, scene_targets_content
from veg_area_ros.strict_yaml import StrictYamlError, load_text
from veg_area_ros.targets import TargetsError, TargetsSpec

FUZZ = settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))

scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**12, 10**12), st.floats(allow_nan=True),
                    st.text(max_size=12))
documents = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=12),
                                                          st.dictionaries(st.text(max_size=12) | st.integers(), inner,
                                                                          max_size=8)), max_leaves=40)
GOOD_INFO = to_camera_info_dict(ENDOSCOPE, "endoscope")
GOOD_TARGETS = scene_targets_content()


def mutations(base: dict) -> st.SearchStrategy:
    """A good document with one or more keys replaced by anything (the likeliest real mistakes)."""
    keys = st.sampled_from(sorted(base))
    return st.lists(st.tuples(keys, documents), min_size=1, max_size=3).map(lambda changes: {**base, **dict(changes)})


@FUZZ
@given(st.one_of(documents, mutations(GOOD_INFO)))
def test_calibration_documents(content):
    try:
        calibration = from_camera_info_dict(content, Path("fuzz.yaml"))
    except CalibrationFileError:
        return
    assert calibration.camera.width > 0 and np.all(np.isfinite(calibration.camera.dist))


FOREIGN_CALIBRATIONS = [  # one of each format another tool writes, as read_calibration meets them
    '<?xml version="1.0"?>\n<calibration>\n  <projection>frame</projection>\n  <width>6000</width>\n'
    '  <height>4000</height>\n  <f>4418.6</f>\n  <cx>21.4</cx>\n  <cy>-14.9</cy>\n  <k1>-0.07</k1>\n'
    '  <p1>0.0004</p1>\n</calibration>\n',
    "# Camera list with one line of data per camera:\n1 OPENCV 640 480 536.07 536.02 342.87 236.04 -0.27 -0.05 "
    "0.0018 -0.0003\n",
    "cam0:\n  camera_model: pinhole\n  distortion_coeffs: [-0.32, 0.12, 0.0012, -0.0008]\n"
    "  distortion_model: radtan\n  intrinsics: [520.0, 522.08, 326.0, 236.5]\n  resolution: [640, 480]\n",
    "[image]\n\nwidth\n640\n\nheight\n480\n\n[narrow_stereo]\n\ncamera matrix\n500 0 320\n0 500 240\n0 0 1\n\n"
    "distortion\n-0.2 0.05 0 0 0\n",
    "%-- Focal length:\nfc = [ 657.46 ; 657.94 ];\ncc = [ 303.14 ; 242.56 ];\nalpha_c = 0.0;\n"
    "kc = [ -0.2558 ; 0.1281 ; -0.0002 ; 0.00003 ; 0.0 ];\nnx = 640;\nny = 480;\n",
]


@FUZZ
@given(st.sampled_from(FOREIGN_CALIBRATIONS), st.integers(0, 400), st.integers(0, 12), st.text(max_size=12))
def test_other_tools_calibration_files(base, at, cut, patch):
    """Another tool's file (Metashape XML, COLMAP's cameras.txt, Kalibr, ost.ini, Calib_Results.m) with a stretch
    replaced by any text: read, or refused as a calibration file, never another exception."""
    import tempfile

    from veg_area_ros.calib_io import read_calibration

    text = base[:at] + patch + base[at + cut:]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / ("camera.ini" if base.startswith("[image]") else "camera.txt")
        path.write_text(text, encoding="utf-8", errors="surrogateescape")
        try:
            calibration = read_calibration(path)
        except CalibrationFileError:
            return
    assert calibration.camera.width > 0 and np.all(np.isfinite(calibration.camera.dist))


COLMAP_BINARY = (struct.pack("<Q", 1) + struct.pack("<iiQQ", 1, 4, 640, 480)
                 + struct.pack("<8d", 536.07, 536.02, 342.87, 236.04, -0.27, -0.05, 0.0018, -0.0003))


@FUZZ
@given(st.integers(0, len(COLMAP_BINARY)), st.integers(0, 12), st.binary(max_size=16))
def test_colmaps_binary_cameras_file(at, cut, patch):
    """COLMAP's cameras.bin with a stretch of bytes replaced by any bytes: read, or refused as a calibration
    file, never another exception."""
    import tempfile

    from veg_area_ros.calib_io import read_calibration

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "cameras.bin"
        path.write_bytes(COLMAP_BINARY[:at] + patch + COLMAP_BINARY[at + cut:])
        try:
            calibration = read_calibration(path)
        except CalibrationFileError:
            return
    assert calibration.camera.width > 0 and np.all(np.isfinite(calibration.camera.dist))


@FUZZ
@given(st.one_of(documents, mutations(GOOD_TARGETS)))
def test_targets_documents(content):
    try:
        targets = TargetsSpec.from_dict(content)
    except TargetsError:
        return
    assert len(targets.all_planes()) >= 2 and np.all(np.isfinite(targets.all_planes()))


@FUZZ
@given(st.text(max_size=400))
def test_yaml_text(text):
    """Any text is plain data or one of the two YAML errors; a strict load never accepts what a plain safe load
    refuses."""
    try:
        value = load_text(text)
    except (StrictYamlError, yaml.YAMLError):
        return
    assert repr(value) == repr(yaml.safe_load(text))  # the same data (repr: NaN is not equal to itself)


@FUZZ
@given(st.binary(max_size=600))
def test_image_headers_and_jpeg_structure(data):
    size = header_size(data)
    assert size is None or (len(size) == 2 and all(isinstance(v, int) for v in size))
    problem = jpeg_structure_problem(b"\xff\xd8" + data)
    assert problem is None or isinstance(problem, str)


GOOD_IMAGE = encode_image(np.zeros((16, 24, 3), np.uint8), 1, 2, "camera")


@FUZZ
@given(st.binary(max_size=200), st.integers(0, len(GOOD_IMAGE)), st.binary(min_size=1, max_size=32))
def test_image_messages(noise, at, patch):
    for buffer in (noise, GOOD_IMAGE[:at] + patch + GOOD_IMAGE[at + len(patch):]):
        try:
            fields = decode_image(buffer)
            frame = fields.pixels()
        except ImageMessageError:
            continue
        assert frame.ndim in (2, 3) and frame.shape[0] == fields.height and frame.shape[1] == fields.width


@FUZZ
@given(st.binary(max_size=400))
def test_camera_info_messages(buffer):
    try:
        fields = decode_camera_info(buffer)
    except (ImageMessageError, ValueError):
        return
    try:
        camera = info_to_camera(fields)
    except ValueError:
        return
    assert camera.width * camera.height > 0
