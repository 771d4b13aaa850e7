"""Self-calibrating bundle adjustment of a camera model (plumb_bob, the Brown model; rational_polynomial;
equidistant) from board views.

No ROS here. OpenCV's calibrateCamera (cv2.fisheye.calibrate for equidistant) gives the starting point; then all
views are refined jointly on the analytic Jacobian (cv2.projectPoints) in a sparse block pattern: the camera
parameters (nine for plumb_bob) touch every residual, each view's six pose parameters only its own. Optional robust
loss and outlier rejection. The result carries what a photogrammetrist reads to judge a calibration:
residuals overall and per view, parameter standard deviations and correlations from the covariance, and
warnings about weak geometry.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from .board import Detection
from .camera_model import MODELS, PARAM_NAMES, BrownCamera, distort_model, implausibility, inside_hull, param_names

MIN_VIEWS = 3  # below this the nine camera parameters cannot be separated from the poses at all
RECOMMENDED_VIEWS = 12
SAME_VIEW_PX = 0.1  # views whose corners lie this close (mean) repeat one another: sensor noise moves them ~0.02
SAME_VIEW_NEAR_PX = 50.0  # a repeat's points' centre lies this close (partial views: a tenth of them may differ)
CORRELATION_WARNING = 0.95
ROTATION_WARNING_DEG = 45.0
# rings of distance from the principal point, as fractions of the half-diagonal: where the mean radial residual
# of a ring is well off zero, the lens bends light in a way K1-K3 and P1, P2 do not follow
RADIAL_RINGS = ((0.0, 0.3), (0.3, 0.5), (0.5, 0.7), (0.7, 0.85), (0.85, 1.5))
RING_MIN_POINTS = 30
SYSTEMATIC_PX = 0.05  # and 5 standard errors: synthetic and real cameras the model fits stay below 0.01 px
RADIAL = {"k1", "k2", "k3", "k4", "k5", "k6"}  # a radial polynomial's terms always go together
MAX_REJECTION_ROUNDS = 5
REPEAT_REASON = "the same view as"  # how a repeat's entry in rejected_views begins
INIT_VIEWS = 40  # views OpenCV's initial estimate is made from (all of a smaller set)


class CalibrationError(RuntimeError):
    """A calibration that cannot be computed from the given views."""


@dataclass(frozen=True)
class View:
    """One image's detections, named for reports."""

    name: str
    detection: Detection


@dataclass
class ViewReport:
    name: str
    points: int
    rms_px: float
    mean_px: float
    max_px: float
    rejected_points: int
    roll_deg: float  # in-image direction of the board's x axis


@dataclass
class CalibrationResult:
    camera: BrownCamera
    std: dict[str, float]  # one standard deviation per parameter, keys the camera's param_names
    correlation: np.ndarray  # (n, n) between the camera's param_names (9 for plumb_bob)
    rms_px: float
    mean_px: float
    max_residual_px: float
    views: list[ViewReport]
    rejected_views: dict[str, str]  # name -> reason
    warnings: list[str]
    opencv_rms_px: float  # OpenCV's initial estimate: calibrateCamera on opencv_rms_views views, every point
    sigma0_px: float  # a posteriori standard deviation of one image coordinate
    iterations: int
    seconds: float
    coverage: float  # fraction of an 8x6 grid over the image that holds detected points
    radial_profile: list[dict] = field(default_factory=list)  # per ring: mean radial residual, rms (radial_profile())
    opencv_rms_views: int = 0  # the views OpenCV's initial estimate used (all of at most INIT_VIEWS)
    converged: bool = True  # every bundle adjustment converged (none stopped at its iteration limit)
    std_covariance: dict[str, float] = field(default_factory=dict)  # from the covariance, corner errors independent
    std_views: dict[str, float] = field(default_factory=dict)  # from resampling views (infinitesimal jackknife)
    halves: dict = field(default_factory=dict)  # two disjoint halves of the views fitted apart (cross-validation)
    projection_std_px: dict = field(default_factory=dict)  # a direction's pixel uncertainty over the image
    model_choice: dict = field(default_factory=dict)  # --model auto: each model's evidence and why one was picked
    poses: list[np.ndarray] = field(repr=False, default_factory=list)  # (rvec, tvec) of each used view, 6 values
    image_points: list[np.ndarray] = field(repr=False, default_factory=list)
    object_points: list[np.ndarray] = field(repr=False, default_factory=list)  # the board points of each used view
    residuals: list[np.ndarray] = field(repr=False, default_factory=list)  # detected - projected, px
    inliers: list[np.ndarray] = field(repr=False, default_factory=list)

    @property
    def views_used(self) -> int:
        return len(self.views)

    def used(self, views: Iterable[View]) -> list[View]:
        """The views of `views` this fit used: not one it rejected (corners it does not trust) nor a repeat of
        one it counted (judged again, it would count twice)."""
        return [view for view in views if view.name not in self.rejected_views]

    @property
    def rejected(self) -> dict[str, str]:
        """The views left out for what they showed (outliers), not the repeats of a view already counted."""
        return {name: why for name, why in self.rejected_views.items() if not why.startswith(REPEAT_REASON)}

    def summary(self) -> dict:
        """Plain numbers for JSON: the CLI's --json output and the calibration file's metadata."""
        cam = self.camera
        names = cam.param_names
        return {
            "distortion_model": cam.model,
            "reach_px": cam.reach_px() if not cam.holds_everywhere() else None,
            "model_choice": dict(self.model_choice),
            "rms_px": self.rms_px,
            "mean_px": self.mean_px,
            "max_residual_px": self.max_residual_px,
            "sigma0_px": self.sigma0_px,
            "opencv_rms_px": self.opencv_rms_px,
            "opencv_rms_views": self.opencv_rms_views,
            "views_used": self.views_used,
            "views_rejected": len(self.rejected),
            "views_repeated": len(self.rejected_views) - len(self.rejected),
            "rejected": dict(self.rejected),
            "points_rejected": int(sum(v.rejected_points for v in self.views)),
            "image_width": cam.width,
            "image_height": cam.height,
            **{k: v for k, v in cam.parameters().items() if k in ("fx", "fy", "cx", "cy")},
            "dist": cam.dist.tolist(),
            "std": dict(self.std),
            "std_covariance": dict(self.std_covariance),
            "std_views": dict(self.std_views),
            "halves": dict(self.halves),
            "projection_std_px": dict(self.projection_std_px),
            "correlations": {f"{names[i]}-{names[j]}": float(self.correlation[i, j])
                             for i in range(len(names)) for j in range(i + 1, len(names))},
            "coverage": self.coverage,
            "radial_profile": [dict(ring) for ring in self.radial_profile],
            "per_view": [vars(v) for v in self.views],
            "warnings": list(self.warnings),
            "iterations": self.iterations,
            "converged": self.converged,
            "seconds": self.seconds,
        }


def _project_with_jacobian(
    intrinsics: np.ndarray, pose: np.ndarray, object_points: np.ndarray, model: str = "plumb_bob",
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (u0, v0, u1, ...) of the points and their Jacobian, columns rvec(3) tvec(3) and then the camera's
    parameters in param_names order."""
    fx, fy, cx, cy = intrinsics[:4]
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    if model == "equidistant":
        uv, jac = cv2.fisheye.projectPoints(np.ascontiguousarray(object_points.reshape(-1, 1, 3)), pose[:3],
                                            pose[3:], K, intrinsics[4:])  # contiguous: as in pixels_to_normalized
        # cv2.fisheye's columns: fx fy cx cy k1-k4 rvec(3) tvec(3) skew
        return uv.reshape(-1), np.hstack([jac[:, 8:14], jac[:, :8]])
    uv, jac = cv2.projectPoints(object_points.reshape(-1, 1, 3), pose[:3], pose[3:], K, intrinsics[4:])
    # jac columns: rvec(3) tvec(3) fx fy cx cy and the coefficients (the same order as param_names)
    return uv.reshape(-1), jac


class _Problem:
    """Residuals and the sparse Jacobian over [the camera's parameters, 6 per view]."""

    def __init__(self, object_points: list[np.ndarray], image_points: list[np.ndarray], model: str = "plumb_bob"):
        self.model = model
        self.n = len(param_names(model))
        self.object_points = object_points
        self.observed = np.concatenate([p.reshape(-1) for p in image_points])
        self.counts = [len(p) for p in object_points]
        self.row_starts = np.concatenate([[0], np.cumsum(self.counts) * 2])
        rows, cols = [], []
        for v, count in enumerate(self.counts):
            r = np.arange(self.row_starts[v], self.row_starts[v] + 2 * count)
            c = np.concatenate([np.arange(self.n), self.n + 6 * v + np.arange(6)])
            rows.append(np.repeat(r, len(c)))
            cols.append(np.tile(c, len(r)))
        self.rows = np.concatenate(rows)
        self.cols = np.concatenate(cols)
        self.shape = (len(self.observed), self.n + 6 * len(self.counts))

    def _all(self, x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        n = self.n
        intrinsics = x[:n]
        projected, jacobians = [], []
        for v, points in enumerate(self.object_points):
            uv, jac = _project_with_jacobian(intrinsics, x[n + 6 * v: n + 6 * v + 6], points, self.model)
            projected.append(uv)
            jacobians.append(jac)
        return np.concatenate(projected), jacobians

    def residuals(self, x: np.ndarray) -> np.ndarray:
        projected, _ = self._all(x)
        return projected - self.observed

    def jacobian(self, x: np.ndarray) -> sparse.csr_matrix:
        _, jacobians = self._all(x)
        # per view, reorder columns to [intrinsics, 6 pose] to match the sparsity pattern
        values = np.concatenate([np.hstack([j[:, 6:6 + self.n], j[:, :6]]).ravel() for j in jacobians])
        return sparse.csr_matrix((values, (self.rows, self.cols)), shape=self.shape)


def _view_roll_deg(camera: BrownCamera, detection: Detection, rvec: np.ndarray, tvec: np.ndarray) -> float:
    """Direction in the image of the board's x axis, degrees; 90 apart means rotated by 90."""
    span = np.ptp(detection.object_points[:, 0]) or 1.0
    ends = camera.project(np.array([[0.0, 0, 0], [span, 0, 0]]), rvec, tvec)
    du, dv = ends[1] - ends[0]
    return float(np.degrees(np.arctan2(dv, du)))


COVERAGE_CELLS = (8, 6)  # columns, rows of the grid whose share holding board points is the coverage
CORNER_GRID = 3  # the image in thirds each way: a corner cell no board point reached is warned


def coverage_grid(image_points: Sequence[np.ndarray], width: int, height: int, nx: int, ny: int) -> np.ndarray:
    """Which cells of an nx x ny grid over the image hold at least one of the points."""
    grid = np.zeros((ny, nx), bool)
    for points in image_points:
        ix = np.clip((points[:, 0] / width * nx).astype(int), 0, nx - 1)
        iy = np.clip((points[:, 1] / height * ny).astype(int), 0, ny - 1)
        grid[iy, ix] = True
    return grid


def radial_residuals(camera: BrownCamera, points: np.ndarray, residuals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point: distance from the principal point as a fraction of the half-diagonal, and the residual's
    component along that direction (px, outwards positive)."""
    offsets = points - (camera.xp, camera.yp)
    distance = np.hypot(*offsets.T)
    radial = np.sum(residuals * offsets, axis=1) / np.maximum(distance, 1e-9)
    return distance / np.hypot(camera.width / 2, camera.height / 2), radial


def radial_profile(camera: BrownCamera, points: Sequence[np.ndarray], residuals: Sequence[np.ndarray]) -> list[dict]:
    """The residuals (detected - projected, px) in rings of distance from the principal point: per ring with enough
    points, its bounds (fractions of the half-diagonal), point count, mean radial residual (outwards positive)
    with its standard error, and RMS. A model that fits leaves every ring's mean radial residual at zero."""
    residuals = np.vstack(residuals)
    where, radial = radial_residuals(camera, np.vstack(points), residuals)
    rings = []
    for low, high in RADIAL_RINGS:
        inside = (where >= low) & (where < high)
        n = int(inside.sum())
        if n >= RING_MIN_POINTS:
            rings.append({"from": low, "to": high, "points": n, "mean_radial_px": float(radial[inside].mean()),
                          "standard_error_px": float(radial[inside].std(ddof=1) / np.sqrt(n)),
                          "rms_px": float(np.sqrt(np.mean(np.sum(residuals[inside] ** 2, axis=1))))})
    return rings


def _systematic_residual_warning(rings: list[dict]) -> list[str]:
    off = [r for r in rings if abs(r["mean_radial_px"]) > max(SYSTEMATIC_PX, 5 * r["standard_error_px"])]
    if not off:
        return []
    where = ", ".join(f"{r['mean_radial_px']:+.2f} px at {r['from']:.0%}-{r['to']:.0%}" for r in off)
    return [f"residuals are systematic with the distance from the centre (mean radial residual {where} of the "
            "half-diagonal): the Brown model (K1-K3, P1, P2) does not fully follow this lens (or port); idealized "
            "positions carry errors of about that size"]


NEW_POSE_DISTANCE = 0.08  # pose signature distance below which a view adds nothing new (a video's next frames)


def pose_signature(points: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """Where the board is (centre), how big (sqrt of its hull area), and how it is turned (doubled angle of
    its principal axis, so a 180° turn is the same pose): all scaled to about 0..1."""
    width, height = image_size
    centre = points.mean(axis=0)
    spread = points - centre
    # the spread's principal axes from its 2x2 scatter matrix (what an SVD of the points gives, without one)
    (a, b), (_, d) = spread.T @ spread
    half_gap = math.hypot((a - d) / 2, b)
    major, minor = math.sqrt((a + d) / 2 + half_gap), math.sqrt(max((a + d) / 2 - half_gap, 0.0))
    doubled = math.atan2(2 * b, a - d)  # twice the major axis's direction
    size = math.sqrt(max(major * minor, 1e-9) / len(points)) / width
    return np.array([centre[0] / width, centre[1] / height, 2 * size, 0.25 * math.cos(doubled),
                     0.25 * math.sin(doubled), minor / max(major, 1e-9) * 0.3])


HELD_POSE_FRACTION = 0.01  # board points moving less than this share of the image diagonal: the same pose


def same_pose(a: Detection, b: Detection, image_size: tuple[int, int]) -> bool:
    """Whether two detections show the board where it was (a video of a pose held still): most points in common
    and their mean displacement under 1 % of the image diagonal."""
    common, in_a, in_b = np.intersect1d(a.ids, b.ids, return_indices=True)
    if len(common) < 0.5 * max(len(a.ids), len(b.ids)):
        return False
    moved = np.hypot(*(a.image_points[in_a] - b.image_points[in_b]).T).mean()
    return bool(moved < HELD_POSE_FRACTION * math.hypot(*image_size))


def _weak_geometry_warnings(
    views: list[ViewReport], image_points: list[np.ndarray], correlation: np.ndarray, width: int, height: int,
    names: Sequence[str] = PARAM_NAMES,
) -> list[str]:
    warnings = []
    if len(views) < RECOMMENDED_VIEWS:
        warnings.append(f"only {len(views)} views used; take {RECOMMENDED_VIEWS} or more for a reliable calibration")
    rolls = np.array([v.roll_deg for v in views]) % 180.0
    # largest angular separation between any two views, on the circle of directions mod 180
    separation = np.abs(rolls[:, None] - rolls[None, :])
    separation = np.minimum(separation, 180.0 - separation).max() if len(rolls) > 1 else 0.0
    if separation < ROTATION_WARNING_DEG:
        warnings.append(
            f"no view is rotated by about 90 degrees (largest rotation between views {separation:.0f} deg): "
            "the principal point is poorly determined; add views with the camera or board turned by 90 deg")
    cells = coverage_grid(image_points, width, height, CORNER_GRID, CORNER_GRID)
    missing = [name for name, (r, c) in
               {"top-left": (0, 0), "top-right": (0, -1), "bottom-left": (-1, 0), "bottom-right": (-1, -1)}.items()
               if not cells[r, c]]
    if missing:
        warnings.append(f"image corners not covered by any board point: {', '.join(missing)}; "
                        "distortion there is extrapolated")
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            pair = {names[i], names[j]}
            # fx-fy and the radial terms among themselves are correlated by nature, not by weak views
            if abs(correlation[i, j]) > CORRELATION_WARNING and pair != {"fx", "fy"} and not pair <= RADIAL:
                warnings.append(f"parameters {names[i]} and {names[j]} are strongly correlated "
                                f"({correlation[i, j]:+.3f}); the views do not separate them")
    return warnings


def _camera_block(object_points: list[np.ndarray], x: np.ndarray, problem: _Problem
                  ) -> tuple[np.ndarray, np.ndarray]:
    """From each view's blocks of the Jacobian (A: camera, B: pose): the camera block of the inverse normal
    matrix, S^-1 with S = sum A^T A - sum W V^-1 W^T (W = A^T B, V = B^T B), and each view's influence on the
    camera, S^-1 (A^T r - W V^-1 B^T r) (rows). The covariance of the camera when views, not corners, are the
    independent samples is the sum of the influences' outer products (G / (G - 1) aside): the infinitesimal
    jackknife over views, what a bootstrap over views measures, without refitting."""
    n = problem.n
    reduced = np.zeros((n, n))
    gradients = []
    for v, points in enumerate(object_points):
        uv, jac = _project_with_jacobian(x[:n], x[n + 6 * v: n + 6 * v + 6], points, problem.model)
        r = uv - problem.observed[problem.row_starts[v]:problem.row_starts[v + 1]]
        a, b = jac[:, 6:6 + n], jac[:, :6]
        w, pose_inverse = a.T @ b, np.linalg.inv(b.T @ b)
        reduced += a.T @ a - w @ pose_inverse @ w.T
        gradients.append(a.T @ r - w @ pose_inverse @ (b.T @ r))
    camera_inverse = np.linalg.inv(reduced)
    return camera_inverse, np.array(gradients) @ camera_inverse.T


LM_MAX_ITERATIONS = 200
LM_TOLERANCE = 1e-12  # relative decrease of the cost, and relative step, below which the fit has converged
# Marquardt's damping (relative to the normal matrix's diagonal) to start from: from OpenCV's estimate, and when
# refitting from a converged solution (outlier rounds, halves), which needs nearly Gauss-Newton steps at once
# (starting again from 1e-3 spent 5-6 of 9-11 iterations only lowering the damping, on 408 real views)
LM_DAMPING_COLD = 1e-3
LM_DAMPING_WARM = 1e-6


def _bundle_lm(object_points: list[np.ndarray], image_points: list[np.ndarray], start: np.ndarray,
               damping: float = LM_DAMPING_COLD, model: str = "plumb_bob") -> tuple[np.ndarray, bool, int]:
    """Levenberg-Marquardt bundle adjustment exploiting its structure: the camera parameters are solved from the
    reduced camera system (Schur complement of each view's 6x6 pose block), then every pose from its own block.
    (solution, converged, iterations). Each iteration costs one projection per view."""
    n_camera = len(param_names(model))
    x = np.array(start, float)
    views = len(object_points)
    observed = [p.reshape(-1) for p in image_points]
    every_point = np.vstack(object_points)
    every_observed = np.concatenate(observed)
    owner = np.repeat(np.arange(views), [len(p) for p in object_points])

    def cost_at(x: np.ndarray) -> float:
        """The sum of squared residuals, all views projected at once (no Jacobian)."""
        poses = x[n_camera:].reshape(views, 6)
        rotations = np.array([cv2.Rodrigues(pose[:3])[0] for pose in poses])
        camera = np.einsum("nij,nj->ni", rotations[owner], every_point) + poses[owner, 3:]
        fx, fy, cx, cy = x[:4]
        normalized = camera[:, :2] / camera[:, 2:3]
        distorted = distort_model(normalized, model, x[4:n_camera])  # the model's order, as x holds it
        projected = (distorted * (fx, fy) + (cx, cy)).ravel()
        difference = projected - every_observed
        return float(difference @ difference)

    rows = 2 * max(len(p) for p in object_points)  # every view's rows padded with zeros to the longest view's
    camera_jacobian = np.zeros((views, rows, n_camera))
    pose_jacobian = np.zeros((views, rows, 6))
    residuals = np.zeros((views, rows))

    def evaluate(x: np.ndarray) -> None:
        """Each view's residuals and Jacobian blocks (camera A, pose B), into the padded arrays (zero rows add
        nothing to the normal equations)."""
        for v in range(views):
            uv, jac = _project_with_jacobian(x[:n_camera], x[n_camera + 6 * v: n_camera + 6 * v + 6],
                                             object_points[v], model)
            n = len(uv)
            residuals[v, :n] = uv - observed[v]
            camera_jacobian[v, :n] = jac[:, 6:6 + n_camera]
            pose_jacobian[v, :n] = jac[:, :6]

    evaluate(x)
    cost = float(np.sum(residuals**2))
    for iteration in range(1, LM_MAX_ITERATIONS + 1):
        # per view: camera block A, pose block B; all views' small matrices at once (views x 9 x 6, ...)
        cross = camera_jacobian.transpose(0, 2, 1) @ pose_jacobian
        pose_normal = pose_jacobian.transpose(0, 2, 1) @ pose_jacobian
        pose_gradient = np.einsum("vri,vr->vi", pose_jacobian, residuals)
        stacked = camera_jacobian.reshape(-1, n_camera)
        camera_normal = stacked.T @ stacked
        camera_gradient = stacked.T @ residuals.ravel()
        diagonal = np.einsum("vii->vi", pose_normal)
        while True:
            damped = camera_normal + damping * np.diag(np.diag(camera_normal))
            inverses = np.linalg.inv(pose_normal + damping * diagonal[:, :, None] * np.eye(6))
            w_inv = cross @ inverses  # views x 9 x 6
            reduced = damped - np.einsum("vij,vkj->ik", w_inv, cross)
            rhs = -(camera_gradient - np.einsum("vij,vj->i", w_inv, pose_gradient))
            try:
                camera_step = np.linalg.solve(reduced, rhs)
            except np.linalg.LinAlgError:
                damping *= 10
                continue
            pose_steps = np.einsum("vij,vj->vi", inverses, -pose_gradient - np.einsum("vji,j->vi", cross,
                                                                                        camera_step))
            step = np.concatenate([camera_step, pose_steps.ravel()])
            trial = x + step
            trial_cost = cost_at(trial)
            if np.isfinite(trial_cost) and trial_cost <= cost:
                small_step = np.linalg.norm(step) <= LM_TOLERANCE * (np.linalg.norm(x) + LM_TOLERANCE)
                small_gain = cost - trial_cost <= LM_TOLERANCE * cost
                x, cost = trial, trial_cost
                damping = max(damping / 3, 1e-15)
                if small_step or small_gain:
                    return x, True, iteration
                evaluate(x)
                break
            damping *= 4
            if damping > 1e12:  # no step lowers the cost: at the minimum to machine precision
                return x, True, iteration
    return x, False, LM_MAX_ITERATIONS


def _halves(object_points: list[np.ndarray], image_points: list[np.ndarray], x: np.ndarray, camera: BrownCamera,
            std: dict[str, float], covered: np.ndarray | None = None) -> dict:
    """The views split into two disjoint halves (alternately, so both span the session), each fitted apart:
    the camera parameters' differences in combined std (each half's std is sqrt(2) x the whole's), the largest
    difference in projection over the part of the image the board points cover (px), and each half's camera
    predicting the other half's corners (each view placed anew by the camera, which it did not help fit): the
    held-out RMS, the evidence a model with more coefficients must win on."""
    names, model = camera.param_names, camera.model
    n = len(names)
    fitted, held_out = [], []
    for half in (0, 1):
        chosen = list(range(half, len(object_points), 2))
        start = np.concatenate([x[:n]] + [x[n + 6 * v: n + 6 * v + 6] for v in chosen])
        fitted.append(_bundle_lm([object_points[v] for v in chosen], [image_points[v] for v in chosen], start,
                                 LM_DAMPING_WARM, model)[0])
    for half in (0, 1):
        others = list(range(1 - half, len(object_points), 2))
        held_out += [pose_residuals(fitted[half][:n], x[n + 6 * v: n + 6 * v + 6], object_points[v],
                                     image_points[v], model) for v in others]
    held = np.concatenate(held_out)
    difference = fitted[0][:n] - fitted[1][:n]
    combined = np.array([std[name] for name in names]) * 2  # sqrt(2 std_half^2), std_half = sqrt(2) std
    z = np.abs(difference) / np.maximum(combined, 1e-300)
    grid = _covered_grid(camera, covered)
    directions = camera.pixels_to_normalized(grid)
    projected = [camera.with_parameters(f).normalized_to_pixels(directions) for f in fitted]
    shift = np.hypot(*(projected[0] - projected[1]).T)
    worst = int(np.argmax(z))
    return {"z": dict(zip(names, map(float, z), strict=True)), "max_z": float(z.max()),
            "worst": f"{names[worst]} {difference[worst]:+.3g}", "projection_difference_px":
            {"median": float(np.median(shift)), "max": float(shift.max())},
            "held_out_rms_px": float(np.sqrt(np.mean(held**2) * 2))}


POSE_ITERATIONS = 20


def pose_residuals(intrinsics: np.ndarray, pose: np.ndarray, object_points: np.ndarray, image_points: np.ndarray,
                    model: str) -> np.ndarray:
    """A view's residuals (u, v interleaved) after its pose alone is fitted (Gauss-Newton) to a fixed camera."""
    pose = np.array(pose, float)
    observed = image_points.reshape(-1)
    for _ in range(POSE_ITERATIONS):
        uv, jac = _project_with_jacobian(intrinsics, pose, object_points, model)
        b = jac[:, :6]
        step = np.linalg.lstsq(b, -(uv - observed), rcond=None)[0]
        pose += step
        if np.linalg.norm(step) < 1e-12 * (1 + np.linalg.norm(pose)):
            break
    uv, _ = _project_with_jacobian(intrinsics, pose, object_points, model)
    return uv - observed


def _image_grid(camera: BrownCamera, n: int = 9) -> np.ndarray:
    u, v = np.meshgrid(np.linspace(0, camera.width - 1, n + 2)[1:-1], np.linspace(0, camera.height - 1, n + 2)[1:-1])
    return np.column_stack([u.ravel(), v.ravel()])


def _covered_grid(camera: BrownCamera, covered: np.ndarray | None) -> np.ndarray:
    """The image grid's points inside the board points' hull, `covered`, where the model is not extrapolated
    (the whole grid without points, or where none lies inside)."""
    grid = _image_grid(camera)
    if covered is not None and len(covered) >= 3:
        inside = inside_hull(grid, covered)
        grid = inside if len(inside) else grid
    return grid


def projection_std(camera: BrownCamera, covariance: np.ndarray, covered: np.ndarray | None = None) -> dict:
    """How far (px, 1 std) the image of a fixed viewing direction is uncertain, over a grid on the image (the
    part inside the board points' hull, `covered`, where the model is not extrapolated), from the camera
    parameters' covariance: median and max, and the grid's values."""
    grid = _covered_grid(camera, covered)
    directions = camera.pixels_to_normalized(grid)
    base = camera.parameters()
    values = np.array(list(base.values()))
    jac = np.zeros((len(grid), 2, len(values)))
    for i in range(len(values)):
        step = 1e-6 * max(abs(values[i]), 1.0)
        moved = values.copy()
        moved[i] += step
        shifted = camera.with_parameters(moved).normalized_to_pixels(directions)
        jac[:, :, i] = (shifted - camera.normalized_to_pixels(directions)) / step
    variances = np.einsum("pij,jk,pik->pi", jac, covariance, jac)
    std = np.sqrt(np.clip(variances.sum(axis=1), 0, None))
    return {"median": float(np.median(std)), "max": float(std.max()), "points": grid.round(1).tolist(),
            "std_px": std.round(4).tolist()}


def _uncertainty_warnings(std: dict[str, float], views: list[ViewReport], width: int, height: int) -> list[str]:
    """Warnings from the measured uncertainties and the views' residuals."""
    warnings = []
    principal = max(std["cx"], std["cy"])
    if principal > 0.005 * min(width, height):  # 2.4 px at 640x480, 5.4 px at 1440x1080
        warnings.append(f"principal point uncertain by ±{principal:.1f} px: add views rotated by 90 deg and views "
                        "that fill the corners")
    if len(views) >= 4:
        typical = float(np.median([v.rms_px for v in views]))
        outliers = [v for v in views if v.rms_px > max(3 * typical, typical + 0.3)]
        if outliers:
            names = ", ".join(f"{v.name} ({v.rms_px:.2f} px)" for v in outliers)
            warnings.append(f"views far worse than the others (median {typical:.2f} px): {names}; "
                            "check them (blur, a bent board, a wrong detection) or leave them out")
    return warnings


def distinct_views(views: Sequence[View]) -> tuple[list[View], dict[str, str]]:
    """The views with repeats of an earlier view left out, and why each was: the same board points detected
    within SAME_VIEW_PX (mean) of where an earlier view has them. A photograph given twice, or a still board
    in a video, adds no information but would shrink the std as if it did (15 copies of one photo: fx +77 %
    with a std of 21 px)."""
    kept: list[View] = []
    centres = np.empty((0, 2))
    by_ids: dict[bytes, dict[int, np.ndarray]] = {}  # kept views with the very same point ids: index -> pixels
    repeated: dict[str, str] = {}
    for view in views:
        ids, pixels = np.asarray(view.detection.ids).ravel(), view.detection.image_points.reshape(-1, 2)
        centre = pixels.mean(axis=0)
        # only views whose points lie about where these do can repeat it (a cheap test before the ids' match)
        near_views = np.flatnonzero(np.hypot(*(centres - centre).T) < SAME_VIEW_NEAR_PX).tolist()
        moved: dict[int, float] = {}
        same_ids = by_ids.get(ids.tobytes(), {})
        alike = [k for k in near_views if k in same_ids]  # e.g. a whole chessboard: the points in the same order
        if alike:
            gaps = np.hypot(*(np.stack([same_ids[k] for k in alike]) - pixels).transpose(2, 0, 1)).mean(axis=1)
            moved = dict(zip(alike, gaps.tolist(), strict=True))
        for k in near_views:
            if k in moved:
                continue
            earlier = kept[k].detection
            shared, mine, theirs = np.intersect1d(ids, np.asarray(earlier.ids).ravel(), return_indices=True)
            if len(shared) >= 0.9 * max(len(ids), len(earlier.ids)):
                moved[k] = float(np.mean(np.hypot(*(pixels[mine] - earlier.image_points.reshape(-1, 2)[theirs]).T)))
        first = next((k for k in near_views if moved.get(k, math.inf) < SAME_VIEW_PX), None)
        if first is not None:
            repeated[view.name] = (f"{REPEAT_REASON} {kept[first].name} (its corners {moved[first]:.3f} px apart "
                                   "on average): counted once")
            continue
        by_ids.setdefault(ids.tobytes(), {})[len(kept)] = pixels
        kept.append(view)
        centres = np.vstack([centres, centre])
    return kept, repeated


def calibrate(
    views: Sequence[View],
    image_size: tuple[int, int],
    robust_loss: str = "linear",
    outlier_sigma: float | None = 4.0,
    progress: Callable[[str], None] | None = None,
    cross_validate: bool = True,
    model: str = "plumb_bob",
) -> CalibrationResult:
    """Fit a camera model (`model`: one of MODELS, or "auto": `choose_model`) to the views. `robust_loss` is a
    scipy loss ('linear', 'huber', 'soft_l1', ...); points whose residual exceeds `outlier_sigma` robust
    standard deviations are rejected and the fit repeated (None disables rejection). `std` is the larger of the
    covariance's and the view-resampling std; `cross_validate` also fits two disjoint halves of the views and
    compares them (and has each half predict the other's corners)."""
    if model == "auto":
        return choose_model(views, image_size, robust_loss, outlier_sigma, progress)
    if model not in MODELS:
        raise CalibrationError(f"unknown camera model {model!r} (known: {', '.join(MODELS)}, auto)")
    n_camera = len(param_names(model))
    started = time.perf_counter()
    say = progress or (lambda _msg: None)
    width, height = image_size
    views = [v for v in views if len(v.detection) >= 4]
    views, repeated = distinct_views(views)
    if len(views) < MIN_VIEWS:
        raise CalibrationError(f"{len(views)} usable views; at least {MIN_VIEWS} are needed "
                               f"({RECOMMENDED_VIEWS}+ recommended)"
                               + (f"; {len(repeated)} more repeat a view already counted ({next(iter(repeated))}: "
                                  f"{next(iter(repeated.values()))})" if repeated else ""))
    object_points = [v.detection.object_points.astype(np.float64) for v in views]
    image_points = [v.detection.image_points.astype(np.float64) for v in views]
    # OpenCV's estimate from at most INIT_VIEWS views spread over the set (its cost grows with the views; the
    # joint refinement uses them all), then every view's pose from that camera
    chosen = np.unique(np.linspace(0, len(views) - 1, min(len(views), INIT_VIEWS)).round().astype(int))
    initial_views = len(chosen)
    say(f"initial estimate (OpenCV) from {initial_views} of {len(views)} views")
    opencv_rms, K, dist = _initial_camera([object_points[v] for v in chosen], [image_points[v] for v in chosen],
                                          (width, height), model)
    rvecs, tvecs = [], []
    start_camera = BrownCamera.from_opencv(K, dist, (width, height), model) if model == "equidistant" else None
    for points, pixels in zip(object_points, image_points, strict=True):
        if start_camera is None:
            found, rvec, tvec = cv2.solvePnP(points, pixels, K, dist)
        else:  # OpenCV's solvePnP knows no fisheye: place the view by its corners' ideal rays
            found, rvec, tvec = cv2.solvePnP(points, start_camera.pixels_to_normalized(pixels), np.eye(3), None)
        if not found:
            raise CalibrationError("OpenCV could not place a view from the initial camera")
        rvecs.append(rvec)
        tvecs.append(tvec)
    dist = np.asarray(dist, float).ravel()[:n_camera - 4]
    x = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], dist]
                       + [np.concatenate([np.ravel(r), np.ravel(t)]) for r, t in zip(rvecs, tvecs, strict=True)])

    def pose_of(v: int) -> slice:
        return slice(n_camera + 6 * v, n_camera + 6 * v + 6)

    keep = [np.ones(len(p), bool) for p in object_points]
    rejected_views: dict[str, str] = dict(repeated)
    active = list(range(len(views)))
    iterations = 0

    unconverged = 0

    def refine() -> np.ndarray:
        """Joint least squares over the active views' kept points; updates x, returns the residuals."""
        nonlocal iterations, unconverged
        active_objects = [object_points[v][keep[v]] for v in active]
        active_images = [image_points[v][keep[v]] for v in active]
        x_active = np.concatenate([x[:n_camera]] + [x[pose_of(v)] for v in active])
        say(f"bundle adjustment: {len(active)} views, {sum(len(o) for o in active_objects)} points")
        if robust_loss == "linear":
            refit = iterations > 0  # x holds a converged (or stopped) fit already
            solution, converged, nfev = _bundle_lm(active_objects, active_images, x_active,
                                                   LM_DAMPING_WARM if refit else LM_DAMPING_COLD, model)
        else:  # robust losses: scipy's trust region on the sparse Jacobian
            problem = _Problem(active_objects, active_images, model)
            fit = least_squares(problem.residuals, x_active, jac=problem.jacobian, method="trf", x_scale="jac",
                                loss=robust_loss, f_scale=1.0, tr_solver="lsmr", ftol=1e-12, xtol=1e-12,
                                gtol=1e-12, max_nfev=200)
            solution, converged, nfev = fit.x, fit.status > 0, fit.nfev
        iterations += nfev
        unconverged += not converged
        x[:n_camera] = solution[:n_camera]
        for k, v in enumerate(active):
            x[pose_of(v)] = solution[n_camera + 6 * k: n_camera + 6 * k + 6]
        return _Problem(active_objects, active_images, model).residuals(solution)

    residuals = refine()
    for _ in range(MAX_REJECTION_ROUNDS if outlier_sigma is not None else 0):
        # robust scale of the inlier residuals; then every point of every active view is judged afresh
        # against the new fit, so points condemned by an earlier, bent fit come back
        inlier_err = np.hypot(*residuals.reshape(-1, 2).T)
        robust_sigma = 1.4826 * np.median(inlier_err) / np.sqrt(np.log(4))  # Rayleigh median -> per-axis sigma
        limit = max(outlier_sigma * robust_sigma * np.sqrt(2), 0.05)
        changed = False
        for v in list(active):
            uv, _ = _project_with_jacobian(x[:n_camera], x[pose_of(v)], object_points[v], model)
            new_keep = np.hypot(*(uv.reshape(-1, 2) - image_points[v]).T) <= limit
            if not np.array_equal(new_keep, keep[v]):
                keep[v] = new_keep
                changed = True
            if keep[v].sum() < max(6, 0.5 * len(keep[v])):
                active.remove(v)
                rejected_views[views[v].name] = (f"more than half of its points are outliers "
                                                 f"(residual > {limit:.2f} px)")
        if len(active) < MIN_VIEWS:
            raise CalibrationError(f"only {len(active)} views left after rejecting outliers")
        if not changed:
            break
        residuals = refine()  # the reported solution is always fitted to the final set of points

    # final solution over the kept points; covariance from the Jacobian there
    obj = [object_points[v][keep[v]] for v in active]
    problem = _Problem(obj, [image_points[v][keep[v]] for v in active], model)
    x_final = np.concatenate([x[:n_camera]] + [x[pose_of(v)] for v in active])
    residuals = problem.residuals(x_final)
    dof = len(residuals) - len(x_final)
    if dof <= 0:
        raise CalibrationError("more unknowns than observations; add views or board points")
    sigma0 = float(np.sqrt(residuals @ residuals / dof))
    try:
        camera_inverse, view_terms = _camera_block(obj, x_final, problem)
    except np.linalg.LinAlgError as exc:
        raise CalibrationError("the normal equations are singular: the views do not determine the camera") from exc
    covariance = camera_inverse * sigma0**2  # the camera block of the inverse normal matrix, scaled
    covariance_std = np.sqrt(np.clip(np.diag(covariance), 0, None))
    view_cov = view_terms.T @ view_terms * len(obj) / max(len(obj) - 1, 1)
    # the honest std: corner errors are not independent within a view (board flatness, lighting, blur), so
    # resampling views spreads the camera more than the covariance says; the larger of the two
    view_std = np.sqrt(np.clip(np.diag(view_cov), 0, None))
    cov_i = view_cov if np.all(view_std >= covariance_std) else covariance
    std_values = np.maximum(view_std, covariance_std)
    correlation = cov_i / np.outer(np.sqrt(np.diag(cov_i)), np.sqrt(np.diag(cov_i)))
    names = param_names(model)
    camera = BrownCamera.from_opencv(
        np.array([[x_final[0], 0, x_final[2]], [0, x_final[1], x_final[3]], [0, 0, 1]]), x_final[4:n_camera],
        (width, height), model)

    reports, per_view_residuals, per_view_points, per_view_inliers = [], [], [], []
    offset = 0
    for k, v in enumerate(active):
        n = len(obj[k])
        r = residuals[offset: offset + 2 * n].reshape(-1, 2)
        offset += 2 * n
        pose = x_final[n_camera + 6 * k: n_camera + 6 * k + 6]
        # residuals of all the view's points, rejected ones included, for the report
        all_r = views[v].detection.image_points - camera.project(views[v].detection.object_points, pose[:3], pose[3:])
        per_view_residuals.append(all_r)
        per_view_points.append(views[v].detection.image_points)
        per_view_inliers.append(keep[v].copy())
        err = np.hypot(r[:, 0], r[:, 1])
        reports.append(ViewReport(
            name=views[v].name, points=n, rms_px=float(np.sqrt(np.mean(err**2))), mean_px=float(err.mean()),
            max_px=float(err.max()), rejected_points=int((~keep[v]).sum()),
            roll_deg=_view_roll_deg(camera, views[v].detection, pose[:3], pose[3:])))
    err = np.hypot(*residuals.reshape(-1, 2).T)
    used_points = [views[v].detection.image_points[keep[v]] for v in active]
    warnings = _weak_geometry_warnings(reports, used_points, correlation, width, height, names)
    profile = radial_profile(camera, used_points, [r[k] for r, k in zip(per_view_residuals, per_view_inliers,
                                                                          strict=True)])
    warnings += _systematic_residual_warning(profile)
    if camera.reach is not None and not np.all(camera.within_reach(np.vstack(used_points))):
        raise CalibrationError(f"the {model} fit folds over {camera.reach_px():.0f} px from the principal point, "
                               "inside the region the board points cover: it passes near the points but bends "
                               "between them, which no lens does (is the board spec the board in the images? "
                               "else another model suits this lens better: --model auto)")
    if not camera.holds_everywhere():
        warnings.append(f"the {model} model holds to {camera.reach_px():.0f} px from the principal point and "
                        "folds beyond (its polynomial bends back past the board's reach): frames are measured only "
                        "inside that circle and a ROI reaching past it says so; cover the corners with the board, "
                        "or use a model made for wide lenses (--model equidistant or rational_polynomial)")
    coverage = float(coverage_grid(used_points, width, height, *COVERAGE_CELLS).mean())
    honest = dict(zip(names, map(float, std_values), strict=True))
    projection = projection_std(camera, view_cov if np.all(view_std >= covariance_std) else cov_i,
                                np.vstack(used_points))
    halves = {}
    if cross_validate and len(active) >= 2 * MIN_VIEWS + 2:
        say("cross-validation: the two halves of the views fitted apart")
        halves = _halves(obj, [image_points[v][keep[v]] for v in active], x_final, camera, honest,
                         np.vstack(used_points))
        if halves["max_z"] > 3:
            warnings.append(f"two halves of the views disagree by up to {halves['max_z']:.1f} combined std "
                            f"({halves['worst']}): some views are not like the others (moved board, refocus, "
                            "another distance); check the per-view residuals")
    warnings += _uncertainty_warnings(honest, reports, width, height)
    if repeated:
        warnings.append(f"{len(repeated)} view(s) repeat a view already counted (the same photograph, or a still "
                        f"board filmed frame after frame) and were counted once: {len(active)} distinct views")
    if unconverged:
        warnings.append(f"{unconverged} of the bundle adjustments stopped at the iteration limit before converging")
    say(f"done: RMS {np.sqrt(np.mean(err**2)):.4f} px over {len(active)} views")
    return CalibrationResult(
        camera=camera, std=dict(zip(names, map(float, std_values), strict=True)), correlation=correlation,
        rms_px=float(np.sqrt(np.mean(err**2))), mean_px=float(err.mean()), max_residual_px=float(err.max()),
        views=reports, rejected_views=rejected_views, warnings=warnings, opencv_rms_px=float(opencv_rms),
        opencv_rms_views=initial_views,
        sigma0_px=sigma0, iterations=iterations, seconds=time.perf_counter() - started, coverage=coverage,
        converged=not unconverged, radial_profile=profile,
        std_covariance=dict(zip(names, map(float, covariance_std), strict=True)),
        std_views=dict(zip(names, map(float, view_std), strict=True)), halves=halves,
        projection_std_px=projection,
        poses=[x_final[n_camera + 6 * k: n_camera + 6 * k + 6].copy() for k in range(len(active))],
        image_points=per_view_points, residuals=per_view_residuals, inliers=per_view_inliers,
        object_points=[views[v].detection.object_points.astype(np.float64) for v in active])


_OPENCV_THREADS_LOCK = threading.Lock()


@contextmanager
def _opencv_single_threaded() -> Iterator[None]:
    """OpenCV on one thread while inside: its calibrations sum over threads in an order that varies from run to
    run, which moves the adjustment's converged result in the 8th digit (the same views, another file)."""
    with _OPENCV_THREADS_LOCK:
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
        try:
            yield
        finally:
            cv2.setNumThreads(threads)


def _initial_camera(object_points: list[np.ndarray], image_points: list[np.ndarray], image_size: tuple[int, int],
                    model: str) -> tuple[float, np.ndarray, np.ndarray]:
    """OpenCV's calibration of the model from these views, the bundle adjustment's start: (RMS px, K, dist).
    rational_polynomial starts from plumb_bob's fit with the denominator 1, the optimum nearest the simpler
    model (a ratio of polynomials has many with one mapping: numerator and denominator can share a factor).
    cv2.fisheye.calibrate often fails on views of a lens that is not a true fisheye: equidistant then starts
    from the pinhole's camera matrix with zero coefficients (r_d = θ), from which the adjustment converges."""
    objects = [p.astype(np.float32) for p in object_points]
    images = [p.astype(np.float32) for p in image_points]
    try:
        with _opencv_single_threaded():
            rms, K, dist, _, _ = cv2.calibrateCamera(objects, images, image_size, None, None)
    except cv2.error as exc:
        raise CalibrationError(f"OpenCV could not initialise the calibration: {exc.err}") from exc
    if not np.isfinite(rms):
        raise CalibrationError("OpenCV's initial calibration did not converge")
    if model == "plumb_bob":
        return float(rms), K, np.asarray(dist, float).ravel()
    if model == "rational_polynomial":  # from plumb_bob's fit, the denominator 1: the nearest of its many optima
        return float(rms), K, np.concatenate([np.asarray(dist, float).ravel()[:5], np.zeros(3)])
    try:
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)
        with _opencv_single_threaded():
            fisheye_rms, fisheye_k, fisheye_d, _, _ = cv2.fisheye.calibrate(
                [p.reshape(-1, 1, 3).astype(np.float64) for p in object_points],
                [p.reshape(-1, 1, 2).astype(np.float64) for p in image_points], image_size, None, None,
                flags=cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW, criteria=criteria)
        if np.isfinite(fisheye_rms) and np.all(np.isfinite(fisheye_d)):
            return float(fisheye_rms), fisheye_k, np.asarray(fisheye_d, float).ravel()
    except cv2.error:
        pass
    return float(rms), K, np.zeros(4)


MODEL_PREFERENCE = ("plumb_bob", "equidistant", "rational_polynomial")  # every ROS tool knows the first; fewest terms
MODEL_MARGIN = 0.03  # a model must predict held-out corners this much better (relative RMS) to be preferred
# views the models are compared on (evenly through them), the one taken then fitted to all: a video's 400 views
# tell the models apart as 120 do (each half's 60 views predict the other's 4000-odd corners), in a third the time
MAX_VIEWS_TO_CHOOSE = 120
MIN_VIEWS_TO_CHOOSE = 2 * MIN_VIEWS + 2  # each half must calibrate on its own


def choose_model(views: Sequence[View], image_size: tuple[int, int], robust_loss: str = "linear",
                 outlier_sigma: float | None = 4.0, progress: Callable[[str], None] | None = None,
                 ) -> CalibrationResult:
    """Every model fitted to the views, one picked on evidence: how well each half of the views' camera predicts
    the other half's corners (held-out RMS), not the fit's RMS (more coefficients always lower it). A model
    whose distortion has no inverse over the board points' region is out. The first of MODEL_PREFERENCE within
    MODEL_MARGIN of the best held-out RMS is picked; the result's `model_choice` says each model's figures and
    why. With too few views to split, plumb_bob."""
    say = progress or (lambda _msg: None)
    if len(views) < MIN_VIEWS_TO_CHOOSE:
        result = calibrate(views, image_size, robust_loss, outlier_sigma, progress, True, "plumb_bob")
        result.model_choice = {"chosen": "plumb_bob", "reason": f"{len(views)} views are too few to compare models "
                               f"on held-out views (at least {MIN_VIEWS_TO_CHOOSE}): the common one",
                               "candidates": {}}
        return result
    if len(views) > MAX_VIEWS_TO_CHOOSE:
        result = _chosen_on_a_sample(views, image_size, robust_loss, outlier_sigma, progress)
        if result is not None:
            return result
    fitted: dict[str, CalibrationResult] = {}  # every model that could be fitted
    fits: dict[str, CalibrationResult] = {}  # ... of those, the ones with a held-out figure and no problem
    candidates: dict[str, dict] = {}
    for model in MODEL_PREFERENCE:
        say(f"model {model}")
        try:
            fit = calibrate(views, image_size, robust_loss, outlier_sigma, progress, True, model)
        except CalibrationError as exc:
            candidates[model] = {"error": str(exc)}
            continue
        fitted[model] = fit
        problem = _implausible_over_its_points(fit)
        held_out = fit.halves.get("held_out_rms_px", math.nan)
        candidates[model] = {"rms_px": fit.rms_px, "held_out_rms_px": held_out, "problem": problem}
        if problem is None and np.isfinite(held_out):
            fits[model] = fit
    if not fits and all("error" not in c and not c["problem"] for c in candidates.values()):
        # no held-out figure anywhere: too few distinct views to split (repeats counted once)
        result = fitted["plumb_bob"]
        result.model_choice = {"chosen": "plumb_bob", "reason": f"{result.views_used} distinct views are too few to "
                               f"compare models on held-out views (at least {MIN_VIEWS_TO_CHOOSE}): the common one",
                               "candidates": candidates}
        return result
    if not fits:
        raise CalibrationError("no camera model fits these views: " + "; ".join(
            f"{m}: {c.get('error') or c.get('problem') or 'no held-out figure'}" for m, c in candidates.items()))
    best = min(fit.halves["held_out_rms_px"] for fit in fits.values())
    chosen = next(m for m in MODEL_PREFERENCE
                  if m in fits and fits[m].halves["held_out_rms_px"] <= best * (1 + MODEL_MARGIN))
    figures = ", ".join(f"{m} {c['held_out_rms_px']:.3f} px" if "held_out_rms_px" in c else f"{m} failed"
                        for m, c in candidates.items())
    out = [f"{m} ({c.get('error') or c.get('problem')})" for m, c in candidates.items() if m not in fits]
    reason = (f"each half of the views predicts the other half's corners to {figures} (RMS); "
              + (f"{chosen} is within {MODEL_MARGIN:.0%} of the best and earlier in {', '.join(MODEL_PREFERENCE)}"
                 if fits[chosen].halves["held_out_rms_px"] > best else f"{chosen} predicts best")
              + (f"; left out: {'; '.join(out)}" if out else ""))
    result = fits[chosen]
    result.model_choice = {"chosen": chosen, "reason": reason, "candidates": candidates}
    say(f"model {chosen}: {reason}")
    return result


def _implausible_over_its_points(fit: CalibrationResult) -> str | None:
    """Why the fitted model cannot be this lens over the region its board points (the inliers) cover, or None."""
    covered = np.vstack([points[kept] for points, kept in zip(fit.image_points, fit.inliers, strict=True)])
    return implausibility(fit.camera, covered=covered)


def _chosen_on_a_sample(views: Sequence[View], image_size: tuple[int, int], robust_loss: str,
                        outlier_sigma: float | None, progress: Callable[[str], None] | None
                        ) -> CalibrationResult | None:
    """The model compared on MAX_VIEWS_TO_CHOOSE views evenly through `views`, then fitted to all of them (the
    same fit as `calibrate` with that model); None where the sample cannot tell the models apart (no held-out
    figure), or the model taken does not fit all the views or is implausible over their points: then all views
    choose."""
    step = len(views) / MAX_VIEWS_TO_CHOOSE
    sample = [views[int(k * step)] for k in range(MAX_VIEWS_TO_CHOOSE)]
    try:
        judged = choose_model(sample, image_size, robust_loss, outlier_sigma, progress)
    except CalibrationError:
        return None
    choice = judged.model_choice
    if not any(np.isfinite(c.get("held_out_rms_px", math.nan)) for c in choice["candidates"].values()):
        return None
    try:
        result = calibrate(views, image_size, robust_loss, outlier_sigma, progress, True, choice["chosen"])
    except CalibrationError:
        return None
    if _implausible_over_its_points(result) is not None:
        return None
    result.model_choice = {**choice, "reason": f"{choice['reason']} (compared on {len(sample)} of the "
                                               f"{len(views)} views, evenly through them; fitted to all)",
                           "views_compared": len(sample)}
    return result
