"""Synthetic renders with a known camera: a textured plane seen through a lens and, optionally, a flat port
into water (refraction traced exactly with Snell's law). Ground truth for tests and the demo.

No ROS here. Each output pixel is traced backwards: pixel -> ideal ray (inverse Brown model) -> refraction
at the port -> intersection with the plane -> texture lookup, supersampled for anti-aliasing.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..board import BoardSpec
from ..camera_model import BrownCamera
from ..flat_port import FlatPort, air_rays_to, along, in_frame, rays_in_water
from ..targets import TargetsSpec

if TYPE_CHECKING:
    from collections.abc import Callable

# the synthetic set-up: camera, calibration board and object at the paper's 0.7 m, 15 calibration views
DISTANCE_M = 0.7
BOARD = "chessboard:9x6:0.04"
VIEWS = 15

# a typical cheap 640x480 underwater endoscope: short focal length and strong barrel distortion
ENDOSCOPE = BrownCamera(640, 480, c=520.0, xp=326.0, yp=236.5, aspect=1.004,
                        k1=-0.32, k2=0.12, k3=-0.02, p1=0.0012, p2=-0.0008)


# rays are computed and traced a band of image rows at a time: a whole 10 MP image's temporaries cost more in
# page faults than in arithmetic
_BAND_RAYS = 1 << 16


@lru_cache(maxsize=4)
def _pixel_rays(camera: BrownCamera, supersample: int) -> np.ndarray:
    """Unit rays (H*s, W*s, 3) in camera coordinates for every sub-pixel sample, cached per camera."""
    s = supersample
    offsets = (np.arange(s) + 0.5) / s - 0.5
    u = (np.arange(camera.width)[:, None] + offsets[None, :]).ravel()
    v = (np.arange(camera.height)[:, None] + offsets[None, :]).ravel()
    rays = np.empty((len(v), len(u), 3))
    rows = max(1, _BAND_RAYS // len(u))
    for top in range(0, len(v), rows):  # in bands, as plane_coordinates: each ray depends on its pixel alone
        uu, vv = np.meshgrid(u, v[top:top + rows])
        xy = camera.pixels_to_normalized(np.column_stack([uu.ravel(), vv.ravel()]))
        band = np.column_stack([xy, np.ones(len(xy))])
        band /= np.linalg.norm(band, axis=1, keepdims=True)
        rays[top:top + rows] = band.reshape(-1, len(u), 3)
    rays.setflags(write=False)
    return rays


def refract_at_port(rays: np.ndarray, port: FlatPort) -> tuple[np.ndarray, np.ndarray]:
    """Unit rays from the lens centre -> (origins on the port's outer surface, directions in water), both
    (..., 3): the exact flat-port model (`flat_port.rays_in_water`)."""
    return rays_in_water(port, rays)


def ideal_rays_to(points: np.ndarray, port: FlatPort | None = None) -> np.ndarray:
    """Camera-frame 3-D points (N, 3) -> ideal normalized (x, y) of the air ray that reaches each point,
    refraction at the port included."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if port is None:
        return points[:, :2] / points[:, 2:3]
    air = air_rays_to(port, points)
    return air[:, :2] / air[:, 2:3]


def plane_coordinates(
    camera: BrownCamera, rvec: np.ndarray, tvec: np.ndarray, port: FlatPort | None = None, supersample: int = 1,
) -> np.ndarray:
    """For every (sub-)pixel, the (x, y) in metres where its ray meets the plane z = 0 of the pose; NaN
    where it misses (behind the camera or parallel)."""
    rays = _pixel_rays(camera, supersample)
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
    t = np.asarray(tvec, dtype=float).ravel()
    xy = np.empty((*rays.shape[:2], 2))
    rows = max(1, _BAND_RAYS // rays.shape[1])
    for top in range(0, rays.shape[0], rows):
        xy[top:top + rows] = _plane_hits(rays[top:top + rows], R, t, port)
    return xy


def _plane_hits(rays: np.ndarray, R: np.ndarray, t: np.ndarray, port: FlatPort | None) -> np.ndarray:
    if port is None:
        origins, directions = np.zeros_like(rays), rays
    else:
        origins, directions = refract_at_port(rays, port)
    normal = R[:, 2]
    denom = along(directions, normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = along(t - origins, normal) / denom
    hit = origins + directions * depth[..., None]
    local = in_frame(hit - t, R)  # R^T (hit - t), row-wise
    xy = local[..., :2]
    xy[~(depth > 0)] = np.nan
    return xy


def render_plane(
    camera: BrownCamera,
    texture: np.ndarray,
    extent: tuple[float, float, float, float],
    rvec: np.ndarray,
    tvec: np.ndarray,
    port: FlatPort | None = None,
    background: int | tuple[int, int, int] = 90,
    supersample: int = 3,
) -> np.ndarray:
    """Render a textured plane whose texture covers `extent` = (x0, y0, x1, y1) metres of the plane z = 0."""
    fine = _render_fine(camera, texture, extent, rvec, tvec, port, background, supersample)
    return cv2.resize(fine, camera.image_size, interpolation=cv2.INTER_AREA)


def _render_fine(camera: BrownCamera, texture: np.ndarray, extent: tuple[float, float, float, float],
                 rvec: np.ndarray, tvec: np.ndarray, port: FlatPort | None, background: int | tuple[int, int, int],
                 supersample: int) -> np.ndarray:
    """The plane's texture at every sub-pixel sample (supersampled image, before averaging to pixels)."""
    x0, y0, x1, y1 = extent
    scale_x = texture.shape[1] / (x1 - x0)
    scale_y = texture.shape[0] / (y1 - y0)
    xy = plane_coordinates(camera, rvec, tvec, port, supersample)
    # texel i covers [x0 + i/scale, x0 + (i+1)/scale]: its centre is at texture coordinate i
    map_x = ((xy[..., 0] - x0) * scale_x - 0.5).astype(np.float32)
    map_y = ((xy[..., 1] - y0) * scale_y - 0.5).astype(np.float32)
    map_x[np.isnan(map_x)] = -1e6
    map_y[np.isnan(map_y)] = -1e6
    border = background if np.ndim(background) == 0 or texture.ndim == 3 else int(np.mean(background))
    return cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=border)


def look_at_pose(
    distance: float, tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0, roll_deg: float = 0.0,
    centre: tuple[float, float] = (0.0, 0.0), plane_point: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray]:
    """Pose (rvec, tvec) of a plane whose point `plane_point` lies at (centre_x, centre_y, distance) in camera
    coordinates, rolled about the optical axis and tilted about its own x and y axes."""
    def rot(axis: int, deg: float) -> np.ndarray:
        r = np.zeros(3)
        r[axis] = np.radians(deg)
        return cv2.Rodrigues(r)[0]

    R = rot(2, roll_deg) @ rot(0, tilt_x_deg) @ rot(1, tilt_y_deg)
    anchor = np.array([centre[0], centre[1], distance])
    t = anchor - R @ np.array([plane_point[0], plane_point[1], 0.0])
    return cv2.Rodrigues(R)[0].ravel(), t


SPREAD = [(-1, -1), (1, 1), (1, -1), (-1, 1), (0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)]


def board_views(
    camera: BrownCamera, board: BoardSpec, count: int, distance: float, rng: np.random.Generator,
    max_tilt_deg: float = 35.0, port: FlatPort | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Poses that a careful calibrator would take: tilted, spread over the image (corners included), every
    third one rolled by 90 degrees so the principal point is well determined, board fully in view."""
    x0, y0, x1, y1 = board.extent()
    board_centre = ((x0 + x1) / 2, (y0 + y1) / 2)
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], float)
    # with a flat port the field of view shrinks by about the refractive index
    fov_scale = 1.0 / (port.water_index if port else 1.0)
    half_w = distance * (camera.width / 2) / camera.fx * fov_scale
    half_h = distance * (camera.height / 2) / camera.fy * fov_scale
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    attempts = 0
    while len(poses) < count:
        attempts += 1
        if attempts > 2000 * count:
            raise RuntimeError("could not place the board in view; move it further away or use a smaller board")
        roll = (90.0 if len(poses) % 3 == 2 else 0.0) + rng.uniform(-10, 10)
        tilt_x, tilt_y = rng.uniform(-max_tilt_deg, max_tilt_deg, size=2)
        # visit the image corners, edges and centre in turn, as a careful calibrator does
        gx, gy = SPREAD[len(poses) % len(SPREAD)]
        reach = rng.uniform(0.3, 0.8)
        centre = (gx * reach * half_w, gy * reach * half_h)
        rvec, tvec = look_at_pose(distance * rng.uniform(0.9, 1.1), tilt_x, tilt_y, roll, centre, board_centre)
        cam_points = (cv2.Rodrigues(rvec)[0] @ corners.T).T + tvec
        u, v = camera.normalized_to_pixels(ideal_rays_to(cam_points, port)).T
        margin = 0.03 * camera.width
        inside_u = margin < u.min() and u.max() < camera.width - margin
        if inside_u and margin < v.min() and v.max() < camera.height - margin:
            poses.append((rvec, tvec))
    return poses


def degrade(image: np.ndarray, rng: np.random.Generator, noise_sigma: float = 1.0, blur_sigma_px: float = 0.0,
            light_gradient: float = 0.0, light_direction_deg: float = 45.0, gain: float = 1.0,
            tone_curve: str = "linear") -> np.ndarray:
    """What a flume adds to a clean render: uneven light (brightness falling by `light_gradient` across the
    image towards `light_direction_deg` (0: to the right, 90: down; 45, the default, diagonally), plus
    vignetting of the same strength), turbidity blur, sensor noise, and an exposure `gain` (over 1 clips the
    whites); then the camera's tone curve (`srgb`: light encoded as most JPEG cameras do). uint8 out."""
    out = image.astype(np.float32) * np.float32(gain)
    if light_gradient:
        h, w = out.shape[:2]
        y, x = np.mgrid[0:h, 0:w].astype(np.float32)
        cos, sin = np.cos(np.radians(light_direction_deg)), np.sin(np.radians(light_direction_deg))
        ramp = 1 - light_gradient * ((x / w - 0.5) * cos + (y / h - 0.5) * sin) / (abs(cos) + abs(sin))
        vignette = 1 - light_gradient * (((x - w / 2) / w) ** 2 + ((y - h / 2) / h) ** 2)
        out *= ramp * vignette
    if blur_sigma_px:
        out = cv2.GaussianBlur(out, (0, 0), blur_sigma_px)
    out += rng.normal(0.0, noise_sigma, out.shape).astype(np.float32)
    if tone_curve == "srgb":  # the light (0..255) encoded: the inverse of classify.to_light
        x = np.clip(out / 255.0, 0.0, 1.0)
        out = 255.0 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    elif tone_curve != "linear":
        raise ValueError(f"tone curve must be linear or srgb, got {tone_curve!r}")
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def render_board_views(
    camera: BrownCamera, board: BoardSpec, poses: list[tuple[np.ndarray, np.ndarray]],
    port: FlatPort | None = None, noise_sigma: float = 1.0, rng: np.random.Generator | None = None,
    blur_sigma_px: float = 0.0, light_gradient: float = 0.0, supersample: int = 3, gain: float = 1.0,
    tone_curve: str = "linear",
) -> list[np.ndarray]:
    """Grey images of the board at each pose, with mild sensor noise (and flume degradation if asked). The
    board's white renders at BOARD_WHITE, as a well-exposed camera leaves headroom; `gain` over 1.09 clips it;
    `tone_curve` as `degrade` takes it."""
    rng = rng or np.random.default_rng(0)
    pixels_per_metre = 40.0 / board.square  # 40 texels per square: finer than any camera pixel here
    texture = np.round(board.texture(pixels_per_metre).astype(np.float32) * (BOARD_WHITE / 255)).astype(np.uint8)
    return [degrade(render_plane(camera, texture, board.extent(), rvec, tvec, port, background=110,
                                 supersample=supersample), rng, noise_sigma, blur_sigma_px, light_gradient,
                    gain=gain, tone_curve=tone_curve)
            for rvec, tvec in poses]


BOARD_WHITE = 235  # grey level of the board's white squares in a well-exposed view (255 would be clipped)


# a DSLR as in the paper (3872x2592) with an 18 mm-class lens: milder distortion than the endoscope
DSLR = BrownCamera(3872, 2592, c=2450.0, xp=1941.0, yp=1290.5, aspect=1.0, k1=-0.09, k2=0.03, k3=0.0,
                   p1=0.0003, p2=-0.0002)

# the real webcam calibration's parameter stds (docs/calibration.md; c, xp, yp px, aspect, k1-k3, p1, p2 in
# BrownCamera.param_names' order): a rendered camera given them measures with a calibration's term in its std
WEBCAM_CALIBRATION_STD = (0.5, 0.5, 1.3, 0.7, 0.009, 0.04, 2.5e-4, 2.8e-4, 0.055)


def webcam_like_covariance(camera: BrownCamera) -> dict:
    """A calibration file's `camera_covariance` for `camera` with the webcam's parameter stds and no
    correlations (CameraCovariance.as_dict)."""
    from ..camera_uncertainty import CameraCovariance

    std = dict(zip(camera.param_names, WEBCAM_CALIBRATION_STD, strict=True))
    return CameraCovariance.from_std(std, {}).as_dict()


# --- measurement scenes: a target frame of ArUco markers in the object's plane, and an object --------------
CUBE_SIDE_M = 0.1027  # the paper's cube: face area 0.01055 m²
SCENE_MARKERS = {0: (-0.22, -0.16), 1: (0.22, -0.16), 2: (0.22, 0.16), 3: (-0.22, 0.16)}
SCENE_DICTIONARY = "DICT_4X4_50"


def scene_targets_content(markers: dict[int, tuple[float, float]] | None = None) -> dict:
    """A targets file's content (YAML-ready) for the scene's four markers, or for `markers` in its dictionary."""
    markers = SCENE_MARKERS if markers is None else markers
    return {"dictionary": SCENE_DICTIONARY, "markers": {int(k): [float(x), float(y)] for k, (x, y) in markers.items()}}


def scene_targets() -> TargetsSpec:
    """The scene's four markers as a targets file gives them: what the built-in default camera shows."""
    return TargetsSpec.from_dict(scene_targets_content())


@dataclass(frozen=True)
class Scene:
    texture: np.ndarray  # grey, covering `extent` of the object plane
    extent: tuple[float, float, float, float]
    true_area_m2: float
    markers: dict[int, tuple[float, float]]
    dictionary: str = SCENE_DICTIONARY
    coverage: np.ndarray | None = None  # the object's share of each texel (0..1)
    marker_mask: np.ndarray | None = None  # texels of the markers with their white quiet zone
    background: int = 200
    object_level: int = 40


def _coverage_1d(n: int, start: float, stop: float) -> np.ndarray:
    """Fraction of each unit texel [i, i+1] inside [start, stop] (texel units)."""
    edges = np.arange(n + 1, dtype=float)
    return np.clip(np.minimum(edges[1:], stop) - np.maximum(edges[:-1], start), 0.0, 1.0)


def _compose_scene(coverage_fn: Callable[[int, int, float, float], np.ndarray], pixels_per_metre: float,
                   marker_size: float, background: int, object_level: int,
                   markers: dict[int, tuple[float, float]] | None = None) -> Scene:
    """A bright board with four ArUco markers (`markers`: id -> centre, default SCENE_MARKERS) and an object
    whose per-texel coverage (0..1) comes from `coverage_fn(width, height, x0, y0)`; the true area is the
    coverage sum, so it is exact for the texture."""
    markers = dict(SCENE_MARKERS if markers is None else markers)
    x0, y0, x1, y1 = -0.3, -0.225, 0.3, 0.225
    width, height = round((x1 - x0) * pixels_per_metre), round((y1 - y0) * pixels_per_metre)
    coverage = coverage_fn(width, height, x0, y0)
    texture = np.rint(background + (object_level - background) * coverage).astype(np.uint8)
    marker_mask = np.zeros(texture.shape, bool)
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, SCENE_DICTIONARY))
    size = round(marker_size * pixels_per_metre)
    for marker_id, (mx, my) in markers.items():
        image = cv2.aruco.generateImageMarker(dictionary, marker_id, size)
        left = round((mx - x0) * pixels_per_metre - size / 2)
        top = round((my - y0) * pixels_per_metre - size / 2)
        quiet = size // 4
        texture[top - quiet: top + size + quiet, left - quiet: left + size + quiet] = 255
        texture[top: top + size, left: left + size] = image
        marker_mask[top - quiet: top + size + quiet, left - quiet: left + size + quiet] = True
    true_area = float(coverage.sum()) / pixels_per_metre**2
    return Scene(texture, (x0, y0, x1, y1), true_area, markers, coverage=coverage, marker_mask=marker_mask,
                 background=background, object_level=object_level)


def cube_scene(side: float = CUBE_SIDE_M, marker_size: float = 0.05, pixels_per_metre: float = 2000.0,
               background: int = 200, object_level: int = 40,
               markers: dict[int, tuple[float, float]] | None = None) -> Scene:
    """A dark square cube face of exactly `side` metres centred between four ArUco markers on a bright
    board; texels on the face's edge carry their exact coverage, so the true area is side² to rounding."""
    def coverage(width: int, height: int, x0: float, y0: float) -> np.ndarray:
        cover_x = _coverage_1d(width, (-side / 2 - x0) * pixels_per_metre, (side / 2 - x0) * pixels_per_metre)
        cover_y = _coverage_1d(height, (-side / 2 - y0) * pixels_per_metre, (side / 2 - y0) * pixels_per_metre)
        return np.outer(cover_y, cover_x)

    return _compose_scene(coverage, pixels_per_metre, marker_size, background, object_level, markers)


def bush_scene(seed: int = 7, marker_size: float = 0.05, pixels_per_metre: float = 2000.0, background: int = 200,
               object_level: int = 40, oversample: int = 8) -> Scene:
    """A bush-like silhouette: a stem, branches of 3-8 mm and elliptic leaves, about 0.2 m tall, drawn at
    `oversample` x the texture resolution and averaged, so its true area is known to the texel."""
    rng = np.random.default_rng(seed)

    def coverage(width: int, height: int, x0: float, y0: float) -> np.ndarray:
        k = pixels_per_metre * oversample
        fine = np.zeros((height * oversample, width * oversample), np.uint8)

        def px(x: float, y: float) -> tuple[int, int]:
            return round((x - x0) * k), round((y - y0) * k)

        def grow(x: float, y: float, angle: float, length: float, thick: float, depth: int) -> None:
            x2, y2 = x + length * np.sin(angle), y - length * np.cos(angle)
            cv2.line(fine, px(x, y), px(x2, y2), 255, max(1, round(thick * k)), cv2.LINE_8)
            if depth == 0:
                for _ in range(3):
                    lx, ly = x2 + rng.normal(0, 0.006), y2 + rng.normal(0, 0.006)
                    axes = (round(rng.uniform(0.008, 0.014) * k), round(rng.uniform(0.003, 0.006) * k))
                    cv2.ellipse(fine, px(lx, ly), axes, float(rng.uniform(0, 180)), 0, 360, 255, -1)
                return
            for turn in (-1, 1):
                grow(x2, y2, angle + turn * rng.uniform(0.3, 0.7), length * rng.uniform(0.6, 0.8),
                     max(0.003, thick * 0.7), depth - 1)

        grow(0.0, 0.11, rng.normal(0, 0.05), 0.07, 0.008, 3)
        return cv2.resize(fine.astype(np.float32) / 255, (width, height), interpolation=cv2.INTER_AREA)

    return _compose_scene(coverage, pixels_per_metre, marker_size, background, object_level)


def empty_scene(scene: Scene) -> Scene:
    """The same board and markers without the object: what a background frame of the empty flume shows."""
    texture = scene.texture.copy()
    if scene.marker_mask is not None:
        texture[~scene.marker_mask] = scene.background
    else:
        texture[:] = scene.background
    return Scene(texture, scene.extent, 0.0, scene.markers, scene.dictionary, np.zeros_like(texture, float),
                 scene.marker_mask, scene.background, scene.object_level)


def twig_scene(widths_m: tuple[float, ...] = (0.0015, 0.0025, 0.004), length: float = 0.16, seed: int = 3,
               marker_size: float = 0.05, pixels_per_metre: float = 2000.0, background: int = 200,
               object_level: int = 40, oversample: int = 8) -> Scene:
    """Thin straight twigs (one per width, at assorted angles, not crossing) drawn at `oversample` x the texture
    resolution and averaged: 1-3 endoscope pixels wide at 0.7 m, the branches a count loses or gains whole."""
    rng = np.random.default_rng(seed)

    def coverage(width: int, height: int, x0: float, y0: float) -> np.ndarray:
        k = pixels_per_metre * oversample
        fine = np.zeros((height * oversample, width * oversample), np.uint8)
        for index, twig_width in enumerate(widths_m):
            x = (index - (len(widths_m) - 1) / 2) * 0.06
            angle = rng.uniform(-0.35, 0.35)
            dx, dy = length / 2 * np.sin(angle), length / 2 * np.cos(angle)
            ends = [(round((x + sx * dx - x0) * k), round((sy * dy - y0) * k)) for sx, sy in ((-1, -1), (1, 1))]
            cv2.line(fine, ends[0], ends[1], 255, max(1, round(twig_width * k)), cv2.LINE_8)
        return cv2.resize(fine.astype(np.float32) / 255, (width, height), interpolation=cv2.INTER_AREA)

    return _compose_scene(coverage, pixels_per_metre, marker_size, background, object_level)


def render_scene(camera: BrownCamera, scene: Scene, distance: float = DISTANCE_M, port: FlatPort | None = None,
                 tilt_deg: float = 0.0, roll_deg: float = 4.0, noise_sigma: float = 1.0, seed: int = 0,
                 blur_sigma_px: float = 0.0, light_gradient: float = 0.0, supersample: int = 3,
                 centre: tuple[float, float] = (0.0, 0.0), object_offset: float = 0.0,
                 light_direction_deg: float = 45.0, gain: float = 1.0, tone_curve: str = "linear") -> np.ndarray:
    """The scene plane facing the camera at `distance` (its origin at `centre`, metres in camera x, y), tilted
    about its vertical axis by `tilt_deg` and rolled about the optical axis by `roll_deg` (4° by default, as
    the older tests were written; 0 puts edges along the pixel rows). With `object_offset` the object lies on
    its own parallel plane that much farther along the optical axis (negative: nearer), the markers on a
    frame in the scene's plane and the board's background behind both; `tone_curve` as `degrade` takes it. BGR."""
    rvec, tvec = look_at_pose(distance, tilt_y_deg=tilt_deg, roll_deg=roll_deg, centre=centre)
    if not object_offset:
        fine = _render_fine(camera, scene.texture, scene.extent, rvec, tvec, port, 60, supersample)
    else:
        fine = _render_layers(camera, scene, rvec, tvec, object_offset, port, supersample)
    image = cv2.resize(fine, camera.image_size, interpolation=cv2.INTER_AREA)
    grey = degrade(image, np.random.default_rng(seed), noise_sigma, blur_sigma_px, light_gradient,
                   light_direction_deg, gain, tone_curve)
    return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)


def _render_layers(camera: BrownCamera, scene: Scene, rvec: np.ndarray, tvec: np.ndarray, object_offset: float,
                   port: FlatPort | None, supersample: int) -> np.ndarray:
    """The markers (with their quiet zones) on the scene's plane, the object on the plane `object_offset`
    farther along the optical axis, the uniform background behind both: composited front to back per sample."""
    if scene.coverage is None or scene.marker_mask is None:
        raise ValueError("this scene has no separate object and marker layers")

    def layer(texture: np.ndarray, translation: np.ndarray) -> np.ndarray:
        return _render_fine(camera, texture.astype(np.float32), scene.extent, rvec, translation, port, 0.0,
                            supersample)

    shifted = np.asarray(tvec, float) + np.array([0.0, 0.0, object_offset])
    object_alpha = layer(scene.coverage, shifted)
    marker_alpha = layer(scene.marker_mask.astype(np.float32), np.asarray(tvec, float))
    marker_value = layer(np.where(scene.marker_mask, scene.texture, 0).astype(np.float32), np.asarray(tvec, float))
    behind = scene.background * (1 - object_alpha) + scene.object_level * object_alpha  # object over background
    if object_offset > 0:  # markers in front of the object
        fine = marker_value + (1 - marker_alpha) * behind
    else:  # the object in front of the markers' frame
        frame = marker_value + (1 - marker_alpha) * scene.background
        fine = scene.object_level * object_alpha + (1 - object_alpha) * frame
    return np.clip(fine, 0, 255).astype(np.float32)
