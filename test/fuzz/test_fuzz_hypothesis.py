"""Property-based fuzzing of every parser that meets outside input: whatever the bytes or the YAML, each one
answers with its result or its own error class (the one the CLI and the nodes turn into a one-line message),
never another exception. Derandomized, so CI sees the same examples every run."""

from __future__ import annotations

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
