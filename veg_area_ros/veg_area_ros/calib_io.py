"""Calibration files in the camera_info YAML of ROS's camera_calibration / camera_info_manager.

No ROS here. The standard keys (image_width, image_height, camera_name, camera_matrix, distortion_model,
distortion_coefficients, rectification_matrix, projection_matrix) are what ROS tools read; what a
researcher needs later (medium, calibration distance, residuals, uncertainties, date, board) goes under
the extra key ``veg_area_ros``, which ROS's parsers ignore. The projection matrix is the idealized camera
(no distortion, square pixels, principal point at the image centre), so ROS's own rectification produces
the idealized image this package measures.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from . import __version__
from .camera_info import camera_from_info, camera_info_fields
from .camera_model import BrownCamera, check_plausible
from .camera_uncertainty import CameraCovariance
from .files import write_atomic
from .flat_port import PORT_KEY, FlatPortCamera, port_from_dict
from .strict_yaml import StrictYamlError, dump_portable, load_text, read_text

METADATA_KEY = "veg_area_ros"


class CalibrationFileError(ValueError):
    """A calibration file that cannot be read; the message names the file and the problem."""


@dataclass
class CalibrationFile:
    camera: BrownCamera  # plumb_bob: the calibration, or a flat port's absorbed equivalent at one distance
    camera_name: str = "camera"
    metadata: dict[str, Any] = field(default_factory=dict)

    def port_camera(self) -> FlatPortCamera | None:
        """The air lens behind its flat port, when the file carries one (`veg-area calibrate --port`)."""
        block = self.metadata.get(PORT_KEY)
        return None if block is None else port_from_dict(block, self.camera.image_size)


def _matrix(rows: int, cols: int, values: np.ndarray) -> dict[str, Any]:
    return {"rows": rows, "cols": cols, "data": [float(v) for v in np.asarray(values, float).ravel()]}


def to_camera_info_dict(camera: BrownCamera, camera_name: str = "camera",
                        metadata: dict[str, Any] | None = None) -> dict[str, Any]:
    fields = camera_info_fields(camera)
    content: dict[str, Any] = {
        "image_width": fields["width"],
        "image_height": fields["height"],
        "camera_name": camera_name,
        "camera_matrix": _matrix(3, 3, fields["k"]),
        "distortion_model": fields["distortion_model"],
        "distortion_coefficients": _matrix(1, len(fields["d"]), fields["d"]),
        "rectification_matrix": _matrix(3, 3, fields["r"]),
        "projection_matrix": _matrix(3, 4, fields["p"]),
    }
    if metadata:
        content[METADATA_KEY] = plain(metadata)
    return content


METADATA_MATCH_FIELDS = ("width", "height", "distortion_model", "k", "d")


def metadata_message(camera: BrownCamera, metadata: dict[str, Any]) -> str:
    """A calibration's metadata (medium, distance, tone curve...: what camera_info cannot carry) as the JSON
    text the nodes publish beside camera_info (`camera_info/metadata`), with the calibration it belongs to so
    a receiver applies it only to that calibration."""
    fields = camera_info_fields(camera)
    return json.dumps({"calibration": {name: plain(fields[name]) for name in METADATA_MATCH_FIELDS},
                       "metadata": plain(metadata)}, default=str)


def metadata_for(camera: BrownCamera, text: str) -> dict[str, Any] | None:
    """The metadata in `text` (`metadata_message`) if it belongs to `camera`'s calibration, else None. Raises
    ValueError for text that is not such a message."""
    try:
        content = json.loads(text)
        calibration, metadata = content["calibration"], content["metadata"]
        if not isinstance(metadata, dict) or not isinstance(calibration, dict):
            raise TypeError("calibration and metadata must be objects")
        fields = camera_info_fields(camera)
        for name in METADATA_MATCH_FIELDS:
            mine, theirs = fields[name], calibration[name]
            if name == "distortion_model":
                if mine != theirs:
                    return None
            elif np.shape(mine) != np.shape(theirs) or not np.allclose(mine, theirs, rtol=1e-9, atol=1e-12):
                return None
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"not a calibration metadata message: {exc}") from exc
    return metadata


def plain(value: Any) -> Any:
    """numpy scalars and arrays -> plain Python, so the YAML stays readable by any parser."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


def write_calibration(path: str | os.PathLike, camera: BrownCamera, camera_name: str = "camera",
                      metadata: dict[str, Any] | None = None) -> None:
    write_atomic(path, dump_portable(to_camera_info_dict(camera, camera_name, metadata)))


def _numbers(path: Path, content: dict, key: str, rows: int, cols: int | None) -> np.ndarray:
    entry = content.get(key)
    if not isinstance(entry, dict) or "data" not in entry:
        raise CalibrationFileError(f"{path}: '{key}' is missing or has no 'data' list")
    try:
        data = np.array(entry["data"], dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise CalibrationFileError(f"{path}: '{key}' data is not a list of numbers") from exc
    expected = rows * cols if cols else None
    if expected is not None and data.size != expected:
        raise CalibrationFileError(f"{path}: '{key}' should hold {expected} numbers, found {data.size}")
    if not np.all(np.isfinite(data)):
        raise CalibrationFileError(f"{path}: '{key}' holds NaN or infinite values")
    return data


def from_camera_info_dict(content: Any, path: Path) -> CalibrationFile:
    if not isinstance(content, dict):
        raise CalibrationFileError(f"{path}: not a camera_info calibration (expected a YAML mapping)")
    for key in ("image_width", "image_height"):
        value = content.get(key)
        if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
            raise CalibrationFileError(f"{path}: '{key}' must be a positive integer, found {value!r}")
    model = content.get("distortion_model", "plumb_bob")
    K = _numbers(path, content, "camera_matrix", 3, 3)
    dist = _numbers(path, content, "distortion_coefficients", 1, None)
    if dist.size == 0 and model != "equidistant":  # a missing key is refused: an empty list is no answer either
        raise CalibrationFileError(f"{path}: 'distortion_coefficients' holds no numbers; give the model's "
                                   "coefficients (zeros for a lens without distortion)")
    try:
        camera = camera_from_info(content["image_width"], content["image_height"], str(model), dist, K)
    except ValueError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    metadata = content.get(METADATA_KEY) or {}
    if not isinstance(metadata, dict):
        raise CalibrationFileError(f"{path}: '{METADATA_KEY}' must be a mapping")
    calibration = CalibrationFile(camera, str(content.get("camera_name", "camera")), metadata)
    try:
        port_camera = calibration.port_camera()
        if port_camera is not None:
            check_plausible(port_camera.lens)
    except ValueError as exc:  # PortError too
        raise CalibrationFileError(f"{path}: {exc}") from exc
    return calibration


OST_INI_KEYS = {"camera matrix": ("camera_matrix", 3, 3), "distortion": ("distortion_coefficients", 1, None),
                "rectification": ("rectification_matrix", 3, 3), "projection": ("projection_matrix", 3, 4)}


def is_ost_ini(path: Path, text: str) -> bool:
    """Whether a calibration file is ROS 1 cameracalibrator's INI (`ost.ini`, '# oST version 5.0 parameters')."""
    return path.suffix.lower() == ".ini" or re.search(r"^\s*\[image\]\s*$", text, re.MULTILINE) is not None


def ost_ini_content(text: str, path: Path) -> dict[str, Any]:
    """The camera_info fields of ROS 1 cameracalibrator's `ost.ini`: an [image] section (width, height) and one
    camera section (camera matrix, distortion, rectification, projection), each key on its own line and its
    numbers on the lines below. A stereo pair's file (two camera sections) is refused with their names."""
    sections: list[tuple[str, dict[str, list[float]]]] = []
    key = None
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if line.startswith("[") and line.endswith("]"):
            sections.append((line[1:-1].strip(), {}))
            key = None
            continue
        if not sections:
            raise CalibrationFileError(f"{path}: not an ost.ini calibration: line {number} comes before any [section]")
        try:
            values = [float(word) for word in line.split()]
        except ValueError:
            key = line.lower()
            sections[-1][1][key] = []
            continue
        if key is None:
            raise CalibrationFileError(f"{path}: line {number} of ost.ini holds numbers under no key")
        sections[-1][1][key].extend(values)
    image = {k: v for name, entries in sections if name == "image" for k, v in entries.items()}
    cameras = [(name, entries) for name, entries in sections if name != "image"]
    if len(cameras) != 1:
        names = ", ".join(name for name, _ in cameras) or "none"
        raise CalibrationFileError(f"{path}: an ost.ini with {len(cameras)} camera sections ({names}); "
                                   "measuring needs one camera's (a stereo pair's file holds two: split it)")
    name, entries = cameras[0]
    content: dict[str, Any] = {"camera_name": name}
    for side in ("width", "height"):
        values = image.get(side, [])
        if len(values) != 1 or not float(values[0]).is_integer():
            raise CalibrationFileError(f"{path}: ost.ini's [image] needs one whole '{side}', found {values}")
        content[f"image_{side}"] = int(values[0])
    for ini_key, (field_name, rows, cols) in OST_INI_KEYS.items():
        if ini_key in entries:
            data = entries[ini_key]
            content[field_name] = {"rows": rows, "cols": cols or len(data), "data": data}
    content["distortion_model"] = "plumb_bob" if len(entries.get("distortion", [])) <= 5 else "rational_polynomial"
    return content


# what OpenCV's calibration sample, its interactive calibrator and common scripts name the fields
OPENCV_KEYS = {"camera_matrix": ("camera_matrix", "cameraMatrix", "K", "intrinsic_matrix"),
               "distortion_coefficients": ("distortion_coefficients", "distCoeffs", "dist_coeffs", "D")}
OPENCV_SIZE_KEYS = ("cameraResolution", "image_size", "imageSize")  # [width, height]


def is_opencv_storage(text: str) -> bool:
    """Whether a calibration file is OpenCV's FileStorage (YAML with '!!opencv-matrix' or '%YAML:1.0', or XML)."""
    head = text.lstrip()[:200]
    return head.startswith("%YAML:") or "!!opencv-matrix" in text or "<opencv_storage>" in head


def opencv_storage_content(text: str, path: Path) -> dict[str, Any]:
    """The camera_info fields of a calibration saved with OpenCV's FileStorage (YAML or XML): the camera matrix,
    the distortion coefficients and the image size under the names OpenCV's tools use. OpenCV files do not name
    the model: 5 coefficients are plumb_bob and 8 rational_polynomial; 4 (OpenCV's k1 k2 p1 p2, or cv2.fisheye's
    k1-k4) are refused unless a `distortion_model` entry says which."""
    import cv2

    try:
        storage = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as exc:  # a parse error comes as either, by where OpenCV's parser stops
        cause = exc.__cause__ if isinstance(exc, SystemError) and exc.__cause__ is not None else exc
        reason = (str(cause).strip().splitlines() or ["a parse error"])[-1]
        raise CalibrationFileError(f"{path}: not a readable OpenCV FileStorage file ({reason})") from exc

    def node(*names: str):
        return next(((name, storage.getNode(name)) for name in names if not storage.getNode(name).empty()),
                    (names[0], None))

    content: dict[str, Any] = {"camera_name": "camera"}
    for field_name, names in OPENCV_KEYS.items():
        name, entry = node(*names)
        if entry is None or not entry.isMap():
            raise CalibrationFileError(f"{path}: an OpenCV calibration file without '{name}' (a matrix)")
        shape = [entry.getNode(side).real() if entry.getNode(side).isReal() or entry.getNode(side).isInt() else -1
                 for side in ("rows", "cols")]
        if not all(1 <= side <= 16 for side in shape):  # checked before OpenCV allocates what a file declares
            raise CalibrationFileError(f"{path}: '{name}' declares {shape[0]:g}x{shape[1]:g} numbers; a camera "
                                       "matrix is 3x3 and distortion at most 1x14")
        try:
            values = entry.mat()
        except cv2.error as exc:
            raise CalibrationFileError(f"{path}: '{name}' is not a matrix OpenCV can read "
                                       f"({str(exc).strip().splitlines()[-1]})") from exc
        if values is None:
            raise CalibrationFileError(f"{path}: '{name}' is not a matrix OpenCV can read")
        content[field_name] = {"rows": values.shape[0], "cols": values.shape[1], "data": values.ravel().tolist()}
    _, width = node("image_width")
    _, height = node("image_height")
    if width is not None and height is not None:
        content["image_width"], content["image_height"] = width.real(), height.real()
    else:
        _, size = node(*OPENCV_SIZE_KEYS)
        if size is None or not size.isSeq() or size.size() != 2:
            raise CalibrationFileError(f"{path}: an OpenCV calibration file without the image size: add "
                                       "image_width and image_height (the frames' size it was fitted on)")
        content["image_width"], content["image_height"] = size.at(0).real(), size.at(1).real()
    for key in ("image_width", "image_height"):
        value = content[key]
        content[key] = int(value) if float(value).is_integer() else value
    _, model = node("distortion_model")
    count = len(content["distortion_coefficients"]["data"])
    if model is not None and model.isString():
        content["distortion_model"] = model.string()
    elif count in (5, 8):
        content["distortion_model"] = "plumb_bob" if count == 5 else "rational_polynomial"
    elif count == 4:
        raise CalibrationFileError(f"{path}: 4 distortion coefficients in an OpenCV file are OpenCV's k1 k2 p1 p2 "
                                   "or cv2.fisheye's k1-k4: add distortion_model: plumb_bob or equidistant")
    else:
        raise CalibrationFileError(f"{path}: {count} distortion coefficients: OpenCV's models read here have 5 "
                                   "(plumb_bob) or 8 (rational_polynomial); the thin-prism and tilted ones are not")
    return content


def read_calibration(path: str | os.PathLike) -> CalibrationFile:
    """Read a camera_info YAML (or ROS 1's `ost.ini`, or OpenCV's FileStorage YAML or XML); any problem raises
    CalibrationFileError naming the file and the problem."""
    path = Path(path)
    try:
        text = read_text(path)
    except FileNotFoundError as exc:
        raise CalibrationFileError(f"{path}: no such calibration file") from exc
    except StrictYamlError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationFileError(f"{path}: cannot be read ({exc})") from exc
    if is_ost_ini(path, text):
        return from_camera_info_dict(ost_ini_content(text, path), path)
    if is_opencv_storage(text):
        import cv2

        try:
            content = opencv_storage_content(text, path)
        except cv2.error as exc:  # what the checks inside did not foresee
            reason = (str(exc).strip().splitlines() or ["an error"])[-1]
            raise CalibrationFileError(f"{path}: not a readable OpenCV FileStorage file ({reason})") from exc
        return from_camera_info_dict(content, path)
    try:
        content = load_text(text)
    except StrictYamlError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        line = f" at line {where.line + 1}" if where else ""
        raise CalibrationFileError(f"{path}: not valid YAML{line}") from exc
    return from_camera_info_dict(content, path)


def camera_info_url_to_path(url: str) -> Path | None:
    """A camera_info URL as camera_info_manager reads it: `file:///absolute/path.yaml`, or
    `package://<package>/<path>` (in that package's installed share folder); a plain absolute or ~ path is
    taken too; '' = none. Anything else is a ValueError with the reason (`file://sub/x.yaml` names a host,
    not a folder, and is refused rather than read as /x.yaml)."""
    if not url:
        return None
    if url.startswith("package://"):
        package, _, relative = url[len("package://"):].partition("/")
        if not package or not relative:
            raise ValueError(f"camera_info URL {url!r}: write package://<package>/<path inside its share folder>")
        try:
            from ament_index_python.packages import get_package_share_directory

            return Path(get_package_share_directory(package)) / relative
        except Exception as exc:  # PackageNotFoundError, or no ament index at all
            raise ValueError(f"camera_info URL {url!r}: package {package!r} not found ({exc})") from exc
    if url.startswith("file://"):
        path = url[len("file://"):]
        if not path.startswith("/"):
            raise ValueError(f"camera_info URL {url!r}: file:// needs an absolute path, e.g. file:///data/calib.yaml "
                             f"(three slashes)")
        return Path(path)
    if ":" in url.split("/", 1)[0]:
        raise ValueError(f"camera_info URL {url!r}: only file:///absolute/path and package://package/path are "
                         "understood")
    path = Path(url).expanduser()
    if not path.is_absolute():
        raise ValueError(f"camera_info URL {url!r}: give an absolute path (file:///...), not one relative to "
                         "wherever the node happens to start")
    return path


FIT_KEYS = ("rms_px", "mean_px", "max_residual_px", "sigma0_px", "views_used", "views_rejected", "views_repeated",
            "std", "std_covariance", "std_views", "coverage", "warnings", "reach_px")


def provenance(producer: str) -> dict[str, str]:
    """When and by what a calibration file was written: the keys every file this package writes carries."""
    return {"date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "software": f"veg_area_ros {__version__} {producer}"}


def fit_metadata(summary: dict, medium: str, distance_m: float | None, board: str, producer: str) -> dict:
    """The metadata of a calibration fitted from board views (`CalibrationResult.summary()`): the medium and
    distance it holds for, the board, its quality indicators and provenance. One set of keys for the command
    line, the calibration node and the demo."""
    return {"medium": medium, "calibration_distance_m": distance_m, "board": str(board), **provenance(producer),
            **{k: summary[k] for k in FIT_KEYS if k in summary},
            "halves": {k: v for k, v in summary.get("halves", {}).items() if k != "z"},
            **({"model_choice": {"chosen": summary["model_choice"]["chosen"],
                                 "reason": summary["model_choice"]["reason"]}} if summary.get("model_choice") else {}),
            "projection_std_px": {k: summary["projection_std_px"][k] for k in ("median", "max")
                                  if k in summary.get("projection_std_px", {})},
            # what measuring carries to Af's std (camera_uncertainty): the parameters' covariance
            **({"camera_covariance": CameraCovariance.from_std(summary["std"], summary["correlations"]).as_dict()}
               if summary.get("std") and "correlations" in summary else {})}


def quality_rms(calibration: CalibrationFile) -> float:
    """The RMS residual recorded with a calibration, or infinity where none is recorded."""
    value = calibration.metadata.get("rms_px")
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else math.inf
