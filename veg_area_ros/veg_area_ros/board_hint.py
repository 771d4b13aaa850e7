"""What board the images hold when the one the user named is found in none of them: the mistakes a person makes
writing a board spec (a chessboard's squares counted instead of its inner corners, a ChArUco board's squares
in the other order or its layout of another OpenCV version, another ArUco dictionary, a circle grid of the other
kind), tried on a few frames."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import cv2
import numpy as np

from .board import BoardSpec

# the largest dictionary of each family: its first markers are the smaller ones' (DICT_4X4_50 is 4X4_1000's 0-49)
ARUCO_FAMILIES = ("DICT_4X4_1000", "DICT_5X5_1000", "DICT_6X6_1000", "DICT_7X7_1000", "DICT_ARUCO_ORIGINAL",
                  "DICT_APRILTAG_36h11")
MIN_MARKERS = 4  # fewer could be a pattern in the scene read as markers


def _alternatives(board: BoardSpec) -> list[tuple[BoardSpec, str]]:
    """Boards the user may have meant, each with what the mistake was."""
    cols, rows = board.cols, board.rows
    if board.kind == "chessboard":
        return [(replace(board, cols=cols - 1, rows=rows - 1), "a chessboard's size counts its inner corners, one "
                 "fewer than its squares each way"),
                (replace(board, cols=cols + 1, rows=rows + 1), "a chessboard's size counts its inner corners, "
                 "where four squares meet")]
    if board.kind == "charuco":
        swapped = [(replace(board, cols=rows, rows=cols), "a ChArUco board's size is its squares across, then down")]
        if rows % 2:
            return swapped
        layout = (replace(board, legacy=not board.legacy), "a ChArUco board with an even number of rows is laid out "
                  "one way by OpenCV 4.6 and later and the other by earlier versions and calib.io: "
                  + ("drop :legacy" if board.legacy else "add :legacy to the spec"))
        return [layout, *swapped]
    return [(replace(board, symmetric=not board.symmetric), "circle grids come symmetric or asymmetric")]


def marker_family(grey: np.ndarray) -> tuple[str, int, int] | None:
    """The ArUco family whose markers the frame holds (either way round in tone): (dictionary, markers, the
    largest id), or None."""
    best = None
    for name in ARUCO_FAMILIES:
        detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)))
        for tone in (grey, 255 - grey):
            _, ids, _ = detector.detectMarkers(tone)
            if ids is not None and len(ids) >= MIN_MARKERS and (best is None or len(ids) > best[1]):
                best = (name, len(ids), int(ids.max()))
    return best


def _family(dictionary: str) -> str:
    """DICT_4X4_250 -> DICT_4X4; a dictionary without sizes (DICT_ARUCO_ORIGINAL) is its own family."""
    head, _, size = dictionary.rpartition("_")
    return head if size.isdigit() and head.count("X") == 1 else dictionary


def _capacity(dictionary: str) -> int:
    """How many markers a dictionary holds."""
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)).bytesList.shape[0]


def _smallest_dictionary(family: str, largest_id: int) -> str:
    """The smallest standard dictionary of a family that holds `largest_id` (DICT_4X4_50 for ids under 50)."""
    if not family.endswith("_1000"):
        return family
    size = next(n for n in (50, 100, 250, 1000) if largest_id < n)
    return f"{family[:-len('1000')]}{size}"


def _markers_seen(dictionary: str, grey: np.ndarray) -> tuple[int, bool, tuple[str, str]] | None:
    """The ArUco markers this frame holds, set against `dictionary`: (how many, whether they are that
    dictionary's, the family and largest id said in words with the dictionary to write), or None."""
    found = marker_family(grey)
    if found is None:
        return None
    name, count, largest = found
    ours = _family(name) == _family(dictionary) and largest < _capacity(dictionary)
    return count, ours, (f"{_family(name).removeprefix('DICT_')} markers (ids up to {largest}), not {dictionary}'s",
                         _smallest_dictionary(name, largest))


def board_hint(board: BoardSpec, greys: Sequence[np.ndarray]) -> str:
    """Why `board` may be found in none of these grey frames: another spec found in them, with the mistake it
    corrects ('' when none is found)."""
    for other, why in _alternatives(board):
        found = sum(other.detect(grey) is not None for grey in greys)
        if found:
            return f"; {other} is found in {found} of the {len(greys)} frames tried: {why}"
    if board.kind != "charuco":
        return ""
    for grey in greys:
        seen = _markers_seen(board.dictionary, grey)
        if seen is None:
            continue
        count, ours, (held, suggested) = seen
        if ours:
            return (f"; {count} {board.dictionary} markers are found but no {board.cols}x{board.rows} board: check "
                    "the squares across and down, and the marker's size against the square's")
        return f"; the frames hold {held}: try {suggested}"
    return ""


def dictionary_hint(dictionary: str, grey: np.ndarray) -> str:
    """Why a targets file's markers of `dictionary` may be found nowhere in this frame: the ArUco family the
    frame holds instead, with the dictionary to write ('' when it holds none, or the same family)."""
    seen = _markers_seen(dictionary, grey)
    if seen is None or seen[1]:
        return ""
    held, suggested = seen[2]
    return f"; the frame holds {held}: is the targets file's dictionary {suggested}?"
