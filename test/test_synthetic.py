import cv2
import numpy as np
import pytest

from veg_area_ros.sim.synthetic import (
    ENDOSCOPE,
    FlatPort,
    _pixel_rays,
    ideal_rays_to,
    look_at_pose,
    plane_coordinates,
    refract_at_port,
)


def test_refraction_obeys_snells_law():
    rays = _pixel_rays(ENDOSCOPE, 1)[::60, ::60].reshape(-1, 3)
    port = FlatPort(distance=0.02, water_index=1.333)
    _, directions = refract_at_port(rays, port)
    sin_air = np.hypot(rays[:, 0], rays[:, 1])
    sin_water = np.hypot(directions[:, 0], directions[:, 1])
    assert np.allclose(np.linalg.norm(directions, axis=1), 1.0)
    assert sin_air == pytest.approx(1.333 * sin_water, rel=1e-12)


@pytest.mark.parametrize("port", [None, FlatPort()])
def test_forward_and_backward_tracing_agree(port):
    rvec, tvec = look_at_pose(0.7, tilt_x_deg=12, tilt_y_deg=-20, roll_deg=30, centre=(0.02, -0.01))
    xy = plane_coordinates(ENDOSCOPE, rvec, tvec, port)  # pixel -> plane
    rng = np.random.default_rng(0)
    v, u = rng.integers(0, 480, 50), rng.integers(0, 640, 50)
    plane = np.column_stack([xy[v, u], np.zeros(50)])
    camera_frame = plane @ cv2.Rodrigues(rvec)[0].T + tvec
    pixels = ENDOSCOPE.normalized_to_pixels(ideal_rays_to(camera_frame, port))  # plane -> pixel
    assert np.abs(pixels - np.column_stack([u, v])).max() < 1e-6


def test_water_magnifies_by_about_the_refractive_index():
    point = np.array([[0.05, 0.0, 0.7]])
    port = FlatPort(distance=0.02, water_index=1.333)
    ratio = ideal_rays_to(point, port)[0, 0] / ideal_rays_to(point)[0, 0]
    # paraxial thin-port optics: the air ray must leave at an angle larger by Z / (d + (Z - d) / n)
    paraxial = 0.7 / (0.02 + 0.68 / 1.333)
    assert ratio == pytest.approx(paraxial, rel=0.005)
