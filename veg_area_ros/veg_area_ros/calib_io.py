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
from .archive import ArchiveError, calibration_text, is_archive
from .camera_info import camera_from_info, camera_info_fields
from .camera_model import BrownCamera, check_plausible
from .camera_uncertainty import CameraCovariance
from .files import write_atomic
from .flat_port import PORT_KEY, FlatPortCamera, port_from_dict
from .foreign_calibrations import (
    ForeignCalibrationError,
    bouguet_content,
    colmap_binary_content,
    colmap_content,
    is_bouguet_results,
    is_colmap_binary,
    is_colmap_cameras,
    is_kalibr_camchain,
    is_metashape_xml,
    is_opencv_storage,
    is_ost_ini,
    kalibr_content,
    metashape_content,
    opencv_storage_content,
    ost_ini_content,
)
from .strict_yaml import StrictYamlError, decode_text, dump_portable, load_text, read_bytes

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
    if ("markers" in content or "points" in content) and "camera_matrix" not in content:
        raise CalibrationFileError(f"{path}: lists targets (markers, points), not a camera: a targets file, given "
                                   "where the calibration belongs (swapped?)")
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


def read_calibration(path: str | os.PathLike) -> CalibrationFile:
    """Read a camera_info YAML (or ROS 1's `ost.ini`, OpenCV's FileStorage YAML or XML, Kalibr's camchain,
    Agisoft Metashape's calibration XML, COLMAP's cameras.txt or cameras.bin, the Bouguet toolbox's
    Calib_Results.m, camera_calibration's saved calibrationdata.tar.gz); any
    problem raises CalibrationFileError naming the file and the problem."""
    path = Path(path)
    try:
        if is_archive(path):  # camera_calibration's saved archive: its ost.yaml
            text = calibration_text(path)[1]
        else:
            data = read_bytes(path)
            if is_colmap_binary(data):
                return from_camera_info_dict(colmap_binary_content(data), path)
            text = decode_text(data)
    except (ArchiveError, ForeignCalibrationError) as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    except FileNotFoundError as exc:
        raise CalibrationFileError(f"{path}: no such calibration file") from exc
    except StrictYamlError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationFileError(f"{path}: cannot be read ({exc})") from exc
    try:
        if is_ost_ini(path, text):
            return from_camera_info_dict(ost_ini_content(text), path)
        if is_opencv_storage(text):
            return from_camera_info_dict(opencv_storage_content(text), path)
        if is_metashape_xml(text):
            return from_camera_info_dict(metashape_content(text), path)
        if is_colmap_cameras(text):
            return from_camera_info_dict(colmap_content(text), path)
        if is_bouguet_results(text):
            return from_camera_info_dict(bouguet_content(text), path)
    except ForeignCalibrationError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    try:
        content = load_text(text)
    except StrictYamlError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        line = f" at line {where.line + 1}" if where else ""
        raise CalibrationFileError(f"{path}: not valid YAML{line}") from exc
    if is_kalibr_camchain(content):
        try:
            content = kalibr_content(content)
        except ForeignCalibrationError as exc:
            raise CalibrationFileError(f"{path}: {exc}") from exc
    return from_camera_info_dict(content, path)


URL_VARIABLES = re.compile(r"\$\{([^}]*)\}")


def camera_info_url_to_path(url: str, camera_name: str = "camera") -> Path | None:
    """A camera_info URL as camera_info_manager reads it: `file:///absolute/path.yaml`, or
    `package://<package>/<path>` (in that package's installed share folder), with `${NAME}` (the camera's name)
    and `${ROS_HOME}` ($ROS_HOME, else ~/.ros) put in as it puts them (its default URL is
    file://${ROS_HOME}/camera_info/${NAME}.yaml); a plain absolute or ~ path is taken too; '' = none. Anything
    else is a ValueError with the reason (`file://sub/x.yaml` names a host, not a folder, and is refused rather
    than read as /x.yaml)."""
    if not url:
        return None
    values = {"NAME": camera_name, "ROS_HOME": os.environ.get("ROS_HOME") or os.path.expanduser("~/.ros")}
    unknown = sorted({name for name in URL_VARIABLES.findall(url) if name not in values})
    if unknown:
        raise ValueError(f"camera_info URL {url!r}: {', '.join('${' + n + '}' for n in unknown)} is not put in by "
                         "camera_info_manager; it knows ${NAME} and ${ROS_HOME}")
    url = URL_VARIABLES.sub(lambda match: values[match.group(1)], url)
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
