"""The calibration's own uncertainty at the object: its parameters' covariance carried to Af. No ROS here.

It exists because a calibration is an estimate: its focal length, principal point and distortion each have a
standard error (the calibration reports them), and a frame measured with it inherits that error wherever the
distortion it undoes, and the targets' idealized positions that set the scale, would lie elsewhere under
another fit the views allow. Where the targets frame the object their fit takes most of that out (OpenCV's webcam
photos, the targets at the board's outer corners: 0.01-0.02 % of Af); where the scale is carried from targets
beside the object across the image, it grows (a render with targets three squares apart: 0.01 %, ten times
more). Moving the ROI with the camera instead of keeping its raw pixels made it look 0.2-0.7 %: the term keeps
the object's pixels, which no calibration moves.

`veg-area calibrate` and the calibration node record the covariance of the camera's parameters in the file's
metadata (`camera_covariance`); a flat port's file records its port's std and the lens's covariance, which
port_area.py turns into stand-in cameras (`CalibrationSpread`). The weights stage (weights.py) asks
`area_sensitivity` once per target layout (kept while the targets stay within a few pixels: it changes slowly
with their place, and costs tens of ms): each of about a thousand raw pixels over the ROI with its footprint on
the object's plane (the idealized area it covers, times the metric area of an idealized pixel under the
targets' fit), re-worked under the camera moved by one standard deviation each way along every axis, the
targets re-idealized and the scale fitted again. Each frame then sums those changes over the samples in its
object's mask: where in the ROI the object lies decides the term (through a port, the whole ROI said half of
what the object's pixels say: its edges move the other way).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .camera_model import BrownCamera
from .idealize import IdealView
from .scale import PlaneScale

# targets within this of those a term was worked for (idealized px): it holds (it changes slowly with their place)
KEPT_WITHIN_PX = 8.0
SAMPLE_PIXELS = 1024  # the ROI's raw pixels, evenly subsampled: Af's relative change is smooth over them


@dataclass(frozen=True, eq=False)
class CameraCovariance:
    """The covariance of a camera's parameters (OpenCV's names, in `BrownCamera.param_names`' order)."""

    parameters: tuple[str, ...]
    matrix: np.ndarray  # (n, n)

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, CameraCovariance) and self.parameters == other.parameters
                and np.array_equal(self.matrix, other.matrix))

    __hash__ = None  # mutable contents: not a key

    def as_dict(self) -> dict:
        return {"parameters": list(self.parameters), "matrix": [[float(v) for v in row] for row in self.matrix]}

    @classmethod
    def from_std(cls, std: dict[str, float], correlations: dict[str, float]) -> CameraCovariance:
        """From the calibration's standard deviations and its correlations keyed 'a-b'."""
        names = tuple(std)
        sigma = np.array([std[n] for n in names], float)
        correlation = np.eye(len(names))
        for i, a in enumerate(names):
            for j, b in enumerate(names[i + 1:], start=i + 1):
                correlation[i, j] = correlation[j, i] = float(correlations.get(f"{a}-{b}", 0.0))
        return cls(names, correlation * np.outer(sigma, sigma))

    @classmethod
    def from_conditions(cls, conditions: dict | None, camera: BrownCamera | None) -> CameraCovariance | None:
        """The covariance a calibration's metadata records for `camera`, or None where it records none.
        ValueError where it records one that does not fit the camera's model or is no covariance."""
        recorded = (conditions or {}).get("camera_covariance")
        if recorded is None or camera is None:
            return None
        try:
            names = tuple(str(n) for n in recorded["parameters"])
            matrix = np.array(recorded["matrix"], float)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"camera_covariance is not readable ({exc.__class__.__name__}: {exc})") from None
        if names != tuple(camera.param_names):
            raise ValueError(f"camera_covariance is for the parameters {list(names)}, the camera's "
                             f"{camera.model} model has {list(camera.param_names)}")
        if (matrix.shape != (len(names), len(names)) or not np.all(np.isfinite(matrix))
                or not np.allclose(matrix, matrix.T, rtol=1e-6, atol=0)
                or np.linalg.eigvalsh(matrix).min() < -1e-9 * max(float(np.abs(matrix).max()), 1e-300)):
            raise ValueError(f"camera_covariance is no covariance matrix for {len(names)} parameters")
        return cls(names, matrix)

    def sensitivity(self, view: IdealView, roi_raw_px: np.ndarray, scale: PlaneScale) -> AreaSensitivity:
        return area_sensitivity(view, self, roi_raw_px, scale)

    def axes(self, camera: BrownCamera) -> Iterator[Callable[[float], BrownCamera]]:
        """The camera moved along each principal axis of the covariance (`CalibrationSpread`)."""
        parameters = np.array(list(camera.parameters().values()), float)
        values, vectors = np.linalg.eigh(self.matrix)
        for value, vector in zip(values, vectors.T, strict=True):
            if value > 0:
                shift = math.sqrt(value) * vector
                yield lambda sign, shift=shift: camera.with_parameters(parameters + sign * shift)


class CalibrationSpread(Protocol):
    """A calibration's uncertainty as the cameras it allows: each of `axes` moves the camera one standard
    deviation along one independent direction, either way (sign +1 or -1); `sensitivity` is what that does to
    the ROI's footprints (`area_sensitivity`, or one kept from targets a few pixels away)."""

    def axes(self, camera: BrownCamera) -> Iterator[Callable[[float], BrownCamera]]: ...

    def sensitivity(self, view: IdealView, roi_raw_px: np.ndarray, scale: PlaneScale) -> AreaSensitivity: ...


@dataclass(frozen=True, eq=False)
class AreaSensitivity:
    """How each raw pixel's metric footprint moves along each axis of a calibration's spread, at samples over
    the ROI: Af's relative std for any set of the ROI's pixels (the object's, frame by frame) is then a sum."""

    raw_px: np.ndarray  # (N, 2) the samples' raw pixel coordinates (u, v), integers
    footprint: np.ndarray  # (N,) each sample's footprint under the calibration (m² per raw pixel)
    change: np.ndarray  # (axes, N) half the footprint's difference between the camera moved either way

    def relative_std(self, inside: np.ndarray | None = None) -> float:
        """Af's relative std over the samples `inside` marks (bool (N,)); over all of them where it marks none
        (an object too small to hold a sample: the ROI's figure stands in)."""
        if inside is None or not np.any(inside):
            inside = np.ones(len(self.footprint), bool)
        base = float(self.footprint[inside].sum())
        if not self.change.size or base <= 0:
            return 0.0
        return float(np.sqrt(np.sum((self.change[:, inside].sum(axis=1) / base) ** 2)))


def area_sensitivity(view: IdealView, spread: CalibrationSpread, roi_raw_px: np.ndarray,
                     scale: PlaneScale) -> AreaSensitivity:
    """Each of the ROI's raw pixels (N, 2; subsampled to SAMPLE_PIXELS) with its footprint on the object's plane
    (the idealized area it covers times the metric area of an idealized pixel under the targets' fit) under the
    view's camera, and how far it moves under the camera moved along each axis of `spread` (a `CameraCovariance`
    or another `CalibrationSpread`), the targets of `scale` (idealized in `view`) re-idealized under each moved
    camera and the scale fitted again. An axis whose moved camera folds inside the ROI (or finds no pose) is left
    out: it says nothing."""
    camera = view.camera
    step = max(1, math.ceil(len(roi_raw_px) / SAMPLE_PIXELS))
    pixels = np.asarray(roi_raw_px, float)[::step]
    targets_raw = view.to_raw(scale.pixels)

    def footprints(moved: BrownCamera) -> np.ndarray:
        ideal_targets, _ = moved.pixels_to_ideal(targets_raw)
        matrix = moved.ideal().camera_matrix if scale.plane_offset_m is not None else None
        fitted = PlaneScale.fit(ideal_targets, scale.planes, scale.distance_std_m, scale.pixel_std,
                                scale.plane_offset_m, matrix)
        ideal_pixels, area = moved.pixels_to_ideal(pixels)
        return area * fitted.pixel_area(ideal_pixels)

    changes = []
    for moved in spread.axes(camera):
        try:
            change = (footprints(moved(1.0)) - footprints(moved(-1.0))) / 2
        except ValueError:
            continue
        if np.all(np.isfinite(change)):
            changes.append(change)
    return AreaSensitivity(pixels, footprints(camera), np.array(changes).reshape(len(changes), len(pixels)))

