"""A marker's corners placed by its sides (`marker_sides`): exact at any sub-pixel phase, blur and rotation on a
square whose pixels hold their true share of it, and refused where a side cannot be read."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from veg_area_ros.marker_sides import corners_by_sides
from veg_area_ros.markers import marker_centre


def _clip(polygon: list[np.ndarray], point: np.ndarray, normal: np.ndarray) -> list[np.ndarray]:
    """The part of a convex polygon where (p - point) . normal >= 0 (Sutherland-Hodgman, one edge)."""
    kept = []
    for k, current in enumerate(polygon):
        previous = polygon[k - 1]
        a, b = (previous - point) @ normal, (current - point) @ normal
        if (a >= 0) != (b >= 0):
            kept.append(previous + (current - previous) * a / (a - b))
        if b >= 0:
            kept.append(current)
    return kept


def _area(polygon: list[np.ndarray]) -> float:
    if len(polygon) < 3:
        return 0.0
    x, y = np.array(polygon).T
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


def _square_image(corners: np.ndarray, size: int = 96, black: float = 30.0, white: float = 230.0,
                  blur: float = 0.0) -> np.ndarray:
    """A dark convex quadrilateral (corners clockwise on screen) on white, each pixel (centre at integer
    coordinates) holding its exact share of it, then blurred."""
    corners = np.asarray(corners, float)
    sides = [(start, np.array([start[1] - end[1], end[0] - start[0]]))  # inward normals
             for start, end in zip(corners, np.roll(corners, -1, axis=0), strict=True)]
    share = np.zeros((size, size))
    for row in range(size):
        for column in range(size):
            centre = np.array([column, row], float)
            distances = [(centre - point) @ normal / np.hypot(*normal) for point, normal in sides]
            if min(distances) >= 0.75:
                share[row, column] = 1.0
            elif min(distances) > -0.75:
                pixel = [centre + offset for offset in np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])]
                for point, normal in sides:
                    pixel = _clip(pixel, point, normal)
                share[row, column] = _area(pixel)
    image = (white + (black - white) * share).astype(np.float32)
    return cv2.GaussianBlur(image, (0, 0), blur) if blur else image


def _square(centre: tuple[float, float], side: float, angle_deg: float) -> np.ndarray:
    a = np.radians(angle_deg)
    rotation = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    unit = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * side / 2
    return unit @ rotation.T + centre


def identity(points: np.ndarray) -> np.ndarray:
    return points


@pytest.mark.parametrize("angle", [0.0, 17.0, 45.0])
@pytest.mark.parametrize("blur", [0.0, 1.0])
def test_the_sides_place_the_corners_at_any_phase(angle, blur):
    """Squares of 37 px (a 6-cell marker's border at 640x480) moved across one pixel in fifths: the corners
    within 0.03 px of the truth, starting from corners 0.3 px off (as cornerSubPix leaves a sharp corner)."""
    rng = np.random.default_rng(5)
    worst = 0.0
    for phase in np.linspace(0.0, 0.8, 5):
        truth = _square((47.0 + phase, 46.3 + 0.6 * phase), 37.0, angle)
        image = _square_image(truth, blur=blur)
        start = truth + rng.uniform(-0.3, 0.3, truth.shape)
        placed = corners_by_sides(image, start, 6, identity)
        assert placed is not None
        worst = max(worst, float(np.abs(placed - truth).max()))
    assert worst < 0.03, worst


@pytest.mark.parametrize(("contrast", "noise"), [(200, 2.0), (60, 4.0)])
def test_centres_from_the_sides_are_closer_than_cornersubpixs_on_noisy_8_bit_squares(contrast, noise):
    """Twelve 8-bit squares, blurred 0.8 px, at random phase and rotation with noise: the centre (the
    diagonals' intersection) from the sides lies at least twice as close to the truth (rms) as from corners
    refined by cv2.cornerSubPix as ArUco refines them (a window of 0.3 cell)."""
    rng = np.random.default_rng(2)
    sides, corners = [], []
    for _ in range(12):
        centre = np.array([48.0, 47.2]) + rng.uniform(0, 1, 2)
        truth = _square(tuple(centre), 37.0, rng.uniform(0, 90))
        image = _square_image(truth, black=200 - contrast, white=200, blur=0.8) + rng.normal(0, noise, (96, 96))
        image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
        start = truth + rng.uniform(-0.3, 0.3, (4, 2))
        placed = corners_by_sides(image.astype(np.float32), start, 6, identity)
        assert placed is not None
        refined = cv2.cornerSubPix(image, start.astype(np.float32).reshape(-1, 1, 2), (2, 2), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)).reshape(4, 2)
        sides.append(np.hypot(*(marker_centre(placed) - centre)))
        corners.append(np.hypot(*(marker_centre(refined) - centre)))
    rms = {name: float(np.sqrt(np.mean(np.square(values))))
           for name, values in (("sides", sides), ("corners", corners))}
    assert rms["sides"] < 0.5 * rms["corners"], rms


def test_a_side_over_a_dark_quiet_zone_is_not_read():
    """Something dark over the white round one side (a plant's leaf, the print's edge): the sides cannot be
    read and the caller keeps the tracked corners."""
    truth = _square((48.0, 48.0), 37.0, 0.0)
    image = _square_image(truth)
    image[20:76, 66:70] = 30.0  # a dark stripe through the quiet zone along the right side
    assert corners_by_sides(image, truth, 6, identity) is None
    image = _square_image(truth)
    image[30:40, 66:72] = 30.0  # a leaf over a sixth of it: the profiles there are left out, the rest hold
    placed = corners_by_sides(image, truth, 6, identity)
    assert placed is not None and np.abs(placed - truth).max() < 0.05


def test_small_markers_and_markers_at_the_frames_edge_keep_their_corners():
    truth = _square((20.0, 20.0), 8.0, 0.0)  # cells of 1.3 px: no room for a profile
    assert corners_by_sides(_square_image(truth), truth, 6, identity) is None
    truth = _square((20.5, 48.0), 37.0, 0.0)  # the left side's profiles would leave the frame
    assert corners_by_sides(_square_image(truth), truth, 6, identity) is None
    truth = _square((48.0, 48.0), 37.0, 0.0)  # corners tracked 1.5 px away from the sides: not the same square
    assert corners_by_sides(_square_image(truth), truth + [[1.5, 0]] * 4, 6, identity) is None


def test_the_sides_are_straight_in_the_idealized_image_not_in_the_raw_frame():
    """A raw frame bent by a barrel lens (x' = x (1 + k r²) about the frame's centre): the sides fitted through
    the mapping land on the idealized square's corners, where lines fitted in the raw frame would not."""
    k, centre, size = -2e-5, np.array([48.0, 48.0]), 96

    def to_raw(points: np.ndarray) -> np.ndarray:
        offset = points - centre
        return centre + offset * (1 + k * (offset ** 2).sum(axis=1, keepdims=True))

    truth = _square((62.0, 61.3), 30.0, 8.0)
    # the raw frame: each raw pixel looks up the ideal point whose image it is (inverted by fixed point)
    raw_grid = np.stack(np.meshgrid(np.arange(size, dtype=float), np.arange(size, dtype=float)), -1).reshape(-1, 2)
    ideal_points = raw_grid.copy()
    for _ in range(20):
        ideal_points = raw_grid - (to_raw(ideal_points) - ideal_points)
    maps = ideal_points.reshape(size, size, 2).astype(np.float32)
    raw = cv2.remap(_square_image(truth, size=size, blur=0.6), maps[..., 0], maps[..., 1], cv2.INTER_LINEAR)
    placed = corners_by_sides(raw, truth, 6, to_raw)
    assert placed is not None and np.abs(placed - truth).max() < 0.04
    straight = corners_by_sides(raw, to_raw(truth), 6, identity)  # sides fitted as lines in the raw frame
    assert straight is None or np.abs(straight - to_raw(truth)).max() > 3 * np.abs(placed - truth).max()


def test_a_marker_whose_margin_is_covered_keeps_its_corners_and_the_result_says_so():
    """A rendered cube whose marker 1 has something dark along one side's white margin (a leaf, a clamp): that
    marker keeps its tracked corners, the others are placed by their sides, Af still holds, and the result's
    warnings name the marker."""
    from helpers import calibrated_camera

    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.classify import Classifier
    from veg_area_ros.markers import detect_markers
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene
    from veg_area_ros.targets import TargetsSpec

    scene = cube_scene(side=0.1, markers={0: (-0.15, -0.15), 1: (0.15, -0.15), 2: (0.15, 0.15), 3: (-0.15, 0.15)})
    frame = render_scene(ENDOSCOPE, scene, 0.7, roll_deg=0.0, seed=1)
    targets = TargetsSpec.from_dict({"dictionary": scene.dictionary,
                                     "markers": {i: list(xy) for i, xy in scene.markers.items()}})
    camera = calibrated_camera("endoscope", "air")
    clear = AreaMeasurer(camera, targets, Classifier(threshold="otsu")).measure(frame)
    corners = detect_markers(frame, scene.dictionary)[1].corners
    (_, y0), (x1, y1) = corners.min(axis=0), corners.max(axis=0)
    covered = frame.copy()
    covered[int(y0) - 2:int(y1) + 3, int(np.ceil(x1)) + 1:int(np.ceil(x1)) + 4] = 40  # along its right side
    result = AreaMeasurer(camera, targets, Classifier(threshold="otsu")).measure(covered)
    said = [w for w in result.warnings if "placed by their corners alone" in w]
    assert len(said) == 1 and "[1]" in said[0], result.warnings
    assert not any("placed by their corners alone" in w for w in clear.warnings), clear.warnings
    for measured in (clear, result):
        assert abs(measured.area_m2 / scene.true_area_m2 - 1) < 0.005
