"""The figure of docs/measuring.md's real photos: each well-exposed photo of three real cameras (OpenCV's
webcam pair and Udacity's camera, test/data) as its Af's distance from its set's mean, with ±1 of its
reported std, in the default mode (each photo measured with what the other views alone teach, as
test_real_photos.py measures it) and counted. Where a bar does not reach the zero line, the std did not hold.

    .venv/bin/python test/real_photos_figure.py docs/images/real_photos.png
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / "veg_area_ros"), str(HERE)]  # the working tree
from board_photos import board_photos, calibrated  # noqa: E402
from held_out_board import draw_photos  # noqa: E402
from helpers import OPENCV_LEFT, OPENCV_RIGHT, UDACITY_CAMERA  # noqa: E402
from test_real_photos import BOARD, _evidence, _measure, _with_the_others_trend  # noqa: E402

CAMERAS = (("OpenCV's left webcam", OPENCV_LEFT), ("OpenCV's right webcam", OPENCV_RIGHT),
           ("Udacity's camera (held out)", UDACITY_CAMERA))


def measured(folder: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per mode, each photo's relative error and its reported relative std."""
    camera = calibrated(str(folder), BOARD)
    evidence = _evidence(folder, camera)
    rows: dict[str, list[tuple[float, float]]] = {"default": [], "count": []}
    for photo in board_photos(folder, BOARD, camera=camera):
        if photo.clipped_share >= 0.01:
            continue
        _, shares = _with_the_others_trend(photo, camera, evidence)
        counted = _measure(photo, camera, "otsu", "count")
        for mode, result in (("default", shares), ("count", counted)):
            rows[mode].append((result.area_m2 / photo.true_area_m2 - 1, result.area_std_m2 / photo.true_area_m2))
    return {mode: (np.array([e for e, _ in r]), np.array([s for _, s in r])) for mode, r in rows.items()}


def main(path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(CAMERAS), figsize=(13, 4.2), sharey=True)
    for ax, (title, folder) in zip(axes, CAMERAS, strict=True):
        for mode, (spread, worst, largest) in draw_photos(ax, measured(folder)).items():
            print(f"{title}: {mode} sd {spread:.3f} %, worst {worst:.3f} %, at most {largest:.2f} std")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("photo (whites under 250)")
        ax.legend(fontsize=8, loc="lower left")
    axes[0].set_ylabel("Af from the set's mean [%], ±1 reported std")
    figure.tight_layout()
    figure.savefig(path, dpi=110)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "real_photos.png")
