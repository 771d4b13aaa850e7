"""Per-frame cost of the area node's core (track the targets, classify, Af with its uncertainty and the
threshold sweep, from precomputed raw-pixel weights) at 640x480 and 3872x2592, beside a plain memory copy
and a naive undistort-then-threshold of the same frame, the paper's idealize-then-count path, and the least
any histogram classification costs (one masked 1-D histogram of the ROI's grey band), measured in one run.
The frames are a steady camera's: the same scene with fresh sensor noise each frame. Prints ms per frame
and ratios, and the share of a 30 fps frame interval.

    .venv/bin/python bench/area_speed.py [--repeats N]
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import cv2

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from timing import median_seconds  # bench/ is the script's folder, first on sys.path

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.classify import Classifier
from veg_area_ros.scale import TargetsSpec
from veg_area_ros.synthetic import DSLR, ENDOSCOPE, SCENE_DICTIONARY, SCENE_MARKERS, FlatPort, cube_scene, render_scene


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    targets = TargetsSpec.from_dict({"dictionary": SCENE_DICTIONARY,
                                     "markers": {k: list(v) for k, v in SCENE_MARKERS.items()}})
    for camera in (ENDOSCOPE, DSLR):
        frames = [render_scene(camera, cube_scene(), 0.7, FlatPort(), seed=seed,
                               supersample=1 if camera is DSLR else 3) for seed in range(4)]
        frame = frames[0]
        measurer = AreaMeasurer(camera, targets, Classifier(threshold=120), area_mode="count")
        measurer.measure(frame)  # pixel geometry and weights built once, as in the node
        subpixel = AreaMeasurer(camera, targets, Classifier(threshold=120), area_mode="subpixel")
        subpixel.measure(frame)
        weights = measurer._weights
        band = cv2.cvtColor(frame[weights.window], cv2.COLOR_BGR2GRAY)
        stream = itertools.cycle(frames)

        def naive(frame=frame, camera=camera) -> None:
            ideal = cv2.undistort(frame, camera.camera_matrix, camera.dist)
            cv2.threshold(cv2.cvtColor(ideal, cv2.COLOR_BGR2GRAY), 120, 255, cv2.THRESH_BINARY_INV)

        repeats = args.repeats if camera is ENDOSCOPE else max(3, args.repeats // 5)
        copy_ms = 1000 * median_seconds(lambda frame=frame: frame.copy(), repeats)
        histogram_ms = 1000 * median_seconds(
            lambda band=band, roi=weights.roi: cv2.calcHist([band], [0], roi, [256], [0, 256]), repeats)
        naive_ms = 1000 * median_seconds(naive, repeats)
        core_ms = 1000 * median_seconds(lambda m=measurer, s=stream: m.measure(next(s)), repeats)
        subpixel_ms = 1000 * median_seconds(lambda m=subpixel, s=stream: m.measure(next(s)), repeats)
        paper_ms = 1000 * median_seconds(lambda m=measurer, f=frame: m.measure_idealized(f), max(3, repeats // 3))
        width, height = camera.image_size
        print(f"{width}x{height} bgr8, median of {repeats}")
        print(f"  memory copy                         {copy_ms:9.3f} ms")
        print(f"  one histogram of the ROI (floor)    {histogram_ms:9.3f} ms  ({histogram_ms / copy_ms:6.1f}x copy)")
        print(f"  naive undistort + threshold         {naive_ms:9.3f} ms  ({naive_ms / copy_ms:6.1f}x copy)")
        print(f"  idealize-then-count (paper's path)  {paper_ms:9.3f} ms  ({paper_ms / copy_ms:6.1f}x copy)")
        print(f"  area core, count (Af + uncertainty) {core_ms:9.3f} ms  ({core_ms / copy_ms:6.1f}x copy, "
              f"{core_ms / naive_ms:.2f}x naive, {core_ms / (1000 / 30):.0%} of a 30 fps frame interval)")
        print(f"  area core, sub-pixel                {subpixel_ms:9.3f} ms  ({subpixel_ms / copy_ms:6.1f}x copy, "
              f"{subpixel_ms / core_ms:.2f}x count)")
        print(f"  weights built {measurer.rebuilds} and {subpixel.rebuilds} time(s) for {repeats + 1} frames each")
    return 0


if __name__ == "__main__":
    sys.exit(main())
