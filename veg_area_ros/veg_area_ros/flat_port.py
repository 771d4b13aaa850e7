"""An explicit flat-port refraction model: the lens calibrated once in air, the port described by a few numbers,
exact refraction for every ray at every distance.

No ROS here. The camera frame is the lens's: origin at its projection centre, z forward. The port's inner
surface is the plane n·X = distance, its outer surface n·X = distance + thickness, with n the port's unit
normal (tilted from the optical axis by `tilt_x_rad` about y and `tilt_y_rad` about x). Air inside, glass (or
acrylic) between, water outside.

Back-projection (pixel -> ray in water) is closed form: the lens's ideal ray, two ray-plane intersections and
vector Snell's law. Projection (point in water -> pixel) is a 1-D solve: the air ray, the glass ray and the
water ray all lie in the plane of refraction spanned by n and the point, and the point's distance from the
normal axis grows monotonically with the sine of the air ray's angle (Newton's method, safeguarded by a
bracket; 3-6 steps). With every refractive index 1 the model is the air camera.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.optimize import least_squares

from .camera_model import MODEL_DIST_NAMES, BrownCamera
from .camera_uncertainty import CameraCovariance

WATER_INDEX = 1.333  # fresh water at about 20 °C, visible light
ACRYLIC_INDEX = 1.49
GLASS_INDEX = 1.52


class PortError(ValueError):
    """A port description or fit that cannot be used; the message says why."""


@dataclass(frozen=True)
class FlatPort:
    """A flat window in front of the lens: `distance` m from the projection centre to its inner surface along
    its normal, glass `thickness` m, and the refractive indices behind it."""

    distance: float = 0.02
    water_index: float = WATER_INDEX
    thickness: float = 0.0
    glass_index: float = ACRYLIC_INDEX
    tilt_x_rad: float = 0.0  # the normal turned towards +x (about the y axis)
    tilt_y_rad: float = 0.0  # the normal turned towards +y (about the x axis)

    def __post_init__(self) -> None:
        values = [self.distance, self.water_index, self.thickness, self.glass_index, self.tilt_x_rad, self.tilt_y_rad]
        if not all(np.isfinite(v) for v in values):
            raise PortError(f"port parameters must be finite, got {self}")
        if not 0 < self.distance < 1.0 or not 0 <= self.thickness < 0.2:
            raise PortError(f"port distance must be in (0, 1) m and thickness in [0, 0.2) m, got "
                            f"{self.distance:g} and {self.thickness:g}")
        if not (1.0 <= self.water_index < 2.0 and 1.0 <= self.glass_index < 2.5):
            raise PortError(f"refractive indices must be in [1, 2), got water {self.water_index:g}, "
                            f"glass {self.glass_index:g}")
        if max(abs(self.tilt_x_rad), abs(self.tilt_y_rad)) > np.radians(30):
            raise PortError("a port tilted by more than 30 degrees is not a flat port in front of the lens")

    @property
    def normal(self) -> np.ndarray:
        n = np.array([np.tan(self.tilt_x_rad), np.tan(self.tilt_y_rad), 1.0])
        return n / np.linalg.norm(n)

    @classmethod
    def parse(cls, text: str, water_index: float = WATER_INDEX) -> FlatPort:
        """'flat:DISTANCE_M:THICKNESS_M:N_GLASS' as the command line takes it."""
        parts = text.split(":")
        if len(parts) != 4 or parts[0] != "flat":
            raise PortError(f"port {text!r}: expected flat:DISTANCE_M:THICKNESS_M:N_GLASS")
        try:
            distance, thickness, glass = (float(p) for p in parts[1:])
        except ValueError as exc:
            raise PortError(f"port {text!r}: distance, thickness and index must be numbers") from exc
        return cls(distance, water_index, thickness, glass)


def along(vectors: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Each 3-vector of `vectors` (..., 3) dotted with `axis` (3,) -> (...). One flat matrix-vector product:
    numpy's matmul over an (H, W, 3) stack is some twenty times slower for a whole image of rays."""
    vectors = np.ascontiguousarray(vectors)
    return (vectors.reshape(-1, 3) @ axis).reshape(vectors.shape[:-1])


def in_frame(vectors: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Each 3-vector of `vectors` (..., 3) times the 3x3 `rotation` (row vectors, v @ R) -> (..., 3)."""
    return np.einsum("...i,ij->...j", vectors, rotation)


def _refract(directions: np.ndarray, normal: np.ndarray, eta: float) -> np.ndarray:
    """Vector Snell's law: unit directions crossing a surface of unit normal `normal` (pointing the way they go)
    from index n1 to n2, eta = n1 / n2."""
    cos_in = along(directions, normal)
    sin2_out = eta**2 * (1.0 - cos_in**2)
    cos_out = np.sqrt(np.maximum(1.0 - sin2_out, 0.0))
    return eta * directions + (cos_out - eta * cos_in)[..., None] * normal


def rays_in_water(port: FlatPort, air: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit air rays from the projection centre (..., 3) -> (origins on the port's outer surface, unit
    directions in water), both (..., 3): two ray-plane intersections and Snell's law at each surface."""
    n = port.normal
    inner = air * (port.distance / along(air, n))[..., None]
    glass = _refract(air, n, 1.0 / port.glass_index)
    outer = inner + glass * (port.thickness / along(glass, n))[..., None]
    return outer, _refract(glass, n, port.glass_index / port.water_index)


def air_rays_to(port: FlatPort, points: np.ndarray) -> np.ndarray:
    """Camera-frame points in water (N, 3) -> the unit air ray from the projection centre that reaches each
    through the port. The ray lies in the plane of refraction (the normal and the point); the sine of its
    angle to the normal is solved for from the point's distance from the normal's axis."""
    n = port.normal
    points = np.asarray(points, float).reshape(-1, 3)
    depth = points @ n
    radial = points - depth[:, None] * n
    reach = np.linalg.norm(radial, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(reach[:, None] > 0, radial / reach[:, None], 0.0)
    water_path = depth - port.distance - port.thickness
    if np.any(water_path <= 0):
        raise PortError("a point lies inside the port, not in the water in front of it")
    indices = np.array([1.0, port.glass_index, port.water_index])
    lengths = np.column_stack([np.full_like(depth, port.distance), np.full_like(depth, port.thickness),
                               water_path])

    def lateral(sine: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = sine[:, None] / indices
        root = np.sqrt(1.0 - q * q)
        return (lengths * q / root).sum(axis=1), (lengths / (indices * root**3)).sum(axis=1)

    sine = np.clip(reach / (lengths / indices).sum(axis=1), 0.0, 0.999)  # the paraxial guess
    low, high = np.zeros_like(sine), np.full_like(sine, 1.0 - 1e-12)
    for _ in range(60):
        value, slope = lateral(sine)
        error = value - reach
        low, high = np.where(error < 0, sine, low), np.where(error < 0, high, sine)
        step = sine - error / slope
        outside = ~((step > low) & (step < high))
        step[outside] = 0.5 * (low + high)[outside]  # Newton left the bracket: bisect
        done = np.abs(step - sine) < 1e-15
        sine = step
        if np.all(done):
            break
    return np.sqrt(1.0 - sine**2)[:, None] * n + sine[:, None] * unit


@dataclass(frozen=True)
class FlatPortCamera:
    """The air-calibrated lens behind a flat port."""

    lens: BrownCamera
    port: FlatPort

    @property
    def image_size(self) -> tuple[int, int]:
        return self.lens.image_size

    def air_rays(self, uv: np.ndarray) -> np.ndarray:
        """Raw pixels (N, 2) -> unit ray directions in air (N, 3)."""
        xy = self.lens.pixels_to_normalized(np.asarray(uv, float).reshape(-1, 2))
        rays = np.column_stack([xy, np.ones(len(xy))])
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def back_project(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw pixels (N, 2) -> their rays in water: origins and unit directions (N, 3)."""
        return rays_in_water(self.port, self.air_rays(uv))

    def project(self, points: np.ndarray) -> np.ndarray:
        """Camera-frame points in water (N, 3) -> raw pixels (N, 2), exact."""
        air = air_rays_to(self.port, points)
        return self.lens.normalized_to_pixels(air[:, :2] / air[:, 2:3])

    def project_pose(self, plane_points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
        """Points of a board (N, 3, board frame) seen from a pose -> raw pixels (N, 2)."""
        R, _ = cv2.Rodrigues(np.asarray(rvec, float))
        return self.project(np.asarray(plane_points, float).reshape(-1, 3) @ R.T + np.asarray(tvec, float).ravel())

    def plane_hits(self, uv: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
        """Raw pixels (N, 2) -> where their rays meet the plane z = 0 of the pose, in its (x, y) metres."""
        origins, directions = self.back_project(uv)
        R, _ = cv2.Rodrigues(np.asarray(rvec, float))
        t = np.asarray(tvec, float).ravel()
        normal = R[:, 2]
        depth = ((t - origins) @ normal) / (directions @ normal)
        return ((origins + directions * depth[:, None] - t) @ R)[:, :2]


def estimate_pose(camera: FlatPortCamera, plane_points: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, ...]:
    """The pose (rvec, tvec) of a plane whose points (N, 2 or 3, z = 0) were seen at raw `pixels`, through the
    port: a pinhole start (the lens's focal length times the water index, the paraxial effect of the port),
    refined by least squares on the exact projection. Needs 4 or more points."""
    plane_points = np.asarray(plane_points, float).reshape(len(pixels), -1)
    if plane_points.shape[1] == 2:
        plane_points = np.column_stack([plane_points, np.zeros(len(plane_points))])
    pixels = np.asarray(pixels, float).reshape(-1, 2)
    if len(pixels) < 4:
        raise PortError(f"a plane's pose needs 4 or more targets, got {len(pixels)}")
    lens = camera.lens
    ideal = lens.pixels_to_normalized(pixels)
    K = np.diag([camera.port.water_index, camera.port.water_index, 1.0])  # on normalized coordinates
    ok, rvec, tvec = cv2.solvePnP(plane_points, ideal.reshape(-1, 1, 2), K, None, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise PortError("no pose for the targets")

    def residual(x: np.ndarray) -> np.ndarray:
        return (camera.project_pose(plane_points, x[:3], x[3:]) - pixels).ravel()

    fit = least_squares(residual, np.concatenate([rvec.ravel(), tvec.ravel()]), method="lm", x_scale="jac")
    return fit.x[:3].copy(), fit.x[3:].copy()


def absorbed_camera(camera: FlatPortCamera, rvec: np.ndarray, tvec: np.ndarray, samples: int = 25,
                    box: tuple[float, float, float, float] | None = None,
                    more_tvecs: tuple[np.ndarray, ...] = ()) -> tuple[BrownCamera, float]:
    """The camera of the lens's model (plumb_bob for most) that images the plane z = 0 of this pose as the lens
    behind the port does: what an underwater calibration at this plane would absorb into its coefficients,
    for ROS tools that know no port
    and for measuring with the existing pipeline. Fitted on a grid of pixels over the image, or over `box`
    (u0, v0, u1, v1 raw px: where the measurement is, since five coefficients cannot follow refraction at
    the corners of a wide lens as well), on this plane and on the parallel planes at `more_tvecs` (the
    targets' and the object's, when they differ); returns the camera and its largest residual in pixels."""
    width, height = camera.image_size
    u0, v0, u1, v1 = box if box is not None else (0, 0, width - 1, height - 1)
    u, v = np.meshgrid(np.linspace(u0, u1, samples), np.linspace(v0, v1, samples))
    pixels = np.column_stack([u.ravel(), v.ravel()])
    planes = []
    for translation in (tvec, *more_tvecs):
        hits = camera.plane_hits(pixels, rvec, translation)
        planes.append((np.column_stack([hits, np.zeros(len(hits))]), np.asarray(translation, float)))
    lens, n_w = camera.lens, camera.port.water_index
    start = replace(lens, c=lens.c * n_w)

    names = MODEL_DIST_NAMES[lens.model]

    def model(x: np.ndarray) -> BrownCamera:
        return BrownCamera(width, height, x[0], x[1], x[2], x[3], model=lens.model,
                           **dict(zip(names, map(float, x[4:4 + len(names)]), strict=True)))

    # x[9]: the stand-in pinhole's place along the optical axis. Through a port the planes look as if seen
    # from about distance * (n - 1) farther back; a pinhole held at the lens would scale a second plane's
    # footprint wrongly (0.5 % for a 5 cm plane offset at 0.4 m behind a 2 cm port)
    # (with one plane it trades off with c alone: held at its paraxial value)
    paraxial_shift = camera.port.distance * (n_w - 1)

    def residual(x: np.ndarray) -> np.ndarray:
        candidate = model(x)
        shift = np.array([0.0, 0.0, x[4 + len(names)] if len(x) > 4 + len(names) else paraxial_shift])
        return np.concatenate([(candidate.project(points, rvec, t + shift) - pixels).ravel()
                               for points, t in planes])

    x0 = np.array([start.c, start.xp, start.yp, start.aspect, *[getattr(start, name) for name in names],
                   *([paraxial_shift] if more_tvecs else [])])
    fit = least_squares(residual, x0, method="lm", x_scale="jac")
    absorbed = model(fit.x)
    return absorbed, float(np.max(np.hypot(*residual(fit.x).reshape(-1, 2).T)))


@dataclass
class PortFit:
    """A port fitted from underwater board views with the lens held at its air calibration."""

    port: FlatPort
    std: dict[str, float]  # one standard deviation of each fitted parameter, by name (metres, radians, index)
    fitted: tuple[str, ...]
    rms_px: float
    view_rms_px: list[float]
    poses: list[tuple[np.ndarray, np.ndarray]]


PORT_PARAMETERS = ("tilt_x_rad", "tilt_y_rad", "distance", "water_index")


def fit_port(lens: BrownCamera, views: list[tuple[np.ndarray, np.ndarray]], start: FlatPort,
             fit_water_index: bool = False, lens_covariance: np.ndarray | None = None) -> PortFit:
    """The port's normal (two tilts) and distance (and the water's index if asked) from underwater views of a
    board, each (board points (N, 3), raw pixels (N, 2)), with the lens fixed at its air calibration and the
    glass (thickness, index) as given in `start`: one least-squares adjustment of the port and every view's
    pose on the exact projection. The standard deviations come from the Jacobian at the solution, scaled by
    the residual's variance, plus what the air calibration's own uncertainty (`lens_covariance`, 9x9 in
    PARAM_NAMES order) moves the port by (first order: the solution's sensitivity to each lens parameter).
    Without it the lens counts as exact and the port's std is too small (a 3 σ miss on a DSLR render)."""
    if len(views) < 2:
        raise PortError(f"a port fit needs 2 or more underwater views, got {len(views)}")
    names = PORT_PARAMETERS if fit_water_index else PORT_PARAMETERS[:3]
    poses = [estimate_pose(FlatPortCamera(lens, start), points[:, :2], pixels) for points, pixels in views]

    # the distance as its logarithm: positive by construction, and a step is a share of it (a 5 mm port is
    # as well conditioned as a 30 mm one)
    def port_of(x: np.ndarray) -> FlatPort:
        values = {name: float(value) for name, value in zip(names, x, strict=False)}
        values["distance"] = float(np.exp(values["distance"]))
        return replace(start, **values)

    def residual(x: np.ndarray, seen_by: BrownCamera = lens) -> np.ndarray:
        try:
            camera = FlatPortCamera(seen_by, port_of(x[:len(names)]))
        except PortError:
            return np.full(sum(2 * len(p) for _, p in views), 1e3)
        out = []
        for k, (points, pixels) in enumerate(views):
            pose = x[len(names) + 6 * k:len(names) + 6 * (k + 1)]
            out.append((camera.project_pose(points, pose[:3], pose[3:]) - pixels).ravel())
        return np.concatenate(out)

    first = [np.log(start.distance) if name == "distance" else getattr(start, name) for name in names]
    x0 = np.concatenate([first, *[np.concatenate(p) for p in poses]])
    fit = least_squares(residual, x0, method="lm", x_scale="jac")
    dof = max(len(fit.fun) - len(fit.x), 1)
    variance = float(fit.fun @ fit.fun) / dof
    normal_inverse = np.linalg.pinv(fit.jac.T @ fit.jac)
    covariance = normal_inverse * variance
    if lens_covariance is not None:  # x moves by -(J^T J)^-1 J^T dr/dlens per unit of each lens parameter
        theta = np.array([lens.fx, lens.fy, lens.xp, lens.yp, *lens.dist])
        steps = np.sqrt(np.clip(np.diag(lens_covariance), 0, None))
        sensitivity = np.zeros((len(fit.x), len(theta)))
        for j, step in enumerate(steps):
            if step <= 0:
                continue
            moved = [theta + sign * step * np.eye(len(theta))[j] for sign in (1, -1)]
            plus, minus = (residual(fit.x, lens.with_parameters(values)) for values in moved)
            derivative = (plus - minus) / (2 * step)
            sensitivity[:, j] = -normal_inverse @ (fit.jac.T @ derivative)
        covariance = covariance + sensitivity @ lens_covariance @ sensitivity.T
    std = {name: float(np.sqrt(covariance[k, k])) for k, name in enumerate(names)}
    std["distance"] *= float(np.exp(fit.x[names.index("distance")]))  # d(distance) = distance * d(log distance)
    errors = np.hypot(*fit.fun.reshape(-1, 2).T)
    view_rms, at = [], 0
    for _, pixels in views:
        view_rms.append(float(np.sqrt(np.mean(errors[at:at + len(pixels)] ** 2))))
        at += len(pixels)
    fitted_poses = [(fit.x[len(names) + 6 * k:len(names) + 6 * k + 3].copy(),
                     fit.x[len(names) + 6 * k + 3:len(names) + 6 * (k + 1)].copy()) for k in range(len(views))]
    return PortFit(port_of(fit.x[:len(names)]), std, names, float(np.sqrt(np.mean(errors**2))), view_rms,
                   fitted_poses)


PORT_KEY = "flat_port"  # the block in a calibration file's veg_area_ros metadata


def port_to_dict(camera: FlatPortCamera, std: dict[str, float] | None = None,
                 absorbed_at_m: float | None = None, lens_covariance: dict | None = None) -> dict:
    """The lens and port as our own block of a camera_info YAML (the standard fields carry the absorbed
    plumb_bob equivalent for ROS tools). `lens_covariance`: the air calibration's `camera_covariance`, kept
    beside the lens so that measuring carries it to Af's std."""
    port, lens = camera.port, camera.lens
    block = {"distance_m": port.distance, "thickness_m": port.thickness, "glass_index": port.glass_index,
             "water_index": port.water_index, "tilt_x_deg": float(np.degrees(port.tilt_x_rad)),
             "tilt_y_deg": float(np.degrees(port.tilt_y_rad)),
             "lens": {"distortion_model": lens.model,
                      "camera_matrix": [float(v) for v in lens.camera_matrix.ravel()],
                      "distortion_coefficients": [float(v) for v in lens.dist]}}
    if lens_covariance is not None:
        block["lens"]["camera_covariance"] = lens_covariance
    if std:
        block["std"] = {name: float(value) for name, value in std.items()}
    if absorbed_at_m is not None:
        block["absorbed_at_m"] = float(absorbed_at_m)
    return block


def port_from_dict(block: object, image_size: tuple[int, int]) -> FlatPortCamera:
    """The FlatPortCamera of a `port_to_dict` block; PortError with the reason for anything else."""
    if not isinstance(block, dict) or not isinstance(block.get("lens"), dict):
        raise PortError(f"'{PORT_KEY}' must be a mapping with the port's numbers and its 'lens'")
    try:
        # files written before the lens's model was recorded hold plumb_bob lenses only
        lens = BrownCamera.from_opencv(np.array(block["lens"]["camera_matrix"], float).reshape(3, 3),
                                       np.array(block["lens"]["distortion_coefficients"], float), image_size,
                                       str(block["lens"].get("distortion_model", "plumb_bob")))
        port = FlatPort(float(block["distance_m"]), float(block["water_index"]), float(block["thickness_m"]),
                        float(block["glass_index"]), float(np.radians(block.get("tilt_x_deg", 0.0))),
                        float(np.radians(block.get("tilt_y_deg", 0.0))))
    except (KeyError, TypeError, ValueError) as exc:
        raise PortError(f"'{PORT_KEY}' is incomplete or not numbers ({exc})") from exc
    return FlatPortCamera(lens, port)


@dataclass(frozen=True, eq=False)
class PortUncertainty:
    """What a port file records of its own uncertainty: each fitted port parameter's std (none for a port as
    measured) and the air calibration's covariance (none where the lens file recorded none)."""

    port_std: dict[str, float]
    lens_covariance: CameraCovariance | None

    @property
    def recorded(self) -> bool:
        return bool(self.port_std) or self.lens_covariance is not None


def port_uncertainty_from_dict(block: dict, lens: BrownCamera) -> PortUncertainty:
    """The `PortUncertainty` of a `port_to_dict` block for its `lens`; PortError where it is not readable."""
    std = block.get("std") or {}
    if not isinstance(std, dict) or any(name not in PORT_PARAMETERS for name in std):
        raise PortError(f"'{PORT_KEY}' std must map port parameters ({', '.join(PORT_PARAMETERS)}) to numbers")
    try:
        port_std = {str(name): float(value) for name, value in std.items()}
        covariance = CameraCovariance.from_conditions(block["lens"], lens)
    except (TypeError, ValueError) as exc:
        raise PortError(f"'{PORT_KEY}' uncertainty is not readable ({exc})") from exc
    if not all(np.isfinite(v) and v >= 0 for v in port_std.values()):
        raise PortError(f"'{PORT_KEY}' std must be finite and not negative")
    return PortUncertainty(port_std, covariance)


def absorbed_at_distance(camera: FlatPortCamera, distance_m: float) -> tuple[BrownCamera, float]:
    """The absorbed plumb_bob equivalent (`absorbed_camera`) for a plane facing the camera `distance_m` in front
    of the projection centre: what camera_info carries for ROS tools that know only plumb_bob."""
    return absorbed_camera(camera, np.zeros(3), np.array([0.0, 0.0, distance_m]))
