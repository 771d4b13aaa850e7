"""The targets file: the targets in the object's plane (ArUco markers by id, or points picked by hand) with
their plane positions, uncertainties and the optional object plane offset, read and validated:

    dictionary: DICT_4X4_50
    markers:            # marker id: centre [x, y] in the object plane, metres
      0: [-0.22, -0.16]
      1: [0.22, -0.16]
    points:             # optional hand-picked targets: raw-frame pixel and plane position
      - {pixel: [u, v], plane: [x, y]}
    distance_std_m: 0.0005      # calliper uncertainty of target distances (default 0.5 mm)
    pixel_std: 0.1              # localisation uncertainty of a target centre, px (default 0.1)
    object_plane_offset_m: 0.035     # optional: object's plane this far behind the targets' (+ = farther)
    object_plane_offset_std_m: 0.002 # its uncertainty (default 2 mm when an offset is given)

No ROS here.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from .strict_yaml import StrictYamlError, load_text, read_text

# the targets' extent in their plane: a flume's or river's scene is centimetres to metres across; outside this
# range the coordinates are in the wrong unit (millimetres as metres gave Af of 1e24 m²)
MIN_TARGET_SPAN_M = 0.002
MAX_TARGET_SPAN_M = 50.0
# every key a targets file may hold: any other is a typo that would be passed over (an `object_plane_ofset_m`
# measured the object in the targets' plane without a word)
TARGETS_KEYS = ("dictionary", "markers", "points", "distance_std_m", "pixel_std", "object_plane_offset_m",
                "object_plane_offset_std_m", "marker_side_m")
POINT_KEYS = ("pixel", "plane")
CALIBRATION_KEYS = ("camera_matrix", "image_width", "image_height", "distortion_coefficients")


class TargetsError(ValueError):
    """A targets file or a frame's targets that cannot give a scale; the message says why."""


class TargetsNotFoundError(TargetsError):
    """A frame that shows too few of its targets; `markers_found`: how many of the ArUco markers it showed (none
    where the markers are printed from another dictionary than the targets file names)."""

    def __init__(self, message: str, markers_found: int) -> None:
        super().__init__(message)
        self.markers_found = markers_found


def _pair(value: object, what: str) -> np.ndarray:
    try:
        pair = np.array(value, dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise TargetsError(f"{what} must be two numbers, got {value!r}") from exc
    if pair.size != 2 or not np.all(np.isfinite(pair)):
        raise TargetsError(f"{what} must be two finite numbers, got {value!r}")
    return pair


@dataclass
class TargetsSpec:
    dictionary: str = ""
    markers: dict[int, np.ndarray] = field(default_factory=dict)  # id -> plane (x, y), metres
    points: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # (raw pixel, plane)
    distance_std_m: float = 0.0005
    pixel_std: float = 0.1
    object_plane_offset_m: float | None = None  # None: the object lies in the targets' plane (the paper's set-up)
    object_plane_offset_std_m: float = 0.002
    marker_side_m: float | None = None  # the black square's side: checks the layout's scale against each marker

    @classmethod
    def load(cls, path: str | Path) -> TargetsSpec:
        path = Path(path)
        try:
            content = load_text(read_text(path))
        except StrictYamlError as exc:
            raise TargetsError(f"{path}: {exc}") from exc
        except FileNotFoundError as exc:
            raise TargetsError(f"{path}: no such targets file") from exc
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise TargetsError(f"{path}: not a readable YAML targets file ({exc.__class__.__name__})") from exc
        try:
            return cls.from_dict(content)
        except TargetsError as exc:
            raise TargetsError(f"{path}: {exc}") from exc

    @classmethod
    def from_dict(cls, content: object) -> TargetsSpec:
        if not isinstance(content, dict):
            raise TargetsError("expected a mapping with 'markers' and/or 'points'")
        _known_keys(content, TARGETS_KEYS, "a targets file")
        spec = cls(dictionary=str(content.get("dictionary", "")).upper())
        if spec.dictionary and not spec.dictionary.startswith("DICT_"):  # '4X4_50', as OpenCV's docs name them
            spec.dictionary = f"DICT_{spec.dictionary}"
        markers = content.get("markers") or {}
        if not isinstance(markers, dict):
            raise TargetsError("'markers' must map marker ids to [x, y]")
        for marker_id, plane in markers.items():
            if not isinstance(marker_id, int) or isinstance(marker_id, bool) or marker_id < 0:
                raise TargetsError(f"marker id {marker_id!r} is not a non-negative integer")
            spec.markers[marker_id] = _pair(plane, f"marker {marker_id}")
        if spec.markers and not (spec.dictionary.startswith("DICT_") and hasattr(cv2.aruco, spec.dictionary)):
            raise TargetsError(f"unknown or missing ArUco dictionary {content.get('dictionary')!r}")
        for k, entry in enumerate(content.get("points") or []):
            if not isinstance(entry, dict) or "pixel" not in entry or "plane" not in entry:
                raise TargetsError(f"point {k} needs 'pixel' and 'plane'")
            _known_keys(entry, POINT_KEYS, f"point {k}")
            spec.points.append((_pair(entry["pixel"], f"point {k} pixel"), _pair(entry["plane"], f"point {k} plane")))
        if "marker_side_m" in content:
            side = content["marker_side_m"]
            if not _is_number(side) or not 0 < side <= 10:
                raise TargetsError(f"'marker_side_m' must be a side in metres, got {side!r}")
            spec.marker_side_m = float(side)
        for key in ("distance_std_m", "pixel_std", "object_plane_offset_std_m"):
            if key in content:
                value = content[key]
                if not _is_number(value) or value < 0:
                    raise TargetsError(f"'{key}' must be a non-negative number, got {value!r}")
                setattr(spec, key, float(value))
        planes = [tuple(p) for p in spec.markers.values()] + [tuple(p) for _, p in spec.points]
        if len(planes) < 2:
            raise TargetsError(f"{len(planes)} target(s) given; at least 2 are needed for a scale")
        if len(set(planes)) != len(planes):
            raise TargetsError("two targets share the same plane position")
        span = float(np.max(np.ptp(np.array(planes, float), axis=0)))
        if not MIN_TARGET_SPAN_M <= span <= MAX_TARGET_SPAN_M:
            raise TargetsError(f"the targets span {span:.3g} m in their plane; plane positions are in metres "
                               f"({MIN_TARGET_SPAN_M * 1000:g} mm to {MAX_TARGET_SPAN_M:g} m for a scene a camera "
                               "sees whole): " + ("millimetres given as metres?" if span > MAX_TARGET_SPAN_M
                                                  else "metres given as kilometres?"))
        if "object_plane_offset_m" in content:
            offset = content["object_plane_offset_m"]
            if not _is_number(offset) or abs(offset) > 10:
                raise TargetsError(f"'object_plane_offset_m' must be a distance in metres, got {offset!r}")
            if len(planes) < 4:
                raise TargetsError(f"an object plane offset needs 4 or more targets (their plane's pose); this file "
                                   f"lists {len(planes)}: put the targets in the object's plane, or add targets")
            spec.object_plane_offset_m = float(offset)
        elif "object_plane_offset_std_m" in content:
            raise TargetsError("'object_plane_offset_std_m' given without 'object_plane_offset_m'")
        return spec

    def all_planes(self) -> np.ndarray:
        """Plane positions of every listed target, markers then points (N, 2)."""
        return np.array([*self.markers.values(), *(plane for _, plane in self.points)], float).reshape(-1, 2)


def _known_keys(content: dict, known: tuple[str, ...], what: str) -> None:
    """Refuse keys `what` does not have, each with the known one it is most like; a calibration given in its
    place is named as such."""
    unknown = [key for key in content if key not in known]
    if not unknown:
        return
    if what == "a targets file" and any(key in content for key in CALIBRATION_KEYS):
        raise TargetsError("this is a camera calibration (it has camera_matrix, image_width ...), not a targets "
                           "file: were the calibration and the targets swapped?")
    said = []
    for key in unknown:
        like = difflib.get_close_matches(str(key), known, n=1, cutoff=0.8)
        said.append(f"{key!r}" + (f" (did you mean {like[0]!r}?)" if like else ""))
    raise TargetsError(f"{what} has no key {', '.join(said)}; its keys are {', '.join(known)}")


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and bool(np.isfinite(value))
