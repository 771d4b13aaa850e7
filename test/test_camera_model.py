import cv2
import numpy as np
import pytest

from veg_area_ros.camera_model import BrownCamera, from_matlab, from_photomodeler, implausibility
from veg_area_ros.sim.synthetic import ENDOSCOPE


def grid(camera, n=25):
    u, v = np.meshgrid(np.linspace(0, camera.width - 1, n), np.linspace(0, camera.height - 1, n))
    return np.column_stack([u.ravel(), v.ravel()])


def test_opencv_conversion_is_exact_both_ways():
    K, dist = ENDOSCOPE.to_opencv()
    assert K[0, 0] == ENDOSCOPE.c and K[1, 1] == pytest.approx(ENDOSCOPE.c * ENDOSCOPE.aspect, rel=1e-15)
    assert (K[0, 2], K[1, 2]) == (ENDOSCOPE.xp, ENDOSCOPE.yp)
    assert list(dist) == [ENDOSCOPE.k1, ENDOSCOPE.k2, ENDOSCOPE.p1, ENDOSCOPE.p2, ENDOSCOPE.k3]
    again = BrownCamera.from_opencv(K, dist, ENDOSCOPE.image_size)
    assert again.to_opencv()[0] == pytest.approx(K, rel=1e-15)
    assert np.array_equal(again.dist, dist)


def test_model_equals_opencv_projection():
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(-0.3, 0.3, (200, 2)), rng.uniform(0.5, 1.0, 200)])
    ours = ENDOSCOPE.normalized_to_pixels(points[:, :2] / points[:, 2:])
    opencv, _ = cv2.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), *ENDOSCOPE.to_opencv())
    assert np.abs(ours - opencv.reshape(-1, 2)).max() < 1e-9


def test_pixel_inversion_round_trips_under_strong_distortion():
    pixels = grid(ENDOSCOPE)
    back = ENDOSCOPE.normalized_to_pixels(ENDOSCOPE.pixels_to_normalized(pixels))
    assert np.abs(back - pixels).max() < 1e-8


def test_a_pixels_inversion_does_not_depend_on_the_pixels_inverted_with_it():
    """Bit for bit: any part of a frame's pixels gives what the whole frame gives there, so weights built over
    a window equal the whole frame's (and a segment measured alone equals the same segment in a longer run).
    A strong, plausible barrel lens whose pixels need different numbers of Newton steps."""
    lens = BrownCamera(640, 480, 478.0, 302.8, 222.0, 1.0, k1=-0.466, k2=0.282, p1=-0.00144, p2=0.00252, k3=0.047)
    assert implausibility(lens) is None
    u, v = np.meshgrid(np.arange(0, 640, 7.0), np.arange(0, 480, 7.0))
    pixels = np.column_stack([u.ravel(), v.ravel()])
    whole = lens.pixels_to_normalized(pixels)
    rng = np.random.default_rng(0)
    for part in (rng.random(len(pixels)) < 0.3, np.all(np.abs(pixels - [320, 240]) < 100, axis=1)):
        assert np.array_equal(lens.pixels_to_normalized(pixels[part]), whole[part])


@pytest.mark.parametrize("bad", [dict(c=float("nan")), dict(k1=float("inf")), dict(c=-1.0), dict(aspect=0.0)])
def test_invalid_parameters_are_refused(bad):
    with pytest.raises(ValueError):
        BrownCamera(**{**ENDOSCOPE.to_dict(), **bad})


def test_skew_and_unsupported_models_are_refused():
    K, dist = ENDOSCOPE.to_opencv()
    skewed = K.copy()
    skewed[0, 1] = 2.0
    with pytest.raises(ValueError, match="skew"):
        BrownCamera.from_opencv(skewed, dist, ENDOSCOPE.image_size)
    with pytest.raises(ValueError, match="plumb_bob"):
        BrownCamera.from_opencv(K, np.r_[dist, 0.1, 0, 0], ENDOSCOPE.image_size)


def test_ideal_camera_is_centred_square_and_undistorted():
    ideal = ENDOSCOPE.ideal()
    assert (ideal.xp, ideal.yp) == (319.5, 239.5)
    assert ideal.aspect == 1.0 and not ideal.dist.any() and ideal.c == ENDOSCOPE.c


@pytest.mark.parametrize("model", ["plumb_bob", "rational_polynomial"])
def test_a_camera_without_distortion_holds_everywhere_without_searching_for_a_fold(model, monkeypatch):
    """A pinhole model with zero coefficients maps every ray to itself: its reach is None at once (the fold
    search over 72 x 400 rays cost 1.3 ms for each idealized camera a calibration's views made, 0.56 s of a
    417-view calibration), and the search, when made, finds none either. A tiny coefficient is searched."""
    import veg_area_ros.camera_model as camera_model

    camera = BrownCamera(640, 480, 500.0, 319.5, 239.5, model=model)
    assert camera.reach is None and camera.holds_everywhere()
    searched = []
    jacobian = camera_model.BrownCamera._distortion_jacobian

    def counted(self, xy):
        searched.append(len(xy))
        return jacobian(self, xy)

    monkeypatch.setattr(camera_model.BrownCamera, "_distortion_jacobian", counted)
    assert camera_model.model_reach(BrownCamera(640, 480, 500.0, 319.5, 239.5, model=model)) is None
    assert not searched
    barely = BrownCamera(640, 480, 500.0, 319.5, 239.5, k1=1e-9, model=model)
    grid = camera_model.FOLD_DIRECTIONS * camera_model.FOLD_STEPS
    assert camera_model.model_reach(barely) is None and searched == [grid]


def test_photomodeler_without_distortion_is_exact_metric_conversion():
    # 4 mm lens, 6.4 mm wide format on 640 px: 0.01 mm pixels; principal point 3.2, 2.4 mm from top-left
    imported = from_photomodeler(4.0, 6.4, (3.2, 2.4), (640, 480))
    cam = imported.camera
    assert cam.c == pytest.approx(400.0)
    assert (cam.xp, cam.yp) == pytest.approx((319.5, 239.5))
    assert cam.aspect == pytest.approx(1.0)
    assert imported.refit_max_px < 1e-9


def test_photomodeler_distortion_is_refitted_and_reported():
    K1, K2, P1, P2 = -8e-3, 2e-4, 1e-4, -5e-5  # mm^-2, mm^-4, mm^-1: a visibly distorting small lens
    imported = from_photomodeler(4.0, 6.4, (3.25, 2.38), (640, 480), K1=K1, K2=K2, P1=P1, P2=P2)
    cam = imported.camera
    assert imported.notes and imported.refit_rms_px < 0.05
    # the imported model sends each PhotoModeler-corrected (ideal) point back to the measured pixel
    measured = grid(cam)
    pixel = 0.01
    x = (measured[:, 0] - cam.xp) * pixel
    y = (measured[:, 1] - cam.yp) * pixel
    r2 = x * x + y * y
    xi = x + x * (K1 * r2 + K2 * r2**2) + P1 * (r2 + 2 * x * x) + 2 * P2 * x * y
    yi = y + y * (K1 * r2 + K2 * r2**2) + P2 * (r2 + 2 * y * y) + 2 * P1 * x * y
    ideal = np.column_stack([xi / 4.0, yi / 4.0])  # normalized: divided by the focal length in mm
    error = np.hypot(*(cam.normalized_to_pixels(ideal) - measured).T)
    assert error.max() <= imported.refit_max_px + 1e-9
    # K1 < 0 pulls measured points inwards to ideal ones, so forwards the lens pushes them out: k1 > 0
    assert cam.k1 > 0


def test_matlab_import_is_exact_and_zero_based():
    K = ENDOSCOPE.camera_matrix.copy()
    K[0, 2] += 1.0  # MATLAB's pixel centres start at 1
    K[1, 2] += 1.0
    imported = from_matlab(K.T, [ENDOSCOPE.k1, ENDOSCOPE.k2, ENDOSCOPE.k3], [ENDOSCOPE.p1, ENDOSCOPE.p2],
                           (ENDOSCOPE.height, ENDOSCOPE.width))
    assert imported.refit_max_px == 0.0
    assert imported.camera.to_opencv()[0] == pytest.approx(ENDOSCOPE.camera_matrix, rel=1e-14)
    assert imported.camera.dist == pytest.approx(ENDOSCOPE.dist, rel=1e-14)


def test_matlab_skew_is_refitted_with_its_residual_reported():
    K = ENDOSCOPE.camera_matrix.copy()
    K[:2, 2] += 1.0
    K[0, 1] = 1.5
    imported = from_matlab(K.T, [ENDOSCOPE.k1, ENDOSCOPE.k2], [0, 0], (480, 640))
    assert imported.refit_max_px > 0.01  # a shear is not in the model: the residual says so
    assert "skew" in imported.notes[0]
