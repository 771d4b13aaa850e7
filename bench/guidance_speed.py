"""What the calibration node spends looking at one frame (board search, the view's judgement, the feedback
image) at 640x480 and at the DSLR's 3872x2592, beside the full-size board search it replaces, on renders with
3 DN of sensor noise, measured in one run. The goal: a 10-megapixel frame looked at in at most 250 ms.

    .venv/bin/python bench/guidance_speed.py [--repeats N]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "veg_area_ros"))

from timing import median_seconds  # bench/ is the script's folder, first on sys.path

from veg_area_ros.board import BoardSpec, detect_scaled
from veg_area_ros.feedback import render_feedback
from veg_area_ros.guidance import CalibrationGuide
from veg_area_ros.sim.synthetic import DSLR, ENDOSCOPE, board_views, render_board_views


def look(board: BoardSpec, camera, images: list[np.ndarray]) -> None:
    """The node's work on each frame: the search (reduced above 1600 px), the judgement, the feedback image."""
    guide = CalibrationGuide(board, camera.image_size)
    for image in images:
        detection = detect_scaled(board, image)
        verdict = guide.offer(detection, image) if detection is not None else None
        render_feedback(image, guide, None if detection is None else detection.image_points, verdict)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    repeats = parser.parse_args().repeats
    board = BoardSpec.parse("chessboard:9x6:0.03")
    for name, camera in (("640x480", ENDOSCOPE), ("3872x2592", DSLR)):
        poses = board_views(camera, board, 3, 0.7, np.random.default_rng(1))
        images = render_board_views(camera, board, poses, supersample=1, noise_sigma=3.0)
        full = median_seconds(lambda images=images: [board.detect(image) for image in images], repeats)
        looked = median_seconds(lambda images=images, camera=camera: look(board, camera, images), repeats)
        print(f"{name}: a frame looked at (search, judgement, feedback image) {1000 * looked / len(images):7.1f} ms;"
              f" the board search alone at full size {1000 * full / len(images):7.1f} ms ({looked / full:.2f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
