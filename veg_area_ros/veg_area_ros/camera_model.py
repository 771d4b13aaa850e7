"""The camera models: a pinhole with the Brown distortion (principal distance, principal point, K1 K2 K3, P1 P2,
pixel aspect) and ROS's two other distortion models, each with its forward and inverse mapping.

No ROS here. Conventions: pixel coordinates (u, v) with the origin at the centre of the top-left pixel,
u right, v down (as OpenCV and ROS). The model maps an ideal pinhole ray (x, y) = (X/Z, Y/Z) to a
distorted pixel; `plumb_bob` (the Brown model, the default):

    r² = x² + y²
    x_d = x (1 + K1 r² + K2 r⁴ + K3 r⁶) + 2 P1 x y + P2 (r² + 2 x²)
    y_d = y (1 + K1 r² + K2 r⁴ + K3 r⁶) + P1 (r² + 2 y²) + 2 P2 x y
    u = xp + c · x_d,     v = yp + c · aspect · y_d

which is OpenCV's pinhole + ``plumb_bob`` with fx = c, fy = c · aspect, (cx, cy) = (xp, yp), and the
same five coefficients, so the conversion both ways is exact. Under water the refraction at a flat port
is absorbed into K1..P2, as in the self-calibration method this package follows.

Calibrations made elsewhere use other conventions: PhotoModeler-style parameters are metric (mm) and
correct *measured* (distorted) coordinates towards ideal ones, the opposite direction; they are refitted
here by least squares and the refit residual is reported in pixels.

ROS's (and OpenCV's) other two models:

    rational_polynomial (wide lenses): the radial factor (1 + K1 r² + K2 r⁴ + K3 r⁶) / (1 + K4 r² + K5 r⁴ + K6 r⁶),
        the same tangential terms; coefficients (k1, k2, p1, p2, k3, k4, k5, k6)
    equidistant (fisheye, OpenCV's cv2.fisheye): θ = atan r, θ_d = θ (1 + K1 θ² + K2 θ⁴ + K3 θ⁶ + K4 θ⁸),
        (x_d, y_d) = (θ_d / r) (x, y); coefficients (k1, k2, k3, k4). With every K zero it is r_d = θ, not a
        pinhole's tan θ: a ray 60° off the axis lands 1.05 f from the centre, not 1.73 f.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import cached_property

import cv2
import numpy as np
from scipy.optimize import least_squares

DIST_NAMES = ("k1", "k2", "p1", "p2", "k3")  # plumb_bob order
PARAM_NAMES = ("fx", "fy", "cx", "cy", *DIST_NAMES)  # OpenCV's names, the order calibration fits them
# each model's coefficients in camera_info's (and OpenCV's) order
MODEL_DIST_NAMES = {
    "plumb_bob": DIST_NAMES,
    "rational_polynomial": (*DIST_NAMES, "k4", "k5", "k6"),
    "equidistant": ("k1", "k2", "k3", "k4"),
}
MODELS = tuple(MODEL_DIST_NAMES)
SMALL_RADIUS = 1e-8  # normalized: below it the equidistant factor θ_d / r is taken at its limit, 1


def param_names(model: str = "plumb_bob") -> tuple[str, ...]:
    """A model's parameters by OpenCV's names, in the order calibration fits them: fx fy cx cy, then its
    distortion coefficients in camera_info's order."""
    return ("fx", "fy", "cx", "cy", *MODEL_DIST_NAMES[model])
NEWTON_TOLERANCE = 1e-14  # normalized units: ~1e-11 px, the inverse distortion's round trip


def distort(xy: np.ndarray, k1: float, k2: float, p1: float, p2: float, k3: float) -> np.ndarray:
    """The Brown model: ideal normalized coordinates (N, 2) -> distorted normalized coordinates (N, 2)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([xd, yd])


def distort_model(xy: np.ndarray, model: str, dist: np.ndarray) -> np.ndarray:
    """Any model's distortion: ideal normalized coordinates (N, 2) -> distorted ones (N, 2); `dist` in the
    model's camera_info order (MODEL_DIST_NAMES)."""
    if model == "plumb_bob":
        return distort(xy, *dist)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    x, y = xy[:, 0], xy[:, 1]
    if model == "rational_polynomial":
        k1, k2, p1, p2, k3, k4, k5, k6 = dist
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.column_stack([xd, yd])
    scale, _ = _equidistant_scale(x, y, dist)
    return np.column_stack([x * scale, y * scale])


def _equidistant_scale(x: np.ndarray, y: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The equidistant model's factor s = θ_d / r and (ds/dr) / r, the two numbers its mapping and Jacobian
    need; both at their limits near the axis (s -> 1, (ds/dr) / r -> 2 (K1 - 1/3))."""
    k1, k2, k3, k4 = dist
    r2 = x * x + y * y
    r = np.sqrt(r2)
    theta = np.arctan(r)
    t2 = theta * theta
    theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    dtheta_d = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
    near = r < SMALL_RADIUS
    safe_r = np.where(near, 1.0, r)
    scale = np.where(near, 1.0, theta_d / safe_r)
    slope = np.where(near, 2 * (k1 - 1 / 3), (dtheta_d / (1 + r2) - scale) / (safe_r * safe_r))
    return scale, slope


def distortion_jacobian(xy: np.ndarray, model: str, dist: np.ndarray) -> tuple[np.ndarray, ...]:
    """d(x_d, y_d)/d(x, y) of any model as the four entries (dxd/dx, dxd/dy, dyd/dx, dyd/dy)."""
    x, y = xy[:, 0], xy[:, 1]
    if model == "equidistant":
        scale, slope = _equidistant_scale(x, y, dist)
        cross = x * y * slope
        return scale + x * x * slope, cross, cross, scale + y * y * slope
    r2 = x * x + y * y
    if model == "plumb_bob":
        k1, k2, p1, p2, k3 = dist
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial_dr2 = k1 + r2 * (2 * k2 + 3 * r2 * k3)
    else:
        k1, k2, p1, p2, k3, k4, k5, k6 = dist
        numerator = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        denominator = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        radial = numerator / denominator
        dradial_dr2 = ((k1 + r2 * (2 * k2 + 3 * r2 * k3)) * denominator
                       - numerator * (k4 + r2 * (2 * k5 + 3 * r2 * k6))) / denominator**2
    dxd_dx = radial + 2 * x * x * dradial_dr2 + 2 * p1 * y + 6 * p2 * x
    dxd_dy = 2 * x * y * dradial_dr2 + 2 * p1 * x + 2 * p2 * y
    dyd_dx = 2 * x * y * dradial_dr2 + 2 * p1 * x + 2 * p2 * y
    dyd_dy = radial + 2 * y * y * dradial_dr2 + 6 * p1 * y + 2 * p2 * x
    return dxd_dx, dxd_dy, dyd_dx, dyd_dy


@dataclass(frozen=True)
class BrownCamera:
    """A calibrated camera of any of MODELS (plumb_bob, the Brown model, by default). Pixel units for c, xp, yp;
    K and P act on ideal normalized coordinates; k4-k6 only in rational_polynomial, k4 also in equidistant,
    which has no P."""

    width: int
    height: int
    c: float  # principal distance, pixels (horizontal)
    xp: float  # principal point, pixels
    yp: float
    aspect: float = 1.0  # fy / fx; 1 for square pixels
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k4: float = 0.0
    k5: float = 0.0
    k6: float = 0.0
    model: str = "plumb_bob"

    def __post_init__(self) -> None:
        if self.model not in MODEL_DIST_NAMES:
            raise ValueError(f"unknown distortion model {self.model!r} (known: {', '.join(MODELS)})")
        unused = sorted(set(("k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2")) - set(MODEL_DIST_NAMES[self.model]))
        if any(getattr(self, name) != 0 for name in unused):
            raise ValueError(f"{self.model} has no {', '.join(n for n in unused if getattr(self, n) != 0)}")
        values = np.array([self.c, self.xp, self.yp, self.aspect, *self.dist], dtype=float)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"camera parameters must be finite, got {self}")
        if self.c <= 0 or self.aspect <= 0:
            raise ValueError(f"principal distance and aspect must be positive (c={self.c}, aspect={self.aspect})")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")

    # --- OpenCV / ROS camera_info -------------------------------------------------------------------
    @property
    def fx(self) -> float:
        return self.c

    @property
    def fy(self) -> float:
        return self.c * self.aspect

    @property
    def dist(self) -> np.ndarray:
        """Distortion coefficients in the model's camera_info order: plumb_bob (k1, k2, p1, p2, k3),
        rational_polynomial (k1, k2, p1, p2, k3, k4, k5, k6), equidistant (k1, k2, k3, k4)."""
        return np.array([getattr(self, name) for name in MODEL_DIST_NAMES[self.model]], dtype=float)

    @property
    def pinhole(self) -> bool:
        """Whether OpenCV's pinhole functions (projectPoints, undistortPoints, ...) take this model."""
        return self.model != "equidistant"

    @property
    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.xp], [0.0, self.fy, self.yp], [0.0, 0.0, 1.0]])

    @property
    def image_size(self) -> tuple[int, int]:
        """(width, height), the order OpenCV functions take."""
        return (self.width, self.height)

    @classmethod
    def from_opencv(cls, camera_matrix: np.ndarray, dist: np.ndarray, image_size: tuple[int, int],
                    model: str = "plumb_bob") -> BrownCamera:
        """Exact conversion from OpenCV's K and a model's coefficients (plumb_bob: 4, 5, or more with the rest
        zero; rational_polynomial: up to 8; equidistant: 4). Skew must be zero."""
        K = np.asarray(camera_matrix, dtype=float).reshape(3, 3)
        given = np.asarray(dist, dtype=float).ravel()
        names = MODEL_DIST_NAMES.get(model)
        if names is None:
            raise ValueError(f"unknown distortion model {model!r} (known: {', '.join(MODELS)})")
        if model == "plumb_bob":
            if given.size not in (4, 5, 8, 12, 14) or (given.size > 5 and np.any(given[5:] != 0)):
                raise ValueError(f"plumb_bob has five coefficients (k1, k2, p1, p2[, k3]), got {given.size}")
        elif model == "rational_polynomial":
            if given.size not in (4, 5, 8, 12, 14) or (given.size > 8 and np.any(given[8:] != 0)):
                raise ValueError(f"rational_polynomial has eight coefficients (k1, k2, p1, p2, k3, k4, k5, k6), "
                                 f"got {given.size}")
        elif given.size != 4:
            raise ValueError(f"equidistant has four coefficients (k1, k2, k3, k4), got {given.size}")
        d = np.zeros(len(names))
        d[: min(len(names), given.size)] = given[: len(names)]
        if abs(K[0, 1]) > 1e-9 * abs(K[0, 0]):
            raise ValueError("camera matrix has skew; the Brown model here has none")
        width, height = image_size
        return cls(width=int(width), height=int(height), c=K[0, 0], xp=K[0, 2], yp=K[1, 2],
                   aspect=K[1, 1] / K[0, 0], model=model, **dict(zip(names, map(float, d), strict=True)))

    def to_opencv(self) -> tuple[np.ndarray, np.ndarray]:
        return self.camera_matrix, self.dist

    @property
    def param_names(self) -> tuple[str, ...]:
        return param_names(self.model)

    def parameters(self) -> dict[str, float]:
        """The parameters by OpenCV's names (`param_names`: nine for plumb_bob), as the calibration reports them."""
        values = [self.fx, self.fy, self.xp, self.yp, *self.dist]
        return {name: float(v) for name, v in zip(self.param_names, values, strict=True)}

    def with_parameters(self, values: np.ndarray) -> BrownCamera:
        """This model with other parameters, in `parameters()`' order (fx, fy, cx, cy, then the distortion's;
        values past them are not read)."""
        n = len(self.param_names)
        matrix = np.array([[values[0], 0.0, values[2]], [0.0, values[1], values[3]], [0.0, 0.0, 1.0]])
        return BrownCamera.from_opencv(matrix, np.asarray(values[4:n], float), self.image_size, self.model)

    def ideal(self) -> BrownCamera:
        """The idealized camera: no distortion, square pixels (scale of the horizontal axis), principal point
        at the image centre. Frames remapped to it can be measured with a single scale."""
        return BrownCamera(self.width, self.height, self.c, (self.width - 1) / 2, (self.height - 1) / 2)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    # --- projection ---------------------------------------------------------------------------------
    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Ideal normalized coordinates (N, 2) -> distorted normalized coordinates (N, 2)."""
        return distort_model(xy, self.model, self.dist)

    def normalized_to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """Ideal normalized coordinates -> distorted pixels."""
        d = self.distort_normalized(xy)
        return np.column_stack([self.xp + self.fx * d[:, 0], self.yp + self.fy * d[:, 1]])

    def pixels_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels -> ideal normalized coordinates: OpenCV's fixed-point start, then Newton steps so
        the round trip is exact to ~1e-10 px even with strong barrel distortion."""
        # contiguous: OpenCV 5's cv2.fisheye reads a strided view's rows wrongly (a GoPro's ROI sampled every
        # other pixel came back up to 2.7 normalized units off)
        uv = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
        target = np.column_stack([(uv[:, 0] - self.xp) / self.fx, (uv[:, 1] - self.yp) / self.fy])
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
        if self.pinhole:
            xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), self.camera_matrix, self.dist, criteria=criteria)
        else:
            xy = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), self.camera_matrix, self.dist, criteria=criteria)
        xy = self._newton(xy.reshape(-1, 2).copy(), target)
        if self.reach is not None:  # a solution past the fold is another branch's: start again inside it
            astray = np.flatnonzero(~self.rays_within_reach(xy))
            if len(astray):
                xy[astray] = self._newton(self._radial_start(target[astray]), target[astray])
        return xy

    def _radial_start(self, target: np.ndarray) -> np.ndarray:
        """Ideal rays for distorted ones, the radius bisected inside the model's reach along the distorted
        direction (tangential terms aside): a start on the right branch for Newton's steps."""
        radius = np.hypot(*target.T)
        direction = target / np.maximum(radius, 1e-300)[:, None]
        low, high = np.zeros(len(target)), np.full(len(target), self.reach[0])
        for _ in range(60):
            middle = (low + high) / 2
            below = np.hypot(*self.distort_normalized(middle[:, None] * direction).T) < radius
            low, high = np.where(below, middle, low), np.where(below, high, middle)
        return (low + high)[:, None] / 2 * direction

    def _newton(self, xy: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Newton steps on distort(xy) = target, in place, each point until it is within NEWTON_TOLERANCE (or
        eight steps): a point's result depends on it alone, not on the others computed with it."""
        active = np.arange(len(xy))
        for _ in range(8):
            here = xy[active]
            error = self.distort_normalized(here) - target[active]
            moving = ~(np.max(np.abs(error), axis=1, initial=0.0) < NEWTON_TOLERANCE)
            if not moving.any():
                break
            active, here, error = active[moving], here[moving], error[moving]
            a, b, c, d = self._distortion_jacobian(here)
            det = a * d - b * c
            here[:, 0] -= (d * error[:, 0] - b * error[:, 1]) / det
            here[:, 1] -= (a * error[:, 1] - c * error[:, 0]) / det
            xy[active] = here
        return xy

    def pixels_to_ideal(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw pixels (N, 2) -> their position in the idealized image (N, 2) and the idealized-image area that
        each raw pixel covers (N,), from the analytic Jacobian of the distortion (no finite differences)."""
        xy = self.pixels_to_normalized(uv)
        ideal = self.ideal()
        a, b, c, d = self._distortion_jacobian(xy)
        # d(raw px)/d(ideal px) = diag(fx, fy) . D . (1 / c); its inverse determinant is the area ratio
        area = ideal.c**2 / (self.fx * self.fy * np.abs(a * d - b * c))
        return ideal.normalized_to_pixels(xy), area

    def _distortion_jacobian(self, xy: np.ndarray) -> tuple[np.ndarray, ...]:
        """d(x_d, y_d)/d(x, y) as the four entries (dxd/dx, dxd/dy, dyd/dx, dyd/dy)."""
        return distortion_jacobian(xy, self.model, self.dist)

    @cached_property
    def reach(self) -> tuple[float, float] | None:
        """Where the model stops being one-to-one inside the image (`model_reach`); None: nowhere."""
        return model_reach(self)

    def reach_px(self) -> float | None:
        """The distorted radius the model holds to, in pixels along the principal distance; None: everywhere."""
        return None if self.reach is None else self.reach[1] * self.fx

    def within_reach(self, uv: np.ndarray) -> np.ndarray:
        """Which raw pixels (N, 2) the model gives a trustworthy ray (`reach`): all of them for most lenses."""
        uv = np.asarray(uv, float).reshape(-1, 2)
        if self.reach is None:
            return np.ones(len(uv), bool)
        return np.hypot((uv[:, 0] - self.xp) / self.fx, (uv[:, 1] - self.yp) / self.fy) < self.reach[1]

    def holds_everywhere(self) -> bool:
        """Whether every pixel of the image has its ray (the model folds, if at all, beyond the image)."""
        corners = np.array([[0.0, 0.0], [self.width - 1, 0.0], [0.0, self.height - 1],
                            [self.width - 1, self.height - 1]])
        return bool(np.all(self.within_reach(corners)))

    def rays_within_reach(self, xy: np.ndarray) -> np.ndarray:
        """Which ideal normalized rays (N, 2) lie inside the model's reach (all of them for most lenses)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        if self.reach is None:
            return np.ones(len(xy), bool)
        return np.hypot(xy[:, 0], xy[:, 1]) < self.reach[0]

    def project(self, points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
        """3-D points in a board frame seen from a pose -> distorted pixels (N, 2)."""
        if not self.pinhole:
            uv, _ = cv2.fisheye.projectPoints(np.ascontiguousarray(np.asarray(points, float).reshape(-1, 1, 3)),
                                              np.ravel(rvec).astype(float),
                                              np.ravel(tvec).astype(float), self.camera_matrix, self.dist)
            return uv.reshape(-1, 2)
        uv, _ = cv2.projectPoints(np.asarray(points, float).reshape(-1, 1, 3), rvec, tvec, *self.to_opencv())
        return uv.reshape(-1, 2)


MIN_REACH = 0.5  # a model that folds nearer the centre than this share of the half-diagonal is no lens's
MAX_FIELD_SCALE = 3.0  # ideal vs distorted radius over the image: beyond a factor 3 no lens here, a corrupt model
MIN_FOCAL_SCALE, MAX_FOCAL_SCALE = 0.05, 50.0  # principal distance in image widths: fisheye to long telephoto


FOLD_DIRECTIONS = 72
FOLD_STEPS = 400


def model_reach(camera: BrownCamera) -> tuple[float, float] | None:
    """Where a model stops being one-to-one: (ideal radius, distorted radius), both normalized; the distorted one
    may lie beyond the image (every pixel has its ray, but rays beyond the ideal radius are no pixel's). Along
    every direction from the principal point the mapping is followed outward (ray angles up to the field scale's
    limit) until it folds (its Jacobian turns); the smallest ideal radius where one does, and
    the smallest distorted radius the circle there reaches. Raw pixels farther out than the distorted radius
    (and ideal ones beyond the ideal radius) have no trustworthy ray. None: it holds over the whole image. A
    polynomial fitted to a wide lens bends back beyond the board's reach; inside it, it is as good as any."""
    if camera.pinhole and not np.any(camera.dist):  # no distortion (an ideal camera): the identity never folds
        return None
    width, height = camera.image_size
    corners = np.array([[0.0, 0.0], [width - 1, 0.0], [0.0, height - 1], [width - 1, height - 1]])
    image_reach = float(np.max(np.hypot((corners[:, 0] - camera.xp) / camera.fx,
                                        (corners[:, 1] - camera.yp) / camera.fy)))
    if camera.model == "equidistant":
        top = min(np.pi / 2 - 1e-3, MAX_FIELD_SCALE * image_reach)
    else:
        top = float(np.arctan(MAX_FIELD_SCALE * image_reach))
    angles = np.linspace(0.0, 2 * np.pi, FOLD_DIRECTIONS, endpoint=False)
    radii = np.tan(np.linspace(0.0, top, FOLD_STEPS + 1)[1:])
    rays = (radii[None, :, None] * np.stack([np.cos(angles), np.sin(angles)], axis=1)[:, None, :]).reshape(-1, 2)
    with np.errstate(all="ignore"):
        a, b, c, d = camera._distortion_jacobian(rays)
        distorted = np.hypot(*camera.distort_normalized(rays).T).reshape(FOLD_DIRECTIONS, FOLD_STEPS)
    folds = ~((a * d - b * c) > 0).reshape(FOLD_DIRECTIONS, FOLD_STEPS)
    folds[:, 1:] |= ~(np.diff(distorted, axis=1) > 0)
    if not folds.any():
        return None if distorted[:, -1].min() >= image_reach else (float(radii[-1]), float(distorted[:, -1].min()))
    first = np.where(folds.any(axis=1), folds.argmax(axis=1), FOLD_STEPS)
    last_good = max(int(first.min()) - 1, 0)
    ideal_reach = float(radii[last_good])
    circle = ideal_reach * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    distorted_reach = float(np.hypot(*camera.distort_normalized(circle).T).min())
    # a fold beyond the image still matters: rays past it land in the image a second time (a rational model's pole)
    return ideal_reach, distorted_reach


def implausibility(camera: BrownCamera, samples: int = 25, covered: np.ndarray | None = None) -> str | None:
    """Why this camera model cannot be a real lens-and-port calibration, or None. A model is refused when its
    principal distance or point is absurd for its image, or when its distortion is not one-to-one over the
    image (the Jacobian folds, or a pixel has no ideal ray) or stretches the field by more than
    MAX_FIELD_SCALE: such a model (k1 = 1e6, say) would idealize frames into nonsense without an error.
    With `covered` (pixels, N x 2) only the part of the image inside their hull is asked to be one-to-one."""
    width, height = camera.image_size
    if not MIN_FOCAL_SCALE * width <= camera.fx <= MAX_FOCAL_SCALE * width:
        return f"principal distance {camera.fx:.6g} px is absurd for an image {width} px wide"
    if not 0.25 <= camera.aspect <= 4.0:
        return f"pixel aspect fy/fx = {camera.aspect:.6g} is absurd"
    if not (-0.5 * width <= camera.xp <= 1.5 * width and -0.5 * height <= camera.yp <= 1.5 * height):
        return f"principal point ({camera.xp:.6g}, {camera.yp:.6g}) px is far outside the {width}x{height} image"
    u, v = np.meshgrid(np.linspace(0, width - 1, samples), np.linspace(0, height - 1, samples))
    raw = np.column_stack([u.ravel(), v.ravel()])
    if covered is not None and len(covered) >= 3:
        raw = np.vstack([inside_hull(raw, covered), cv2.convexHull(covered.astype(np.float32)).reshape(-1, 2)])
    with np.errstate(all="ignore"):
        reach = camera.reach
    if reach is not None:
        half_diagonal = 0.5 * np.hypot(width, height)
        reach_px = camera.reach_px()
        if covered is not None and len(covered) >= 3 and not np.all(camera.within_reach(covered)):
            return (f"its distortion folds over {reach_px:.0f} px from the principal point, inside the region "
                    "its board points cover (not monotonic)")
        if reach_px < MIN_REACH * half_diagonal:
            return (f"its distortion folds over {reach_px:.0f} px from the principal point, less than "
                    f"{MIN_REACH:.0%} of the half-diagonal ({half_diagonal:.0f} px): not monotonic")
        raw = raw[camera.within_reach(raw)]
    with np.errstate(all="ignore"):
        ideal = camera.pixels_to_normalized(raw)
        back = camera.normalized_to_pixels(ideal)
        if not np.all(np.isfinite(back)) or np.max(np.abs(back - raw)) > 1e-3:
            return "its distortion has no inverse over the image (some pixels have no ray): not monotonic"
        # along every ray from the centre to an image pixel the mapping must not fold
        steps = np.linspace(0.0, 1.0, 33)[1:, None, None]
        a, b, c, d = camera._distortion_jacobian((steps * ideal[None]).reshape(-1, 2))
        if np.any(a * d - b * c <= 0):
            return "its distortion folds over inside the image (not monotonic)"
        distorted = np.hypot(*camera.distort_normalized(ideal).T)
        radius = np.hypot(*ideal.T)
        if camera.model == "equidistant":  # its own polynomial on θ (r_d = θ with zero coefficients), not r
            radius = np.arctan(radius)
        far = radius > 1e-6
        ratio = radius[far] / distorted[far]
    if far.any() and not 1 / MAX_FIELD_SCALE <= ratio.min() <= ratio.max() <= MAX_FIELD_SCALE:
        return (f"its distortion scales the field by {ratio.min():.3g}–{ratio.max():.3g}x over the image "
                f"(at most {MAX_FIELD_SCALE:g}x for any lens and port): the coefficients are absurd")
    return None


def inside_hull(points: np.ndarray, hull_of: np.ndarray) -> np.ndarray:
    """The points (N, 2) that lie inside (or on) the convex hull of `hull_of`."""
    hull = cv2.convexHull(np.asarray(hull_of, np.float32).reshape(-1, 2))
    inside = [cv2.pointPolygonTest(hull, (float(u), float(v)), False) >= 0 for u, v in points]
    return points[np.array(inside, bool)]


def check_plausible(camera: BrownCamera) -> BrownCamera:
    """The camera, or ValueError with `implausibility`'s reason."""
    problem = implausibility(camera)
    if problem:
        raise ValueError(f"implausible camera model: {problem}")
    return camera


@dataclass(frozen=True)
class ImportResult:
    """A camera converted from another convention, with how well the conversion fits."""

    camera: BrownCamera
    refit_rms_px: float  # 0 where the conversion is exact
    refit_max_px: float
    notes: list[str] = field(default_factory=list)


def _grid(width: int, height: int, n: int = 41) -> np.ndarray:
    u, v = np.meshgrid(np.linspace(0, width - 1, n), np.linspace(0, height - 1, n))
    return np.column_stack([u.ravel(), v.ravel()])


def fit_forward_distortion(
    distorted_px: np.ndarray, ideal_px: np.ndarray, c: float, aspect: float, xp: float, yp: float,
    width: int, height: int,
) -> ImportResult:
    """Least-squares plumb_bob coefficients mapping ideal pixels to distorted ones, with the residual in px."""
    ideal = np.column_stack([(ideal_px[:, 0] - xp) / c, (ideal_px[:, 1] - yp) / (c * aspect)])

    def residual(d: np.ndarray) -> np.ndarray:
        cam = BrownCamera(width, height, c, xp, yp, aspect, k1=d[0], k2=d[1], p1=d[2], p2=d[3], k3=d[4])
        return (cam.normalized_to_pixels(ideal) - distorted_px).ravel()

    fit = least_squares(residual, np.zeros(5), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    d = fit.x
    camera = BrownCamera(width, height, c, xp, yp, aspect, k1=d[0], k2=d[1], p1=d[2], p2=d[3], k3=d[4])
    err = np.hypot(*residual(d).reshape(-1, 2).T)
    return ImportResult(camera, float(np.sqrt(np.mean(err**2))), float(err.max()))


def from_photomodeler(
    focal_length_mm: float,
    format_width_mm: float,
    principal_point_mm: tuple[float, float],
    image_size: tuple[int, int],
    K1: float = 0.0,
    K2: float = 0.0,
    K3: float = 0.0,
    P1: float = 0.0,
    P2: float = 0.0,
    format_height_mm: float | None = None,
) -> ImportResult:
    """Import PhotoModeler-style parameters (metric, correcting measured coordinates).

    Measured image coordinates in mm relative to the principal point, (x, y) with x right and y down,
    are corrected to ideal ones by
        x_i = x + x (K1 r² + K2 r⁴ + K3 r⁶) + P1 (r² + 2x²) + 2 P2 x y
        y_i = y + y (K1 r² + K2 r⁴ + K3 r⁶) + P2 (r² + 2y²) + 2 P1 x y
    The principal point is given in mm from the top-left corner of the format. Because the correction
    runs from distorted to ideal, the plumb_bob coefficients are refitted over the whole image.
    """
    width, height = image_size
    if min(focal_length_mm, format_width_mm) <= 0:
        raise ValueError("focal length and format width must be positive")
    pixel_w = format_width_mm / width
    pixel_h = (format_height_mm / height) if format_height_mm else pixel_w
    c = focal_length_mm / pixel_w
    aspect = pixel_w / pixel_h
    # pixel centres are at (u + 0.5) * pixel size from the format's top-left corner
    xp = principal_point_mm[0] / pixel_w - 0.5
    yp = principal_point_mm[1] / pixel_h - 0.5
    measured = _grid(width, height)
    x = (measured[:, 0] - xp) * pixel_w
    y = (measured[:, 1] - yp) * pixel_h
    r2 = x * x + y * y
    radial = K1 * r2 + K2 * r2**2 + K3 * r2**3
    xi = x + x * radial + P1 * (r2 + 2 * x * x) + 2 * P2 * x * y
    yi = y + y * radial + P2 * (r2 + 2 * y * y) + 2 * P1 * x * y
    ideal_px = np.column_stack([xi / pixel_w + xp, yi / pixel_h + yp])
    result = fit_forward_distortion(measured, ideal_px, c, aspect, xp, yp, width, height)
    note = "PhotoModeler corrections run distorted->ideal; plumb_bob coefficients refitted over the image"
    return ImportResult(result.camera, result.refit_rms_px, result.refit_max_px, [note])


def from_matlab(
    intrinsic_matrix: np.ndarray,
    radial_distortion: np.ndarray,
    tangential_distortion: np.ndarray,
    image_size: tuple[int, int],
    skew: float = 0.0,
) -> ImportResult:
    """Import MATLAB ``cameraParameters`` values.

    MATLAB's IntrinsicMatrix is K transposed, with 1-based pixel coordinates; ImageSize is [rows, cols];
    RadialDistortion has 2 or 3 terms; the model is the same as OpenCV's, so the conversion is exact
    unless there is skew, which is refitted away and reported.
    """
    M = np.asarray(intrinsic_matrix, dtype=float).reshape(3, 3)
    K = M.T if abs(M[0, 2]) < 1e-12 and abs(M[2, 0]) > 0 else M  # accept K or K'
    radial = np.asarray(radial_distortion, dtype=float).ravel()
    if radial.size not in (2, 3):
        raise ValueError(f"RadialDistortion needs 2 or 3 terms, got {radial.size}")
    k3 = radial[2] if radial.size == 3 else 0.0
    p1, p2 = np.asarray(tangential_distortion, dtype=float).ravel()[:2]
    rows, cols = image_size
    skew = skew or K[0, 1]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2] - 1.0, K[1, 2] - 1.0
    camera = BrownCamera(int(cols), int(rows), fx, cx, cy, fy / fx, radial[0], radial[1], k3, p1, p2)
    if skew == 0:
        return ImportResult(camera, 0.0, 0.0, ["exact: same model as OpenCV, principal point made 0-based"])
    # with skew, u = fx x_d + s y_d + cx: fit a skew-free camera to the skewed one's pixels
    ideal_norm = camera.pixels_to_normalized(_grid(camera.width, camera.height))
    distorted = camera.distort_normalized(ideal_norm)
    measured = np.column_stack([fx * distorted[:, 0] + skew * distorted[:, 1] + cx, fy * distorted[:, 1] + cy])
    ideal_px = np.column_stack([cx + fx * ideal_norm[:, 0], cy + fy * ideal_norm[:, 1]])
    result = fit_forward_distortion(measured, ideal_px, fx, fy / fx, cx, cy, camera.width, camera.height)
    return ImportResult(result.camera, result.refit_rms_px, result.refit_max_px,
                        [f"skew {skew:g} is not in the Brown model here; distortion refitted to absorb it"])
