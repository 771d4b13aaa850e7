"""The real ChArUco webcam video (`../shared/data/charuco-video/cam_0.mp4`, a 4x5 board printed white on
black) as an Af measurement: `veg-area calibrate` on the video itself, then in each frame that shows the four
outer inner corners, the dark area of the print inside the plane rectangle through the outer squares' centres,
those four corners as hand-picked targets, in the default mode (auto: the reading the calibration records,
judged on the video's own board views), with the shares and counted, with the calibration file as
`veg-area measure` reads it. The truth is the board's own drawing (OpenCV's, inverted as printed). A weak
reference (a weak calibration, crushed blacks): docs/measuring.md quotes it as such.

    PYTHONPATH=veg_area_ros:test .venv/bin/python test/charuco_video_board.py [VIDEO]
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
from held_out_board import scatter

from veg_area_ros.calib_io import read_calibration
from veg_area_ros.cli import main as veg_area
from veg_area_ros.settings import MeasurementSettings
from veg_area_ros.targets import TargetsSpec

VIDEO = Path(__file__).resolve().parents[2] / "shared/data/charuco-video/cam_0.mp4"
SQUARES, SQUARE_M, MARKER_M, DICTIONARY = (4, 5), 0.054, 0.0405, "DICT_4X4_1000"
OUTER = (0, 2, 11, 9)  # the four outer inner corners of a 4x5 board's 3x4, around the rectangle
MODES = ("auto", "subpixel", "count")  # the default (the reading the calibration records), the shares, counted


def dark_area_m2(board: cv2.aruco.CharucoBoard, px_per_square: int = 1000) -> float:
    """The print's dark area inside the rectangle through the outer squares' centres: the drawing's whites,
    the board being printed white on black."""
    cols, rows = SQUARES
    drawing = board.generateImage((cols * px_per_square, rows * px_per_square), marginSize=0, borderBits=1)
    half = px_per_square // 2
    inside = drawing[half:rows * px_per_square - half, half:cols * px_per_square - half]
    return float(np.mean(inside > 127)) * (cols - 1) * (rows - 1) * SQUARE_M**2


def board_frames(video: Path, board: cv2.aruco.CharucoBoard) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                                np.ndarray]]:
    """(frame, its grey inverted as the print needs, the chessboard corners refined by cornerSubPix, their ids)
    of each frame of the video where the board is found."""
    detector = cv2.aruco.CharucoDetector(board)
    capture = cv2.VideoCapture(str(video))
    try:
        while True:
            ok, frame = capture.read()
            if not ok:
                return
            grey = 255 - cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            corners, ids, _, _ = detector.detectBoard(grey)
            if ids is None:
                continue
            refined = cv2.cornerSubPix(grey, corners.reshape(-1, 1, 2).astype(np.float32), (5, 5), (-1, -1),
                                       (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 0.001))
            yield frame, grey, refined.reshape(-1, 2), ids.ravel()
    finally:
        capture.release()


def measure(video: Path) -> tuple[list[dict[str, tuple[float, float, bool]]], dict]:
    """(per frame measured: mode -> (Af over the truth, minus 1; reported std over the truth; shares applied),
    the calibration file's veg_area_ros block)."""
    with tempfile.TemporaryDirectory() as work, contextlib.redirect_stdout(io.StringIO()):
        calibration = Path(work) / "webcam.yaml"
        code = veg_area(["calibrate", str(video), "--board",
                         f"charuco:{SQUARES[0]}x{SQUARES[1]}:{SQUARE_M}:{MARKER_M}:{DICTIONARY}",
                         "-o", str(calibration), "--video-step", "1", "-q"])
        if code != 0:
            raise RuntimeError(f"veg-area calibrate exited {code}")
        calibration_file = read_calibration(calibration)
    camera = calibration_file.camera
    ideal = camera.ideal()
    board = cv2.aruco.CharucoBoard(SQUARES, SQUARE_M, MARKER_M,
                                   cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, DICTIONARY)))
    truth = dark_area_m2(board)
    chessboard = board.getChessboardCorners()[:, :2] / SQUARE_M  # in squares
    frames = []
    for frame, _, corners, ids in board_frames(video, board):
        if not set(OUTER) <= set(ids.tolist()):
            continue
        points = [{"pixel": corners[int(np.flatnonzero(ids == c)[0])].tolist(),
                   "plane": (chessboard[c] * SQUARE_M).tolist()} for c in OUTER]
        targets = TargetsSpec.from_dict({"points": points, "pixel_std": 0.1})
        idealized = ideal.normalized_to_pixels(camera.pixels_to_normalized(corners.astype(float)))
        homography, _ = cv2.findHomography(chessboard[ids].astype(np.float32), idealized.astype(np.float32))
        cols, rows = SQUARES
        rectangle = np.float32([[0.5, 0.5], [cols - 0.5, 0.5], [cols - 0.5, rows - 0.5], [0.5, rows - 0.5]])
        roi = cv2.perspectiveTransform(rectangle.reshape(-1, 1, 2), homography).reshape(-1, 2).astype(float)
        row = {}
        for mode in MODES:
            settings = MeasurementSettings(threshold="otsu", roi=tuple(np.ravel(roi)), area_mode=mode)
            result = settings.measurer(camera, targets,
                                       calibration_conditions=calibration_file.metadata).measure(frame)
            row[mode] = (result.area_m2 / truth - 1, result.area_std_m2 / truth, result.subpixel_applied)
        frames.append(row)
    return frames, calibration_file.metadata


def main(argv: list[str] | None = None) -> int:
    video = Path((argv or sys.argv[1:] or [str(VIDEO)])[0])
    frames, recorded = measure(video)
    print(f"the calibration records area mode {recorded.get('area_mode', 'none')}: "
          f"{recorded.get('area_mode_evidence')}")
    for mode in MODES:
        errors = np.array([f[mode][0] for f in frames])
        spread, worst, largest = scatter(errors, np.array([f[mode][1] for f in frames]))
        print(f"{mode:8s} {len(errors)} frames: mean {100 * errors.mean():+.2f} %, spread {100 * spread:.2f} %, "
              f"worst {100 * worst:.2f} % from the mean, each within {largest:.2f} reported std; shares applied in "
              f"{sum(f[mode][2] for f in frames)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
