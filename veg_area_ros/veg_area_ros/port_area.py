"""Af through a lens calibrated in air behind a flat port: the plane's pose found through the exact refraction
model, then the measurement of `AreaMeasurer` with the plumb_bob camera that images the targets' and the
object's planes as the lens and port do. It exists apart from `area` because it wraps the whole measurement,
not a stage of it: it only decides when the stand-in camera is made again (the targets moved).

No ROS here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from .area import AreaMeasurer
from .area_result import AreaResult
from .camera_model import BrownCamera
from .camera_uncertainty import KEPT_WITHIN_PX, AreaSensitivity, area_sensitivity
from .classify import Classifier, ClassifyError
from .flat_port import (
    PORT_KEY,
    FlatPortCamera,
    PortError,
    PortUncertainty,
    absorbed_camera,
    estimate_pose,
    port_uncertainty_from_dict,
)
from .idealize import IdealView
from .markers import detect_markers
from .scale import PlaneScale
from .targets import TargetsError, TargetsNotFoundError, TargetsSpec

PORT_AS_MEASURED = ("port uncertainty not recorded (the port as measured): Af's std carries the lens's but not "
                    "the port's numbers' (fit the port from underwater board views to have it)")


@dataclass
class SensitivityMemory:
    """The last sensitivity a port's spread worked out, with the targets' raw pixels it was worked for: kept
    across the stand-ins of a moving camera while the targets stay within KEPT_WITHIN_PX (each costs some 30
    fits of a stand-in, 0.3-0.8 s at 640x480)."""
    targets_raw: np.ndarray | None = None
    sensitivity: AreaSensitivity | None = None
    worked: int = 0  # how often it was worked out


@dataclass(frozen=True, eq=False)
class PortSpread:
    """A port file's uncertainty as the stand-in cameras it allows (`camera_uncertainty.CalibrationSpread`):
    each fitted port parameter moved by its std alone (the file records no correlations between them), and
    the lens along each principal axis of its air calibration's covariance; for each, the plane's pose found
    again from the same target pixels and the stand-in fitted again (`stand_in`)."""

    camera: FlatPortCamera
    uncertainty: PortUncertainty
    stand_in: Callable[[FlatPortCamera], BrownCamera]
    memory: SensitivityMemory

    def sensitivity(self, view: IdealView, roi_raw_px: np.ndarray, scale: PlaneScale) -> AreaSensitivity:
        targets_raw = view.to_raw(scale.pixels)
        kept = self.memory.targets_raw
        if (kept is not None and kept.shape == targets_raw.shape
                and np.max(np.abs(kept - targets_raw)) <= KEPT_WITHIN_PX):
            return self.memory.sensitivity
        self.memory.sensitivity = area_sensitivity(view, self, roi_raw_px, scale)
        self.memory.targets_raw, self.memory.worked = targets_raw, self.memory.worked + 1
        return self.memory.sensitivity

    def axes(self, camera: BrownCamera) -> Iterator[Callable[[float], BrownCamera]]:
        port, lens = self.camera.port, self.camera.lens
        for name, std in self.uncertainty.port_std.items():
            if std > 0:
                yield lambda sign, name=name, std=std: self.stand_in(
                    FlatPortCamera(lens, replace(port, **{name: getattr(port, name) + sign * std})))
        if self.uncertainty.lens_covariance is not None:
            for moved in self.uncertainty.lens_covariance.axes(lens):
                yield lambda sign, moved=moved: self.stand_in(FlatPortCamera(moved(sign), port))


class PortAreaMeasurer:
    """Af through a lens calibrated in air behind a flat port (`flat_port.FlatPortCamera`). The targets' plane
    pose comes from the markers through the exact refraction model; the object's plane (the targets' one, or
    `object_plane_offset_m` farther along the optical axis) and the targets' then get the plumb_bob camera that
    images them as the lens and port do (`flat_port.absorbed_camera`, fitted around the targets), and the
    measurement is the calibrated one of `AreaMeasurer` with that camera. The plane is found again when the
    targets move."""

    def __init__(self, camera: FlatPortCamera, targets: TargetsSpec, classifier: Classifier,
                 calibration_conditions: dict | None = None, **options):
        """`calibration_conditions`: the port file's metadata; the port's std and the lens's covariance it
        records go into Af's std (none recorded: said in each result)."""
        if len(targets.markers) + len(targets.points) < 4:
            raise TargetsError("a flat-port measurement needs 4 or more targets (the plane's pose through the port)")
        self.camera, self.targets, self.classifier, self.options = camera, targets, classifier, options
        block = (calibration_conditions or {}).get(PORT_KEY)
        try:
            self.uncertainty = (PortUncertainty({}, None) if block is None
                                else port_uncertainty_from_dict(block, camera.lens))
        except PortError as exc:
            raise ClassifyError(f"the calibration's {exc}") from None
        # the port holds at any distance: the inner measurement checks the medium only
        self.conditions = {"medium": (calibration_conditions or {}).get("medium", "water")}
        self.sensitivity_memory = SensitivityMemory()
        self._inner: AreaMeasurer | None = None
        self._rebuilds_seen = 0
        self.absorbed_residual_px = float("nan")  # the plumb_bob stand-in's largest misfit around the targets
        self.plane_pose: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def rebuilds(self) -> int:
        return 0 if self._inner is None else self._inner.rebuilds

    def _targets_seen(self, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The targets found in `frame`: their plane coordinates (N, 2) and raw pixels (N, 2)."""
        markers = detect_markers(frame, self.targets.dictionary) if self.targets.markers else {}
        found = [i for i in self.targets.markers if i in markers]
        pixels = [markers[i].centre for i in found] + [pixel for pixel, _ in self.targets.points]
        planes = [self.targets.markers[i] for i in found] + [plane for _, plane in self.targets.points]
        if len(pixels) < 4:
            raise TargetsNotFoundError(f"only {len(pixels)} target(s) found; the plane's pose through the port "
                                       "needs 4", len(found))
        return np.array(planes, float), np.array(pixels, float)

    def _stand_in(self, camera: FlatPortCamera, planes: np.ndarray, pixels: np.ndarray
                  ) -> tuple[BrownCamera, float, tuple[np.ndarray, np.ndarray]]:
        """The camera that images the targets' and the object's planes as `camera` does (its largest misfit
        around the targets, px), with the plane's pose through `camera` from the targets seen."""
        rvec, tvec = estimate_pose(camera, planes, pixels)
        offset = self.targets.object_plane_offset_m or 0.0
        object_tvec = np.asarray(tvec, float) + np.array([0.0, 0.0, offset])
        # one stand-in for both planes: the targets' (their centres make the scale) and the object's (its
        # pixels' footprints); through a port they are not one pinhole's, so each alone would bias the other
        absorbed, residual = absorbed_camera(camera, rvec, object_tvec, box=self._targets_box(camera, rvec, tvec),
                                             more_tvecs=(np.asarray(tvec, float),) if offset else ())
        return absorbed, residual, (rvec, tvec)

    def _targets_box(self, camera: FlatPortCamera, rvec: np.ndarray, tvec: np.ndarray
                     ) -> tuple[float, float, float, float]:
        """The raw-image box of every listed target (seen or not), widened by 15 % of the image a side: where
        the default ROI and the targets are."""
        planes = self.targets.all_planes()
        pixels = camera.project_pose(np.column_stack([planes, np.zeros(len(planes))]), rvec, tvec)
        width, height = camera.image_size
        (u0, v0), (u1, v1) = pixels.min(axis=0), pixels.max(axis=0)
        return (max(0.0, u0 - 0.15 * width), max(0.0, v0 - 0.15 * height),
                min(width - 1.0, u1 + 0.15 * width), min(height - 1.0, v1 + 0.15 * height))

    def _build(self, frame: np.ndarray) -> None:
        planes, pixels = self._targets_seen(frame)
        try:
            absorbed, self.absorbed_residual_px, self.plane_pose = self._stand_in(self.camera, planes, pixels)
        except PortError as exc:
            raise TargetsError(str(exc)) from exc
        spread = None
        if self.uncertainty.recorded:
            spread = PortSpread(self.camera, self.uncertainty,
                                lambda moved: self._stand_in(moved, planes, pixels)[0], self.sensitivity_memory)
        self._inner = AreaMeasurer(absorbed, self.targets, self.classifier, calibration_conditions=self.conditions,
                                   calibration_spread=spread, **self.options)

    def start_segment(self) -> None:
        """As AreaMeasurer.start_segment; the plane's pose through the port and its term are found anew too."""
        self._inner, self._rebuilds_seen = None, 0
        self.sensitivity_memory = SensitivityMemory()

    def measure(self, frame: np.ndarray, keep_images: bool = False, grey: np.ndarray | None = None) -> AreaResult:
        """As AreaMeasurer.measure (`grey` too: the markers found in it)."""
        looked_at = frame if grey is None else grey
        if self._inner is None:
            self._build(looked_at)
        result = self._inner.measure(frame, keep_images, grey)
        if self._inner.rebuilds > max(self._rebuilds_seen, 1):  # the targets moved: find their plane again
            self._build(looked_at)
            result = self._inner.measure(frame, keep_images, grey)
        self._rebuilds_seen = self._inner.rebuilds
        if not self.uncertainty.port_std and self.uncertainty.lens_covariance is not None:
            result.warnings.append(PORT_AS_MEASURED)
        return result
