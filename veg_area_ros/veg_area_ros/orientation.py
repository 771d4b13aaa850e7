"""An image file's EXIF orientation, and its pixels kept in the grid they were stored in (the sensor's).

A phone or a DSLR writes which way up it was held (EXIF tag 274, 1-8), and OpenCV, like a photo viewer, turns
the image by it when decoding. A phone's video carries the same as a rotation
of its container's display matrix. A camera held by hand around a board, or pointing straight down at a flume,
writes a different tag from shot to shot: turned, the same sensor gave 640x480 and 480x640 frames, so a
calibration kept only the views of one orientation (and fitted the sensor turned), and a photo taken the other
way round was refused by it. The lens's geometry belongs to the sensor's grid, so frames are read as stored,
and a frame whose tag would have turned it says so (its pixel coordinates are not a viewer's).

No ROS here.
"""

from __future__ import annotations

import numpy as np

from .exif import exif_tags

# what a viewer does to the stored image for each tag
SHOWN_AS = {2: "mirrored left to right", 3: "turned 180°", 4: "mirrored top to bottom",
            5: "mirrored along its diagonal", 6: "turned 90° clockwise", 7: "mirrored along its other diagonal",
            8: "turned 90° anticlockwise"}


def stored_orientation(data: bytes) -> int:
    """The EXIF orientation (1-8) a JPEG, PNG, WebP or TIFF file records; 1 where it records none."""
    orientation = exif_tags(data)[0]
    return orientation if orientation in SHOWN_AS else 1


def as_stored(shown: np.ndarray, orientation: int) -> np.ndarray:
    """The stored grid of an image that was turned for showing by `orientation` (the inverse of SHOWN_AS)."""
    undo = {2: lambda x: x[:, ::-1], 3: lambda x: x[::-1, ::-1], 4: lambda x: x[::-1],
            5: lambda x: np.swapaxes(x, 0, 1), 6: lambda x: np.rot90(x, 1),
            7: lambda x: np.swapaxes(x, 0, 1)[::-1, ::-1], 8: lambda x: np.rot90(x, -1)}
    return np.ascontiguousarray(undo[orientation](shown)) if orientation in undo else shown


def video_rotation_note(degrees: float) -> str:
    """What a video's frame read as stored says where its container's display matrix would have turned it."""
    turn = round(degrees) % 360
    if turn == 0:
        return ""
    return (f"video rotation {turn}° not applied: read as stored, the sensor's pixel grid that the calibration "
            "holds for, which a video player shows turned; a ROI or hand-picked pixels are taken in the stored grid")


def orientation_note(orientation: int) -> str:
    """What a frame read as stored says where its file would have been turned ('' where it would not)."""
    if orientation not in SHOWN_AS:
        return ""
    return (f"EXIF orientation {orientation} not applied: read as stored, the sensor's pixel grid that the "
            f"calibration holds for, which a photo viewer shows {SHOWN_AS[orientation]}; a ROI or hand-picked "
            "pixels are taken in the stored grid")
