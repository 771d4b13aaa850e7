"""One mapping between BrownCamera and camera_info: a file, a message and CDR fields refuse the same things for
the same reason (none cuts eight distortion coefficients to five without a word)."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest
import yaml
from rclpy.serialization import serialize_message

from veg_area_ros.calib_io import CalibrationFileError, read_calibration, to_camera_info_dict
from veg_area_ros.camera_info import camera_info_fields, info_to_camera
from veg_area_ros.camera_model import BrownCamera
from veg_area_ros.cdr import decode_camera_info
from veg_area_ros.frames import read_image
from veg_area_ros.ros.messages import camera_to_info
from veg_area_ros.sim.synthetic import ENDOSCOPE

CASES = {
    "eight coefficients, the rational ones not zero": (dict(d=[*map(float, ENDOSCOPE.dist), 0.1, 0.0, 0.0]),
                                                       "do not fit plumb_bob's 5"),
    "an unknown model, named": (dict(distortion_model="double_sphere"), "'double_sphere' is not supported"),
    "a fisheye with five coefficients": (dict(distortion_model="equidistant"), "do not fit equidistant's four"),
    "no focal length": (dict(k=[0.0] * 9), "uncalibrated"),
    "k1 = 1e6": (dict(d=[1e6, 0, 0, 0, 0]), "implausible camera model"),
    "a corrupt size": (dict(width=100_000), "beyond any camera"),
}


def _three_ways(tmp_path, change: dict):
    """The same camera_info as a YAML file, a CameraInfo message and CDR fields."""
    fields = {**camera_info_fields(ENDOSCOPE), **change}
    content = to_camera_info_dict(ENDOSCOPE)
    content.update(image_width=fields["width"], distortion_model=fields["distortion_model"])
    content["distortion_coefficients"] = {"rows": 1, "cols": len(fields["d"]), "data": [float(v) for v in fields["d"]]}
    content["camera_matrix"]["data"] = [float(v) for v in fields["k"]]
    path = tmp_path / "camera.yaml"
    path.write_text(yaml.safe_dump(content))
    msg = camera_to_info(ENDOSCOPE)
    msg.width, msg.distortion_model, msg.d, msg.k = (fields["width"], fields["distortion_model"], fields["d"],
                                                     fields["k"])
    return path, msg, decode_camera_info(serialize_message(msg))


@pytest.mark.parametrize("name", list(CASES))
def test_a_file_a_message_and_cdr_fields_refuse_alike(tmp_path, name):
    change, reason = CASES[name]
    path, msg, fields = _three_ways(tmp_path, change)
    with pytest.raises(CalibrationFileError, match=reason):
        read_calibration(path)
    for carrier in (msg, fields):
        with pytest.raises(ValueError, match=reason):
            info_to_camera(carrier)


def test_a_file_a_message_and_cdr_fields_accept_alike(tmp_path):
    """rational_polynomial with its extra terms zero maps as plumb_bob does: taken by all three, the same camera."""
    path, msg, fields = _three_ways(tmp_path, dict(distortion_model="rational_polynomial",
                                                   d=[*map(float, ENDOSCOPE.dist), 0.0, 0.0, 0.0]))
    cameras = [read_calibration(path).camera, info_to_camera(msg), info_to_camera(fields)]
    assert all(camera == cameras[0] for camera in cameras)
    assert cameras[0].model == "rational_polynomial"
    plumb = {k: v for k, v in cameras[0].parameters().items() if k not in ("k4", "k5", "k6")}
    assert plumb == pytest.approx(ENDOSCOPE.parameters(), rel=1e-12)
    rays = np.random.default_rng(1).uniform(-0.5, 0.5, (50, 2))
    assert np.array_equal(cameras[0].normalized_to_pixels(rays), ENDOSCOPE.normalized_to_pixels(rays))


def test_a_fisheye_with_zero_coefficients_is_measured_as_a_fisheye(tmp_path):
    """equidistant with k1-k4 zero is r_d = θ, not a pinhole (r_d = tan θ): read by all three as equidistant, and a
    ray 30 degrees off the axis lands where θ puts it, not tan θ (it was taken as a pinhole without a word)."""
    path, msg, fields = _three_ways(tmp_path, dict(distortion_model="equidistant", d=[0.0, 0.0, 0.0, 0.0]))
    cameras = [read_calibration(path).camera, info_to_camera(msg), info_to_camera(fields)]
    assert all(camera == cameras[0] and camera.model == "equidistant" for camera in cameras)
    ray = np.array([[np.tan(np.radians(30)), 0.0]])
    u = cameras[0].normalized_to_pixels(ray)[0, 0]
    assert u - cameras[0].xp == pytest.approx(cameras[0].fx * np.radians(30), rel=1e-12)
    assert abs(u - ENDOSCOPE.ideal().normalized_to_pixels(ray)[0, 0]) > 20


def test_round_trips_keep_the_model(tmp_path):
    """file -> camera_info -> file keeps each model and its coefficients."""
    from veg_area_ros.calib_io import write_calibration
    from veg_area_ros.camera_model import BrownCamera

    lenses = [BrownCamera(1280, 960, 560.0, 650.0, 500.0, k1=0.07, k2=-0.02, k3=0.018, k4=-0.006, model="equidistant"),
              BrownCamera(1280, 960, 565.0, 651.0, 500.0, k1=0.3, k2=-0.13, p1=-3e-4, p2=1e-4, k3=-0.01, k4=0.57,
                          k5=-0.11, k6=-0.04, model="rational_polynomial")]
    for lens in lenses:
        write_calibration(tmp_path / "a.yaml", lens)
        content = yaml.safe_load((tmp_path / "a.yaml").read_text())
        assert content["distortion_model"] == lens.model
        assert content["distortion_coefficients"]["cols"] == len(content["distortion_coefficients"]["data"]) == len(
            lens.dist)
        storage = cv2.FileStorage(str(tmp_path / "a.yaml"), cv2.FILE_STORAGE_READ)  # OpenCV reads it whole
        assert storage.getNode("distortion_model").string() == lens.model
        assert storage.getNode("distortion_coefficients").getNode("cols").real() == len(lens.dist)
        msg = camera_to_info(read_calibration(tmp_path / "a.yaml").camera)
        assert msg.distortion_model == lens.model and len(msg.d) == len(lens.dist)
        again = info_to_camera(decode_camera_info(serialize_message(msg)))
        write_calibration(tmp_path / "b.yaml", again)
        assert read_calibration(tmp_path / "b.yaml").camera == lens


def _fields(camera, binning=(0, 0), roi=(0, 0, 0, 0, False)):
    from veg_area_ros.camera_info import camera_info_fields
    from veg_area_ros.cdr import CameraInfoFields, Header

    f = camera_info_fields(camera)
    return CameraInfoFields(Header(0, 0, "cam"), camera.height, camera.width, f["distortion_model"], f["d"], f["k"],
                            f["r"], f["p"], binning, roi)


def test_binning_and_roi_give_the_camera_of_the_images_they_describe():
    """A 2x2-binned stream of a calibrated 640x480 endoscope and a cropped one are measured with the camera
    image_geometry makes of their camera_info (fx / 2, cx' = (cx - x_offset) / 2): Af as the full frame's."""
    import cv2

    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.camera_info import info_to_camera
    from veg_area_ros.classify import Classifier
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets

    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7)
    truth = cube_scene().true_area_m2
    full = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120)).measure(frame).area_m2
    binned = info_to_camera(_fields(ENDOSCOPE, binning=(2, 2)))
    assert (binned.width, binned.height, binned.fx, binned.xp) == (320, 240, ENDOSCOPE.fx / 2, ENDOSCOPE.xp / 2)
    small = cv2.resize(frame, (320, 240), interpolation=cv2.INTER_AREA)
    area = AreaMeasurer(binned, scene_targets(), Classifier(threshold=120)).measure(small).area_m2
    assert abs(area / truth - 1) < 0.01 and abs(area / full - 1) < 0.01, (area, full, truth)
    cropped = info_to_camera(_fields(ENDOSCOPE, roi=(40, 20, 440, 560, False)))
    assert (cropped.width, cropped.height, cropped.xp, cropped.yp) == (560, 440, ENDOSCOPE.xp - 40, ENDOSCOPE.yp - 20)
    area = AreaMeasurer(cropped, scene_targets(), Classifier(threshold=120)).measure(frame[20:460, 40:600]).area_m2
    assert abs(area / full - 1) < 1e-3, (area, full)


@pytest.mark.parametrize("roi, binning, problem", [
    ((600, 0, 100, 100, False), (0, 0), "does not lie inside its calibrated 640x480"),
    ((0, 0, 0, 0, False), (1000, 1), "leaves no pixel"),
])
def test_a_binning_or_roi_that_cannot_be_is_refused_with_its_values(roi, binning, problem):
    from veg_area_ros.camera_info import info_to_camera
    from veg_area_ros.sim.synthetic import ENDOSCOPE

    with pytest.raises(ValueError, match=problem):
        info_to_camera(_fields(ENDOSCOPE, binning=binning, roi=roi))


def _png_header(width: int, height: int) -> bytes:
    """A PNG's signature and header chunk alone: its declared size, no pixels."""
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + struct.pack(">I", len(header)) + b"IHDR" + header
            + struct.pack(">I", zlib.crc32(b"IHDR" + header)))


@pytest.mark.parametrize("width, height, taken", [
    (11648, 8736, True),    # a 100 MP medium-format camera (refused as "more than any camera" at 64 MP)
    (16320, 12240, True),   # a 200 MP phone sensor
    (20000, 20000, False),  # 400 MP: no camera's, and decoding one took 9 GB
])
def test_the_largest_sensors_sold_are_taken_and_larger_images_refused_before_decoding(tmp_path, width, height, taken):
    camera = BrownCamera(width, height, c=0.8 * width, xp=width / 2 - 0.5, yp=height / 2 - 0.5)
    path = tmp_path / "photo.png"
    path.write_bytes(_png_header(width, height))
    image, problem = read_image(path)
    assert image is None
    if taken:
        assert info_to_camera(camera_to_info(camera)).image_size == (width, height)
        assert "more than any camera" not in problem, problem
    else:
        with pytest.raises(ValueError, match=r"20000x20000 pixels \(400 MP\) is more than any camera's sensor"):
            info_to_camera(camera_to_info(camera))
        assert problem.startswith("declares 20000x20000 pixels (400 MP) is more than any camera's sensor"), problem
