"""The calibration's guidance on synthetic views whose variety is known: the bars, the one 'still needed'
line for a sequence without tilt, one that never reaches a corner and one never rolled by 90 degrees; a varied
one is enough. Motion-blurred and over-exposed views are rejected with their reasons; the feedback image
shows the points where they were detected and the cells the kept views cover."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from veg_area_ros.board import BoardSpec, detect_scaled
from veg_area_ros.feedback import COVERED_COLOUR, KEPT_COLOUR, MAX_WIDTH, PANEL_WIDTH, render_feedback
from veg_area_ros.guidance import GRID, CalibrationGuide
from veg_area_ros.sim.synthetic import (
    BOARD,
    DSLR,
    ENDOSCOPE,
    FlatPort,
    board_views,
    ideal_rays_to,
    look_at_pose,
    render_board_views,
)

BOARD_SPEC = BoardSpec.parse(BOARD)
DISTANCE = 0.9
PORT = FlatPort()


def poses(count: int, tilt: float = 30.0, rolls: tuple[float, ...] = (0.0, 0.0, 90.0),
          places: tuple[tuple[int, int], ...] = ((-1, -1), (1, 1), (1, -1), (-1, 1), (0, 0), (-1, 0), (1, 0),
                                                 (0, -1), (0, 1)), seed: int = 0) -> list:
    """Board poses in water as an operator would hold them, with the variety under control: tilts up to
    `tilt` degrees about both axes (alternating sign), the rolls in turn, the image places in turn, each
    pushed as far towards its place as the whole board stays in view."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = BOARD_SPEC.extent()
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], float)
    half_w = DISTANCE * (ENDOSCOPE.width / 2) / ENDOSCOPE.fx / PORT.water_index
    half_h = DISTANCE * (ENDOSCOPE.height / 2) / ENDOSCOPE.fy / PORT.water_index
    chosen = []
    for k in range(count):
        gx, gy = places[k % len(places)]
        sign = 1 if k % 2 else -1
        tilt_x, tilt_y = sign * tilt * rng.uniform(0.6, 1.0), -sign * tilt * rng.uniform(0.6, 1.0)
        roll = rolls[k % len(rolls)] + rng.uniform(-5, 5)
        distance = DISTANCE * rng.uniform(0.85, 1.15)  # an arm held out over the flume
        best = None  # the fitting pose that goes farthest towards its place, across and down independently
        for reach_x in np.linspace(1.0, 0.0, 21):
            for reach_y in np.linspace(1.0, 0.0, 21):
                pose = look_at_pose(distance, tilt_x, tilt_y, roll, (gx * reach_x * half_w, gy * reach_y * half_h),
                                    ((x0 + x1) / 2, (y0 + y1) / 2))
                cam = (cv2.Rodrigues(pose[0])[0] @ corners.T).T + pose[1]
                u, v = ENDOSCOPE.normalized_to_pixels(ideal_rays_to(cam, PORT)).T
                fits = min(u.min(), v.min()) > 16 and u.max() < ENDOSCOPE.width - 16 and v.max() < ENDOSCOPE.height - 16
                if fits and (best is None or abs(gx) * reach_x + abs(gy) * reach_y > best[0]):
                    best = (abs(gx) * reach_x + abs(gy) * reach_y, pose)
        if best is not None:
            chosen.append(best[1])
    assert len(chosen) == count, "a pose that fits nowhere: a smaller tilt or a greater distance"
    return chosen


def guide_over(pose_list, **render) -> tuple[CalibrationGuide, list]:
    images = render_board_views(ENDOSCOPE, BOARD_SPEC, pose_list, port=PORT, rng=np.random.default_rng(1),
                                noise_sigma=2.0, supersample=2, **render)
    guide = CalibrationGuide(BOARD_SPEC, ENDOSCOPE.image_size)
    verdicts = []
    for image in images:
        detection = BOARD_SPEC.detect(image)
        if detection is not None:  # a board at the image's edge, steeply tilted, is not always found
            verdicts.append(guide.offer(detection, image))
    assert len(verdicts) >= 0.8 * len(images)
    return guide, verdicts


@pytest.fixture(scope="module")
def varied():
    return guide_over(poses(18))


def test_a_varied_sequence_is_enough(varied):
    guide, _ = varied
    assert guide.still_needed() is None and guide.enough(), guide.summary()
    assert all(fill == 1.0 for fill in guide.bars().values()), guide.bars()
    assert len(guide.kept) >= 12 and not guide.missing_corners()


def test_a_sequence_without_tilt_asks_for_tilt():
    guide, _ = guide_over(poses(16, tilt=0.0))
    assert guide.still_needed() == "tilt the board about its horizontal axis (top towards the camera, then away)"
    assert guide.bars()["tilt_h"] < 0.5 and not guide.enough()


def test_a_sequence_that_never_reaches_a_corner_asks_for_it():
    places = ((-1, -1), (1, -1), (-1, 1), (0, 0), (-1, 0), (0, -1), (0, 1), (1, 0))  # never (1, 1)
    guide, _ = guide_over(poses(16, places=places))
    assert guide.still_needed() == "cover the bottom-right corner", guide.summary()
    assert not guide.enough()


def test_a_sequence_never_rolled_asks_for_a_90_degree_roll():
    guide, _ = guide_over(poses(16, rolls=(0.0,)))
    assert guide.still_needed() == "roll the board by 90 degrees (turn it on its side)", guide.summary()
    assert guide.bars()["roll"] < 0.5


def test_too_few_views_ask_for_more(varied):
    guide, _ = varied
    few = CalibrationGuide(BOARD_SPEC, ENDOSCOPE.image_size, min_views=40, kept=list(guide.kept),
                           covered=guide.covered.copy())
    assert few.still_needed().endswith(f"(kept {len(guide.kept)} of 40)")
    assert few.blur_limit() == guide.blur_limit()  # a guide made from kept views judges blur by their widths


def test_motion_blur_and_over_exposure_are_rejected_with_their_reasons(varied):
    guide, _ = varied
    sharp_widths = [s.edge_width_px for s in guide.kept]
    pose_list = poses(2, seed=9)
    blurred = render_board_views(ENDOSCOPE, BOARD_SPEC, pose_list[:1], port=PORT, noise_sigma=2.0, supersample=2,
                                 rng=np.random.default_rng(2))[0]
    kernel = np.zeros((9, 9), np.float32)
    kernel[4, :] = 1 / 9  # a 9 px horizontal smear: the board moved during the exposure
    blurred = cv2.filter2D(blurred, -1, kernel)
    detection = BOARD_SPEC.detect(blurred)
    assert detection is not None
    verdict = guide.offer(detection, blurred)
    assert not verdict.kept and verdict.kind == "blurred" and verdict.reason.startswith("motion blur")
    assert verdict.stats.edge_width_px > 1.6 * np.median(sharp_widths)
    bright = render_board_views(ENDOSCOPE, BOARD_SPEC, pose_list[1:], port=PORT, noise_sigma=2.0, supersample=2,
                                rng=np.random.default_rng(2), gain=1.3)[0]
    detection = BOARD_SPEC.detect(bright)
    assert detection is not None
    verdict = guide.offer(detection, bright)
    assert not verdict.kept and verdict.kind == "clipped" and "over-exposed board" in verdict.reason
    assert guide.rejected["blurred"] >= 1 and guide.rejected["clipped"] >= 1


def test_the_varied_views_are_all_sharp_and_well_exposed(varied):
    _, verdicts = varied
    assert not any(v.kind in ("blurred", "clipped", "partial") for v in verdicts), [v.reason for v in verdicts]


def test_the_feedback_image_shows_the_points_and_the_covered_cells(varied):
    guide, _ = varied
    image = render_board_views(ENDOSCOPE, BOARD_SPEC, poses(1, seed=4), port=PORT, noise_sigma=2.0,
                               supersample=2)[0]
    detection = BOARD_SPEC.detect(image)
    feedback = render_feedback(image, guide, detection.image_points)
    assert feedback.shape == (480, 640 + PANEL_WIDTH, 3)
    for x, y in detection.image_points[::7]:  # a ring drawn round each point, in the kept colour
        ring = feedback[round(y) - 4:round(y) + 5, round(x) - 4:round(x) + 5].reshape(-1, 3).astype(int)
        assert np.min(np.abs(ring - KEPT_COLOUR).sum(axis=1)) < 60
    cell_w, cell_h = 640 / GRID[0], 480 / GRID[1]
    plain = render_feedback(np.full((480, 640), 128, np.uint8), guide)  # a grey frame: only the overlay shows
    for row in range(GRID[1]):
        for col in range(GRID[0]):
            centre = plain[round((row + 0.25) * cell_h), round((col + 0.5) * cell_w)].astype(int)  # above the banner
            greenish = centre[1] > centre[0] + 10 and centre[1] > centre[2] + 10
            assert greenish == bool(guide.covered[row, col]), (row, col, centre)
    assert COVERED_COLOUR[1] > COVERED_COLOUR[0]


def test_a_large_frame_is_searched_reduced_and_its_feedback_is_at_most_1280_wide():
    board = BoardSpec.parse("chessboard:9x6:0.03")
    pose_list = board_views(DSLR, board, 1, 0.7, np.random.default_rng(1))
    image = render_board_views(DSLR, board, pose_list, supersample=1, noise_sigma=2.0)[0]
    full, reduced = board.detect(image), detect_scaled(board, image)
    assert full is not None and reduced is not None
    assert np.max(np.abs(full.image_points - reduced.image_points)) < 0.1  # refined at full size
    guide = CalibrationGuide(board, DSLR.image_size)
    guide.offer(reduced, image)
    assert render_feedback(image, guide, reduced.image_points).shape[1] == MAX_WIDTH + PANEL_WIDTH


def test_veg_area_calibrate_says_what_is_still_needed_and_reports_the_bars(tmp_path):
    from helpers import REPO, run_cli

    done = run_cli("calibrate", str(REPO / "test" / "data" / "opencv-left"), "--board", "chessboard:9x6:1",
                   "--medium", "air", "-o", str(tmp_path / "left.yaml"), "--report", str(tmp_path / "report"),
                   "--json")
    assert done.returncode == 0, done.stderr
    import json

    variety = json.loads(done.stdout)["variety"]
    lines = [line for line in done.stderr.splitlines() if line.startswith(("still needed:", "variety of the views"))]
    assert len(lines) == 1
    assert lines[0] == (f"still needed: {variety['still_needed']}" if variety["still_needed"]
                        else "variety of the views: enough for every parameter")
    assert set(variety["bars"]) == {"x", "y", "size", "tilt_h", "tilt_v", "roll", "coverage"}
    assert (tmp_path / "report" / "variety.png").stat().st_size > 10_000
    # the clipped real photos (whites at 250+ around the corners) get the advice, and are still used
    assert "over-exposed board" in done.stderr and json.loads(done.stdout)["views_used"] == 13  # none lost
