"""Real photos of a printed chessboard as an Af measurement with a known answer: the black area of the print
inside the plane rectangle through the centres of the outer squares, the four outer inner corners as
hand-picked targets, the camera calibrated on the same photos. The ink's gain shifts every photo of one print
alike; the scatter between photos is what the measurement must keep small."""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from veg_area_ros.board import BoardSpec
from veg_area_ros.calibration import View, calibrate
from veg_area_ros.camera_model import BrownCamera
from veg_area_ros.targets import TargetsSpec
from veg_area_ros.tone_evidence import _within, board_case

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
    """Each photo of `folder` (*.jpg, *.png) where the board is found, with its detection; photos of another
    size than the first one's are left out, as `veg-area calibrate` leaves them."""
    board = BoardSpec.parse(board_spec)
    found, size = [], None
    for path in sorted([*Path(folder).glob("*.jpg"), *Path(folder).glob("*.png")]):
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        size = size or image.shape
        if image.shape != size:
            continue
        detection = board.detect(image)
        if detection is not None:
            found.append((path.name, detection))
    return tuple(found)


@functools.cache
def calibrated(folder: str, board_spec: str) -> BrownCamera:
    """The camera calibrated on every photo of `folder` where the board is found."""
    found = detections(folder, board_spec)
    size = cv2.imread(str(Path(folder) / found[0][0]), cv2.IMREAD_GRAYSCALE).shape[::-1]
    return calibrate([View(name, detection) for name, detection in found], size).camera


def metric(detection, spec: BoardSpec):
    """A detection of the board `spec` with its board points in metres, the print's square taken as SQUARE_M."""
    return replace(detection, object_points=np.asarray(detection.object_points) / spec.square * SQUARE_M)


def board_photos(folder: Path, board_spec: str = "chessboard:9x6:1", camera: BrownCamera | None = None
                 ) -> list[BoardPhoto]:
    """Each photo of `folder` where the board is found, as a measurement with its targets, ROI and truth
    (`tone_evidence.board_case`, the print's square taken as SQUARE_M); with the camera calibrated on them, or
    `camera`. A photo whose rectangle leaves the image is kept: its ROI then says how much has no pixel; one
    whose first outer square lies beyond the image is left out (which squares are black cannot be read)."""
    spec = BoardSpec.parse(board_spec)
    board = replace(spec, square=SQUARE_M)
    camera = camera or calibrated(str(folder), board_spec)
    photos = []
    for name, detection in detections(str(folder), board_spec):
        frame = cv2.imread(str(folder / name), cv2.IMREAD_COLOR)
        case = board_case(name, metric(detection, spec), board, camera, inside_only=False)
        grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        if not _within(case.first_black_probe, camera, 0):
            continue
        mask = np.zeros(grey.shape, np.uint8)
        hull = cv2.convexHull(np.asarray(detection.image_points, np.float32).reshape(-1, 2)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 255)
        clipped = float(np.count_nonzero(grey[mask > 0] >= 250)) / max(cv2.countNonZero(mask), 1)
        area = case.true_area_m2(board, case.first_black(grey))
        photos.append(BoardPhoto(name, frame, case.targets, [tuple(p) for p in case.roi.tolist()], area, clipped))
    return photos
