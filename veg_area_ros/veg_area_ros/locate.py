"""Stage 1 of a frame's measurement, locate: the targets in the frame and the plane scale they give.

It exists because finding the markers, following them from frame to frame and fitting the scale is one job
that the rest only reads: the later stages take a `Located` (the targets in the idealized image, the fit) and
never look at markers. Takes the raw frame (or its grey), gives a `Located`; carries a `Tracking` from frame to
frame (the markers found, the last fit), so that markers that did not move keep their corners and their fit.

No ROS here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .classify import to_light
from .idealize import IdealView
from .markers import DetectedMarker, marker_centre, track_markers
from .scale import PlaneScale
from .target_error import marker_centre_std
from .targets import TargetsError, TargetsNotFoundError, TargetsSpec

MARKER_EXCLUSION = 1.5  # markers are cut out of the default ROI this much larger than their black square
NO_CALIBRATION_FOR_OFFSET = ("an object plane offset needs a calibration (the camera's pinhole); measure with "
                             "one, or put the targets in the object's plane")


@dataclass
class Located:
    """The targets of one frame, in the idealized image, and the scale they give."""
    scale: PlaneScale
    pixels: list[np.ndarray]
    labels: list[str]
    missing: list[int]
    holes: list[np.ndarray]  # marker squares (enlarged) to cut out of the default ROI
    offsets: list[np.ndarray]  # found markers' corners relative to their centre
    # the markers' centre localisation std measured from their corners' squareness on the plane (px per
    # coordinate; target_error), None where the scale gives no plane (two targets) or no marker was found
    marker_std_px: float | None = None

    @property
    def target_pixels(self) -> dict[str, np.ndarray]:
        return dict(zip(self.labels, self.pixels, strict=True))


@dataclass
class Tracking:
    """What locating carries from frame to frame: the raw-frame markers of the last frame, that frame's fit
    (where a hidden marker should be) and, while no marker moves, the `Located` they gave (kept, not refitted)."""
    markers: dict[int, DetectedMarker] = field(default_factory=dict)
    last_scale: PlaneScale | None = None
    last_located: tuple[list[DetectedMarker], Located] | None = None

    def forget(self) -> None:
        self.markers, self.last_scale, self.last_located = {}, None, None


COLLINEAR = 1e-3  # the targets' spread across their line, against along it, below which they span no plane


def _collinear(planes: np.ndarray) -> bool:
    centred = planes - planes.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False)
    return bool(spread[0] == 0 or spread[-1] / spread[0] < COLLINEAR)


class Locator:
    """Locates one camera's targets (`TargetsSpec`) in its frames."""

    def __init__(self, targets: TargetsSpec, view: IdealView, tone_curve: str = "linear"):
        self.targets, self.view = targets, view
        # markers are found in light: a blurred edge's grey levels through the sRGB curve thin the black cells
        # (at 1.2 px of blur a 640x480 frame's markers were found 1 in 4 times in encoded levels, 4 in 4 decoded)
        self.light_table = (None if tone_curve == "linear" else
                            np.clip(np.rint(to_light(np.arange(256), tone_curve)), 0, 255).astype(np.uint8))
        self.hand_pixels = view.to_ideal(np.array([p for p, _ in targets.points]).reshape(-1, 2))
        self.skip_unmoved_markers = True  # markers whose windows did not move keep their corners (markers.unmoved)

    def _hidden_marker_guesses(self, tracking: Tracking) -> dict[int, tuple[np.ndarray, float]]:
        """Where the listed markers the last frame missed should be (raw centre, half a search box of three
        marker sides), from that frame's fit of the others; none when that fit has no orientation."""
        scale = tracking.last_scale
        hidden = [marker_id for marker_id in self.targets.markers if marker_id not in tracking.markers]
        if not hidden or not tracking.markers or scale is None or scale.kind == "distance":
            return {}
        centres = self.view.to_raw(scale.plane_to_pixels(np.array([self.targets.markers[i] for i in hidden])))
        side = np.mean([np.ptp(marker.corners, axis=0).max() for marker in tracking.markers.values()])
        return {marker_id: (centre, 1.5 * side) for marker_id, centre in zip(hidden, centres, strict=True)}

    def locate(self, frame: np.ndarray, tracking: Tracking) -> Located:
        """Markers found in the raw frame (all of it: idealization pushes the periphery of a barrel-distorted
        frame out of view), their corners mapped into the idealized image and the centre intersected there;
        hand-picked points; the scale fit."""
        targets = self.targets
        located = Located(None, [], [], [], [], [])
        found_corners: list[np.ndarray] = []
        if targets.markers:
            if self.light_table is not None:
                frame = cv2.LUT(frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), self.light_table)
            tracking.markers = track_markers(frame, targets.dictionary, tracking.markers, set(targets.markers),
                                             self._hidden_marker_guesses(tracking),
                                             skip_unmoved=self.skip_unmoved_markers)
            found = [marker_id for marker_id in targets.markers if marker_id in tracking.markers]
            tracked = [tracking.markers[marker_id] for marker_id in found]
            last = tracking.last_located
            if last is not None and len(tracked) == len(last[0]) and all(
                    now is before for now, before in zip(tracked, last[0], strict=True)):
                return last[1]  # no marker moved: the same corners give the same fit
            located.missing = [marker_id for marker_id in targets.markers if marker_id not in tracking.markers]
            raw_corners = np.array([tracking.markers[marker_id].corners for marker_id in found]).reshape(-1, 2)
            for marker_id, corners in zip(found, self.view.to_ideal(raw_corners).reshape(-1, 4, 2), strict=True):
                centre = marker_centre(corners)
                located.pixels.append(centre)
                located.labels.append(f"marker {marker_id}")
                located.offsets.append(corners - centre)
                located.holes.append(centre + MARKER_EXCLUSION * located.offsets[-1])
                found_corners.append(corners)
        planes = [targets.markers[int(label.split()[1])] for label in located.labels]
        for k, ((_, plane), pixel) in enumerate(zip(targets.points, self.hand_pixels, strict=True)):
            located.pixels.append(pixel)
            located.labels.append(f"point {k}")
            planes.append(plane)
        if len(located.pixels) < 2:
            raise TargetsNotFoundError(f"only {len(located.pixels)} target(s) found in the frame; missing marker "
                                       f"ids {located.missing}", len(located.pixels) - len(targets.points))
        height, width = frame.shape[:2]
        for k, (pixel, _) in enumerate(targets.points):
            if not (-0.5 <= pixel[0] <= width - 0.5 and -0.5 <= pixel[1] <= height - 0.5):
                raise TargetsError(f"point {k} at ({pixel[0]:g}, {pixel[1]:g}) px lies outside the {width}x{height} "
                                   "frame: a hand-picked target must be a pixel of the image")
        if len(planes) >= 3 and _collinear(np.array(planes)):
            raise TargetsError(f"the {len(planes)} targets' plane coordinates lie on one line: they span no "
                               "plane to scale an area by (give points off that line, or two for a distance)")
        offset = targets.object_plane_offset_m
        if offset is not None and not self.view.calibrated:
            raise TargetsError(NO_CALIBRATION_FOR_OFFSET)
        located.scale = PlaneScale.fit(np.array(located.pixels), np.array(planes), targets.distance_std_m,
                                       targets.pixel_std, offset,
                                       self.view.ideal_matrix if offset is not None else None)
        if found_corners and located.scale.kind != "distance":
            located.marker_std_px = marker_centre_std(np.array(found_corners), planes[:len(found_corners)],
                                                      located.scale.matrix)
            # the targets file's std is the floor: a few markers' corners can form squares by chance
            stds = located.scale.pixel_stds()
            stds[:len(found_corners)] = max(targets.pixel_std, located.marker_std_px)
            located.scale.pixel_std = stds
        tracking.last_scale = located.scale
        if targets.markers:
            tracking.last_located = tracked, located
        return located
