"""The one mapping between a calibrated camera (`BrownCamera`) and camera_info's fields, whichever carries them:
a sensor_msgs/CameraInfo message, its CDR bytes (`cdr.CameraInfoFields`) or a camera_info YAML file. One
validation for all three, with the reason in the error.

No ROS here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from .camera_model import MODEL_DIST_NAMES, MODELS, BrownCamera, check_plausible
from .files import MAX_IMAGE_SIDE, too_many_pixels

if TYPE_CHECKING:  # read by attribute alike: a ROS message or the CDR reader's fields
    from sensor_msgs.msg import CameraInfo

    from .cdr import CameraInfoFields

FISHEYE_MODELS = ("equidistant", "fisheye", "kannala_brandt")  # other tools' names for OpenCV's fisheye
PINHOLE_SIZES = (0, 4, 5, 8, 12, 14)  # OpenCV's lengths; beyond the model's own coefficients they must be zero


def camera_info_fields(camera: BrownCamera) -> dict:
    """camera_info's fields for a camera: its distortion model's ROS name and coefficients, and the projection
    matrix of the ideal camera (what `image_rect` and the idealized images are in)."""
    ideal = camera.ideal().camera_matrix
    return {"width": camera.width, "height": camera.height, "distortion_model": camera.model,
            "d": [float(v) for v in camera.dist], "k": [float(v) for v in camera.camera_matrix.ravel()],
            "r": [float(v) for v in np.eye(3).ravel()],
            "p": [float(v) for v in np.hstack([ideal, np.zeros((3, 1))]).ravel()]}


def camera_from_info(width: int, height: int, distortion_model: str, d: Sequence[float],
                     k: Sequence[float]) -> BrownCamera:
    """The calibrated camera that camera_info's fields describe; ValueError with the reason for an
    uncalibrated, corrupt or implausible one."""
    if width <= 0 or height <= 0:
        raise ValueError("camera_info has no image size")
    if max(width, height) > MAX_IMAGE_SIDE:
        raise ValueError(f"camera_info image size {width}x{height} is beyond any camera "
                         f"(at most {MAX_IMAGE_SIDE} px a side)")
    if excess := too_many_pixels(width, height):
        raise ValueError(f"camera_info image size {excess}")
    dist = np.asarray(d, float).ravel()
    matrix = np.asarray(k, float).ravel()
    if matrix.size != 9:
        raise ValueError(f"the camera matrix should hold 9 numbers, found {matrix.size}")
    matrix = matrix.reshape(3, 3)
    if not np.all(np.isfinite(matrix)) or matrix[0, 0] <= 0 or matrix[1, 1] <= 0:
        raise ValueError("camera matrix fx, fy must be finite and positive (zero: an uncalibrated camera_info)")
    if distortion_model == "" and not np.any(dist):  # camera_info_manager's default: no distortion given
        distortion_model = "plumb_bob"
    if distortion_model in FISHEYE_MODELS:  # r = f·θ, not f·tan θ: no pinhole even with zero coefficients
        distortion_model = "equidistant"
    if distortion_model not in MODELS:
        raise ValueError(f"distortion model {distortion_model!r} is not supported (known: {', '.join(MODELS)})")
    if not np.all(np.isfinite(dist)):
        raise ValueError("distortion coefficients are not finite")
    count = len(MODEL_DIST_NAMES[distortion_model])
    if distortion_model == "equidistant":
        if dist.size not in (0, 4):
            raise ValueError(f"{dist.size} distortion coefficients do not fit equidistant's four (k1-k4)")
    elif dist.size not in PINHOLE_SIZES or np.any(dist[count:] != 0):
        raise ValueError(f"{dist.size} distortion coefficients do not fit {distortion_model}'s {count}")
    coefficients = np.pad(dist[:count], (0, count - min(count, dist.size)))
    return check_plausible(BrownCamera.from_opencv(matrix, coefficients, (int(width), int(height)), distortion_model))


def info_to_camera(msg: CameraInfo | CameraInfoFields) -> BrownCamera:
    """The calibrated camera of the images a sensor_msgs/CameraInfo or CameraInfoFields describes: its
    calibration, binned and cropped to its region of interest where it says so (`binned`)."""
    if hasattr(msg, "binning_x"):  # a ROS message
        binning, roi = (msg.binning_x, msg.binning_y), (msg.roi.x_offset, msg.roi.y_offset, msg.roi.height,
                                                        msg.roi.width)
    else:
        binning, roi = tuple(msg.binning), tuple(msg.roi[:4])
    return binned(camera_from_info(msg.width, msg.height, msg.distortion_model, msg.d, msg.k), binning, roi)


def binned(camera: BrownCamera, binning: tuple[int, int], roi: tuple[int, int, int, int]) -> BrownCamera:
    """The camera of images cropped to `roi` (x_offset, y_offset, height, width of the full-resolution image;
    all zero: the whole image) and then binned by `binning` (x, y; 0 or 1: none), as image_geometry's
    PinholeCameraModel makes it from camera_info: fx / bx, cx' = (cx - x_offset) / bx, the same distortion."""
    bin_x, bin_y = (max(int(b), 1) for b in binning)
    x_offset, y_offset, height, width = (int(v) for v in roi)
    if (height, width) == (0, 0):
        x_offset = y_offset = 0
        height, width = camera.height, camera.width
    if bin_x == bin_y == 1 and (x_offset, y_offset, height, width) == (0, 0, camera.height, camera.width):
        return camera
    if x_offset + width > camera.width or y_offset + height > camera.height or min(height, width) <= 0:
        raise ValueError(f"camera_info's roi (x_offset {x_offset}, y_offset {y_offset}, {width}x{height}) does not "
                         f"lie inside its calibrated {camera.width}x{camera.height} image")
    if width // bin_x < 1 or height // bin_y < 1:
        raise ValueError(f"camera_info's binning {bin_x}x{bin_y} leaves no pixel of its {width}x{height} image")
    return check_plausible(replace(camera, width=width // bin_x, height=height // bin_y, c=camera.c / bin_x,
                                   aspect=camera.aspect * bin_x / bin_y, xp=(camera.xp - x_offset) / bin_x,
                                   yp=(camera.yp - y_offset) / bin_y))


def other_camera(given: BrownCamera, recorded: BrownCamera, fx_std: float | None = None) -> str | None:
    """Why a calibration file is not the camera whose camera_info a recording carries, or None: another image
    size, or a focal length beyond the file's own std (3 std, at least 0.5 %: a refit of one camera moves it
    less) or a principal point more than 2 % of the width away."""
    if given.image_size != recorded.image_size:
        return (f"the calibration is for {given.width}x{given.height} images, the recording's camera_info "
                f"{recorded.width}x{recorded.height}")
    tolerance = max(3 * (fx_std or 0.0), 0.005 * given.fx)
    if abs(given.fx - recorded.fx) > tolerance:
        return (f"the calibration's focal length is {given.fx:.1f} px, the recording's camera_info "
                f"{recorded.fx:.1f} px (more than {tolerance:.1f} px apart)")
    if np.hypot(given.xp - recorded.xp, given.yp - recorded.yp) > 0.02 * given.width:
        return (f"the calibration's principal point is ({given.xp:.0f}, {given.yp:.0f}), the recording's "
                f"camera_info ({recorded.xp:.0f}, {recorded.yp:.0f})")
    return None
