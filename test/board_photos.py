"""Real photos of a printed chessboard as an Af measurement with a known answer: the black area of the print
inside the plane rectangle through the centres of the outer squares, the four outer inner corners as
hand-picked targets, the camera calibrated on the same photos. The ink's gain shifts every photo of one print
alike; the scatter between photos is what the measurement must keep small."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from veg_area_ros.board import BoardSpec
from veg_area_ros.calibration import View, calibrate
from veg_area_ros.camera_model import BrownCamera
from veg_area_ros.targets import TargetsSpec

SQUARE_M = 0.025  # the print's square is not published; any side gives the same relative figures


@dataclass
class BoardPhoto:
    name: str
    frame: np.ndarray  # BGR as decoded
    targets: TargetsSpec
    roi: list[tuple[float, float]]  # idealized px: the rectangle through the outer squares' centres
    true_area_m2: float  # the black squares' area inside it
    clipped_share: float  # share of the board's pixels at 250 or more


@functools.cache
def detections(folder: str, board_spec: str) -> tuple[tuple[str, object], ...]:
    """Each photo of `folder` (*.jpg, *.png) where the board is found, with its detection."""
    board = BoardSpec.parse(board_spec)
    found = []
    for path in sorted([*Path(folder).glob("*.jpg"), *Path(folder).glob("*.png")]):
        detection = board.detect(cv2.imread(str(path), cv2.IMREAD_COLOR))
        if detection is not None:
            found.append((path.name, detection))
    return tuple(found)


@functools.cache
def calibrated(folder: str, board_spec: str) -> BrownCamera:
    """The camera calibrated on every photo of `folder` where the board is found."""
    found = detections(folder, board_spec)
    size = cv2.imread(str(Path(folder) / found[0][0]), cv2.IMREAD_GRAYSCALE).shape[::-1]
    return calibrate([View(name, detection) for name, detection in found], size).camera


def _black_area(cols: int, rows: int, first_black: bool) -> float:
    """Black area (in squares²) of a chessboard of (cols+1) x (rows+1) squares inside the rectangle through its
    outer squares' centres: quarter squares at the corners, halves along the sides, whole ones inside."""
    total = 0.0
    for i in range(cols + 1):
        for j in range(rows + 1):
            black = ((i + j) % 2 == 0) == first_black
            share_x = 0.5 if i in (0, cols) else 1.0
            share_y = 0.5 if j in (0, rows) else 1.0
            total += black * share_x * share_y
    return total


def board_photos(folder: Path, board_spec: str = "chessboard:9x6:1", camera: BrownCamera | None = None
                 ) -> list[BoardPhoto]:
    """Each photo of `folder` where the board is found, as a measurement with its targets, ROI and truth; with
    the camera calibrated on them, or `camera`."""
    board = BoardSpec.parse(board_spec)
    found = detections(str(folder), board_spec)
    camera = camera or calibrated(str(folder), board_spec)
    ideal = camera.ideal()
    cols, rows = board.cols, board.rows
    photos = []
    for name, detection in found:
        frame = cv2.imread(str(folder / name), cv2.IMREAD_COLOR)
        ids = np.asarray(detection.ids).ravel()
        squares = np.asarray(detection.object_points)[:, :2] / board.square  # board coordinates in squares
        raw = np.asarray(detection.image_points, float).reshape(-1, 2)
        corner_ids = [0, cols - 1, cols * rows - 1, cols * (rows - 1)]
        points = []
        for corner in corner_ids:
            k = int(np.flatnonzero(ids == corner)[0])
            points.append({"pixel": raw[k].tolist(), "plane": (squares[k] * SQUARE_M).tolist()})
        targets = TargetsSpec.from_dict({"points": points})
        # the rectangle through the outer squares' centres, half a square beyond the outer inner corners
        idealized = ideal.normalized_to_pixels(camera.pixels_to_normalized(raw))
        homography, _ = cv2.findHomography(squares.astype(np.float32), idealized.astype(np.float32))
        (x0, y0), (x1, y1) = squares.min(axis=0) - 0.5, squares.max(axis=0) + 0.5
        rectangle = np.float32([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]).reshape(-1, 1, 2)
        roi = cv2.perspectiveTransform(rectangle, homography).reshape(-1, 2)
        # which colour the square before the first inner corner has: read in the photo
        grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        inward = cv2.perspectiveTransform(np.float32([[[squares[0, 0] - 0.5, squares[0, 1] - 0.5],
                                                       [squares[0, 0] + 0.5, squares[0, 1] - 0.5]]]),
                                          homography)[0]
        raw_probe = camera.normalized_to_pixels(ideal.pixels_to_normalized(inward.astype(float)))
        values = [float(grey[round(v), round(u)]) for u, v in raw_probe]
        first_black = values[0] < values[1]
        area = _black_area(cols, rows, first_black) * SQUARE_M**2
        mask = np.zeros(grey.shape, np.uint8)
        hull = cv2.convexHull(raw.astype(np.float32)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 255)
        clipped = float(np.count_nonzero(grey[mask > 0] >= 250)) / max(cv2.countNonZero(mask), 1)
        photos.append(BoardPhoto(name, frame, targets, [tuple(p) for p in roi.tolist()], area, clipped))
    return photos
