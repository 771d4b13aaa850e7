"""Idealization: remap frames of a calibrated camera to its ideal camera (no distortion, square pixels,
principal point at the image centre). The maps are computed once per camera and reused for every frame.

No ROS here.
"""

from __future__ import annotations

import cv2
import numpy as np

from .camera_model import BrownCamera

OUTSIDE_PX = -10000.0  # a map entry for no raw pixel: far outside (OpenCV's nearest remap takes -1 as pixel 0)


class FrameSizeError(ValueError):
    """A frame whose size does not match the calibration: measuring it would be wrong, so it is refused."""


class Idealizer:
    def __init__(self, camera: BrownCamera):
        self.camera = camera
        self.ideal = camera.ideal()
        # fixed-point maps: about twice as fast to apply as float maps, 1/32 px interpolation steps
        if camera.pinhole and camera.reach is None:
            self._map1, self._map2 = cv2.initUndistortRectifyMap(
                camera.camera_matrix, camera.dist, None, self.ideal.camera_matrix, camera.image_size, cv2.CV_16SC2)
        else:
            self._map1, self._map2 = cv2.convertMaps(*self._float_maps(), cv2.CV_16SC2)
        self._valid: np.ndarray | None = None

    def _float_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """Each ideal pixel's raw position by the model itself: any model, and a model that folds (`reach`) has
        no raw pixel for the rays beyond the fold (outside, not the ghost its polynomial bends back to)."""
        camera = self.camera
        map_u = np.empty((camera.height, camera.width), np.float32)
        map_v = np.empty_like(map_u)
        u = np.arange(camera.width, dtype=float)
        for first in range(0, camera.height, 256):  # row blocks bound the memory of a 10-megapixel frame
            rows = np.arange(first, min(first + 256, camera.height), dtype=float)
            rays = self.ideal.pixels_to_normalized(np.column_stack([np.tile(u, len(rows)), np.repeat(rows, len(u))]))
            raw = camera.normalized_to_pixels(rays)
            raw[~camera.rays_within_reach(rays)] = OUTSIDE_PX
            map_u[first:first + len(rows)] = raw[:, 0].reshape(len(rows), -1)
            map_v[first:first + len(rows)] = raw[:, 1].reshape(len(rows), -1)
        return map_u, map_v

    def check(self, frame: np.ndarray) -> None:
        height, width = frame.shape[:2]
        if (width, height) != self.camera.image_size:
            raise FrameSizeError(f"frame is {width}x{height} but the calibration is for "
                                 f"{self.camera.width}x{self.camera.height}")

    def __call__(self, frame: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        self.check(frame)
        return cv2.remap(frame, self._map1, self._map2, interpolation, borderMode=cv2.BORDER_CONSTANT)

    def valid_mask(self) -> np.ndarray:
        """Pixels of the ideal image that come from inside the raw frame (uint8, 255 valid); computed once."""
        if self._valid is None:
            ones = np.full((self.camera.height, self.camera.width), 255, np.uint8)
            self._valid = self(ones, cv2.INTER_NEAREST)
            self._valid.setflags(write=False)
        return self._valid


class IdealView:
    """The raw frame and the idealized image of one camera, point by point: a calibrated camera's idealization,
    or none (the raw frame is then the idealized image). Every stage that maps between the two asks this."""

    def __init__(self, camera: BrownCamera | None):
        self.camera = camera
        self.idealizer = Idealizer(camera) if camera is not None else None

    @classmethod
    def of(cls, camera: BrownCamera | None, shared: IdealView | None = None) -> IdealView:
        """`camera`'s view: `shared` where given (its maps are the camera's alone, costly for a model OpenCV
        cannot map; many measurers of one camera's frames build them once), else a new one."""
        if shared is None:
            return cls(camera)
        if shared.camera != camera:
            raise ValueError("the shared ideal view is another camera's")
        return shared

    @property
    def calibrated(self) -> bool:
        return self.camera is not None

    @property
    def ideal_matrix(self) -> np.ndarray:
        """The ideal camera's matrix (a calibrated view only)."""
        return self.idealizer.ideal.camera_matrix

    def check_size(self, frame: np.ndarray) -> None:
        if self.idealizer is not None:
            self.idealizer.check(frame)

    def to_ideal(self, raw_pixels: np.ndarray) -> np.ndarray:
        """Raw-frame pixels -> the idealized image."""
        if self.camera is None or len(raw_pixels) == 0:
            return raw_pixels
        return self.idealizer.ideal.normalized_to_pixels(self.camera.pixels_to_normalized(raw_pixels))

    def to_raw(self, ideal_pixels: np.ndarray) -> np.ndarray:
        """Idealized-image pixels -> the raw frame (the inverse of `to_ideal`)."""
        if self.camera is None or len(ideal_pixels) == 0:
            return ideal_pixels
        return self.camera.normalized_to_pixels(self.idealizer.ideal.pixels_to_normalized(ideal_pixels))

    def image(self, frame: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        """The frame remapped to the idealized image (itself without a calibration)."""
        return self.idealizer(frame, interpolation) if self.idealizer is not None else frame

    def valid_mask(self) -> np.ndarray | None:
        """The idealized image's pixels that come from inside the raw frame; None: all of them."""
        return self.idealizer.valid_mask() if self.idealizer is not None else None
