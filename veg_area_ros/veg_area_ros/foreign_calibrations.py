"""Calibration files other tools write, as the camera_info fields `calib_io` reads: ROS 1 cameracalibrator's
`ost.ini`, OpenCV's FileStorage (its calibration sample's, its interactive calibrator's, a script's; YAML or XML),
Kalibr's camchain YAML, Agisoft Metashape's calibration XML, COLMAP's cameras.txt or cameras.bin and the Bouguet
toolbox's Calib_Results.m. Each gives one camera's fields or a ForeignCalibrationError saying what is wrong."""

from __future__ import annotations

import re
import struct
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2

from .camera_model import MODEL_DIST_NAMES

if TYPE_CHECKING:
    from xml.etree.ElementTree import Element


class ForeignCalibrationError(ValueError):
    """Another tool's file that is not one camera's calibration; `calib_io` adds the file's name."""


OST_INI_KEYS = {"camera matrix": ("camera_matrix", 3, 3), "distortion": ("distortion_coefficients", 1, None),
                "rectification": ("rectification_matrix", 3, 3), "projection": ("projection_matrix", 3, 4)}


def is_ost_ini(path: Path, text: str) -> bool:
    """Whether a calibration file is ROS 1 cameracalibrator's INI (`ost.ini`, '# oST version 5.0 parameters')."""
    return path.suffix.lower() == ".ini" or re.search(r"^\s*\[image\]\s*$", text, re.MULTILINE) is not None


def ost_ini_content(text: str) -> dict[str, Any]:
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
            raise ForeignCalibrationError(f"not an ost.ini calibration: line {number} comes before any [section]")
        try:
            values = [float(word) for word in line.split()]
        except ValueError:
            key = line.lower()
            sections[-1][1][key] = []
            continue
        if key is None:
            raise ForeignCalibrationError(f"line {number} of ost.ini holds numbers under no key")
        sections[-1][1][key].extend(values)
    image = {k: v for name, entries in sections if name == "image" for k, v in entries.items()}
    cameras = [(name, entries) for name, entries in sections if name != "image"]
    if len(cameras) != 1:
        names = ", ".join(name for name, _ in cameras) or "none"
        raise ForeignCalibrationError(f"an ost.ini with {len(cameras)} camera sections ({names}); "
                                      "measuring needs one camera's (a stereo pair's file holds two: split it)")
    name, entries = cameras[0]
    content: dict[str, Any] = {"camera_name": name}
    for side in ("width", "height"):
        values = image.get(side, [])
        if len(values) != 1 or not float(values[0]).is_integer():
            raise ForeignCalibrationError(f"ost.ini's [image] needs one whole '{side}', found {values}")
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


def opencv_storage_content(text: str) -> dict[str, Any]:
    """`_opencv_fields`, with what OpenCV itself raises on a file its checks did not foresee said as one line."""
    try:
        return _opencv_fields(text)
    except cv2.error as exc:
        reason = (str(exc).strip().splitlines() or ["an error"])[-1]
        raise ForeignCalibrationError(f"not a readable OpenCV FileStorage file ({reason})") from exc


def _opencv_fields(text: str) -> dict[str, Any]:
    """The camera_info fields of a calibration saved with OpenCV's FileStorage (YAML or XML): the camera matrix,
    the distortion coefficients and the image size under the names OpenCV's tools use. OpenCV files do not name
    the model: 5 coefficients are plumb_bob and 8 rational_polynomial; 4 (OpenCV's k1 k2 p1 p2, or cv2.fisheye's
    k1-k4) are refused unless a `distortion_model` entry says which."""
    try:
        storage = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as exc:  # a parse error comes as either, by where OpenCV's parser stops
        cause = exc.__cause__ if isinstance(exc, SystemError) and exc.__cause__ is not None else exc
        reason = (str(cause).strip().splitlines() or ["a parse error"])[-1]
        raise ForeignCalibrationError(f"not a readable OpenCV FileStorage file ({reason})") from exc

    def node(*names: str) -> tuple[str, cv2.FileNode | None]:
        return next(((name, storage.getNode(name)) for name in names if not storage.getNode(name).empty()),
                    (names[0], None))

    content: dict[str, Any] = {"camera_name": "camera"}
    for field_name, names in OPENCV_KEYS.items():
        name, entry = node(*names)
        if entry is None or not entry.isMap():
            raise ForeignCalibrationError(f"an OpenCV calibration file without '{name}' (a matrix)")
        shape = [entry.getNode(side).real() if entry.getNode(side).isReal() or entry.getNode(side).isInt() else -1
                 for side in ("rows", "cols")]
        if not all(1 <= side <= 16 for side in shape):  # checked before OpenCV allocates what a file declares
            raise ForeignCalibrationError(f"'{name}' declares {shape[0]:g}x{shape[1]:g} numbers; a camera "
                                          "matrix is 3x3 and distortion at most 1x14")
        try:
            values = entry.mat()
        except cv2.error as exc:
            raise ForeignCalibrationError(f"'{name}' is not a matrix OpenCV can read "
                                          f"({str(exc).strip().splitlines()[-1]})") from exc
        if values is None:
            raise ForeignCalibrationError(f"'{name}' is not a matrix OpenCV can read")
        content[field_name] = {"rows": values.shape[0], "cols": values.shape[1], "data": values.ravel().tolist()}
    _, width = node("image_width")
    _, height = node("image_height")
    if width is not None and height is not None:
        content["image_width"], content["image_height"] = width.real(), height.real()
    else:
        _, size = node(*OPENCV_SIZE_KEYS)
        if size is None or not size.isSeq() or size.size() != 2:
            raise ForeignCalibrationError("an OpenCV calibration file without the image size: add "
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
        raise ForeignCalibrationError("4 distortion coefficients in an OpenCV file are OpenCV's k1 k2 p1 p2 "
                                      "or cv2.fisheye's k1-k4: add distortion_model: plumb_bob or equidistant")
    else:
        raise ForeignCalibrationError(f"{count} distortion coefficients: OpenCV's models read here have 5 "
                                      "(plumb_bob) or 8 (rational_polynomial); the thin-prism and tilted ones are not")
    return content


KALIBR_DISTORTION = {"radtan": ("plumb_bob", 4), "equidistant": ("equidistant", 4), "none": ("plumb_bob", 0)}


def is_kalibr_camchain(content: Any) -> bool:
    """Whether a YAML document is Kalibr's camchain (cam0: {camera_model, intrinsics, ...})."""
    return (isinstance(content, dict) and "camera_matrix" not in content
            and any(isinstance(value, dict) and "intrinsics" in value for value in content.values()))


def kalibr_content(content: dict) -> dict[str, Any]:
    """The camera_info fields of Kalibr's camchain YAML for its one camera: a pinhole camera (intrinsics fu fv
    pu pv, resolution) with radtan (k1 k2 p1 p2: plumb_bob), equidistant (fisheye k1-k4) or no distortion.
    Several cameras, and Kalibr's omnidirectional and double-sphere models, are refused with their names."""
    cameras = {name: value for name, value in content.items() if isinstance(value, dict) and "intrinsics" in value}
    if len(cameras) != 1:
        raise ForeignCalibrationError(f"a Kalibr camchain with {len(cameras)} cameras ({', '.join(cameras)}); "
                                      "measuring needs one camera's: keep its block alone in the file")
    name, camera = next(iter(cameras.items()))
    model, distortion = camera.get("camera_model", "pinhole"), camera.get("distortion_model", "none")
    if model != "pinhole" or distortion not in KALIBR_DISTORTION:
        raise ForeignCalibrationError(f"Kalibr's {model} camera with {distortion} distortion is not read here "
                                      "(pinhole with radtan, equidistant or none is)")
    try:
        fu, fv, pu, pv = (float(value) for value in camera["intrinsics"])
        width, height = camera["resolution"]
        coefficients = [float(value) for value in camera.get("distortion_coeffs") or []]
    except (KeyError, TypeError, ValueError) as exc:
        raise ForeignCalibrationError(f"{name} needs intrinsics [fu, fv, pu, pv], resolution [width, height] "
                                      "and distortion_coeffs") from exc
    ros_model, count = KALIBR_DISTORTION[distortion]
    if len(coefficients) != count:
        raise ForeignCalibrationError(f"{name}'s {distortion} distortion has {count} coefficients, "
                                      f"found {len(coefficients)}")
    if ros_model == "plumb_bob":
        coefficients = (coefficients + [0.0] * 5)[:5]  # radtan is k1 k2 p1 p2; k3 = 0
    return {"camera_name": str(camera.get("rostopic") or name), "image_width": width, "image_height": height,
            "distortion_model": ros_model,
            "camera_matrix": {"rows": 3, "cols": 3, "data": [fu, 0.0, pu, 0.0, fv, pv, 0.0, 0.0, 1.0]},
            "distortion_coefficients": {"rows": 1, "cols": len(coefficients), "data": coefficients}}


def is_metashape_xml(text: str) -> bool:
    """Whether a calibration file is Agisoft Metashape's (or PhotoScan's) camera calibration XML."""
    head = text.lstrip()[:400]
    return head.startswith("<") and ("<calibration" in head or "<document" in head)


METASHAPE_UNSUPPORTED = {"k4": "k4 (r⁸)", "p3": "p3", "p4": "p4", "b2": "b2 (skew)"}


def _metashape_sensor_calibration(document: Element) -> Element:
    """The one sensor's calibration in Metashape's cameras.xml (its adjusted one where it has an initial one too);
    several sensors (cameras) are refused with their labels."""
    sensors = [sensor for sensor in document.iter("sensor") if sensor.findall("calibration")]
    if len(sensors) != 1:
        labels = ", ".join(repr(sensor.get("label", "?")) for sensor in sensors) or "none"
        raise ForeignCalibrationError(f"a Metashape cameras.xml with {len(sensors)} calibrated sensors ({labels}); "
                                      "measuring needs one camera's: export that sensor's calibration")
    calibrations = sensors[0].findall("calibration")
    chosen = next((c for c in calibrations if c.get("class") == "adjusted"), calibrations[-1])
    if chosen.find("resolution") is None and sensors[0].find("resolution") is not None:
        chosen.append(sensors[0].find("resolution"))
    return chosen


def metashape_content(text: str) -> dict[str, Any]:
    """The camera_info fields of Metashape's calibration XML (Tools > Camera Calibration > Export, or the one
    sensor's in File > Export > Export Cameras' cameras.xml), a frame camera's Brown model: f, cx, cy (pixels,
    the principal point from the image's centre), b1 (fx - fy), k1-k3 and p1-p2. Converted to OpenCV's
    conventions: the principal point counted from the top-left pixel's centre (Metashape counts from its
    corner, the centre at 0.5), fx = f + b1, and p1, p2 swapped (Metashape's p1 multiplies r² + 2x², OpenCV's
    p2 does). Terms camera_info's models lack (k4, p3, p4, a skew b2) are refused unless 0, as are its fisheye
    and spherical cameras."""
    import xml.etree.ElementTree as ElementTree

    if "<!DOCTYPE" in text or "<!ENTITY" in text:  # Metashape writes none; entities can expand without bound
        raise ForeignCalibrationError("a Metashape calibration XML with a DOCTYPE or entities, which it never holds")
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as exc:
        raise ForeignCalibrationError(f"not a readable Metashape calibration XML ({exc})") from exc
    if root.tag == "document":  # File > Export > Export Cameras: each sensor's calibrations inside
        root = _metashape_sensor_calibration(root)
    if root.tag != "calibration":
        raise ForeignCalibrationError(f"a Metashape XML whose root is <{root.tag}>, not <calibration>")
    kind = (root.get("type") or root.findtext("projection") or "frame").strip()
    if kind != "frame":
        raise ForeignCalibrationError(f"a Metashape {kind} camera: only frame cameras (the Brown model) are read; "
                                      "calibrate a fisheye lens here (veg-area calibrate --model equidistant)")

    def number(name: str, default: float | None = 0.0) -> float:
        value = root.findtext(name)
        if value is None:
            if default is None:
                raise ForeignCalibrationError(f"a Metashape calibration without <{name}>")
            return default
        try:
            return float(value)
        except ValueError as exc:
            raise ForeignCalibrationError(f"Metashape's <{name}> is not a number: {value.strip()!r}") from exc

    resolution = root.find("resolution")
    sides = ([resolution.get("width", ""), resolution.get("height", "")] if resolution is not None
             else [root.findtext("width") or "", root.findtext("height") or ""])
    if not all(side.strip().isdigit() and int(side) > 0 for side in sides):
        raise ForeignCalibrationError(f"Metashape's image size must be two whole numbers of pixels, found {sides}")
    width, height = (int(side) for side in sides)
    unsupported = [label for name, label in METASHAPE_UNSUPPORTED.items() if number(name) != 0]
    if unsupported:
        raise ForeignCalibrationError(f"Metashape's {', '.join(unsupported)} {'is' if len(unsupported) == 1 else 'are'}"
                                      " not 0: camera_info's plumb_bob model has no such term (fix it at 0 in "
                                      "Metashape's calibration and adjust again)")
    focal = number("f", None)
    fx, fy = focal + number("b1"), focal
    cx, cy = width / 2 + number("cx") - 0.5, height / 2 + number("cy") - 0.5
    return {"camera_name": "metashape", "image_width": width, "image_height": height,
            "camera_matrix": {"rows": 3, "cols": 3, "data": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]},
            "distortion_model": "plumb_bob",
            "distortion_coefficients": {"rows": 1, "cols": 5, "data": [
                number("k1"), number("k2"), number("p2"), number("p1"), number("k3")]}}


# COLMAP's camera models (cameras.txt) that camera_info's hold: their parameters in COLMAP's order, and
# camera_info's model (its coefficients in MODEL_DIST_NAMES' order, those COLMAP's model lacks 0)
COLMAP_MODELS = {
    "SIMPLE_PINHOLE": (["f", "cx", "cy"], "plumb_bob"),
    "PINHOLE": (["fx", "fy", "cx", "cy"], "plumb_bob"),
    "SIMPLE_RADIAL": (["f", "cx", "cy", "k1"], "plumb_bob"),
    "RADIAL": (["f", "cx", "cy", "k1", "k2"], "plumb_bob"),
    "OPENCV": (["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"], "plumb_bob"),
    "FULL_OPENCV": (["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"], "rational_polynomial"),
    "OPENCV_FISHEYE": (["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"], "equidistant"),
}
COLMAP_LINE = re.compile(r"^\s*\d+\s+[A-Z_]+\s+\d+\s+\d+(\s+\S+)+\s*$")


def is_colmap_cameras(text: str) -> bool:
    """Whether a calibration file is COLMAP's cameras.txt (CAMERA_ID MODEL WIDTH HEIGHT PARAMS per line)."""
    lines = [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    return bool(lines) and all(COLMAP_LINE.match(line) for line in lines)


def colmap_content(text: str, source: str = "cameras.txt") -> dict[str, Any]:
    """The camera_info fields of COLMAP's cameras.txt (a sparse model exported as text) for its one camera (or
    several identical ones): its pinhole, radial, OpenCV, full OpenCV or OpenCV fisheye model, the principal
    point moved by half a pixel (COLMAP counts pixels from the top-left pixel's corner, OpenCV from its centre).
    Cameras that differ, or COLMAP's other models, are refused with their names."""
    cameras: dict[tuple, list[str]] = {}
    for line in text.splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        camera_id, model, width, height, *values = line.split()
        cameras.setdefault((model, width, height, *values), []).append(camera_id)
    if len(cameras) != 1:
        described = "; ".join(f"{', '.join(ids)}: {key[0]} {key[1]}x{key[2]}" for key, ids in cameras.items())
        raise ForeignCalibrationError(f"a COLMAP {source} with {len(cameras)} different cameras ({described}); "
                                      "measuring needs one camera's: keep its line")
    model, width, height, *values = next(iter(cameras))
    if model not in COLMAP_MODELS:
        raise ForeignCalibrationError(f"COLMAP's {model} model has no camera_info counterpart; these do: "
                                      f"{', '.join(COLMAP_MODELS)}")
    names, distortion_model = COLMAP_MODELS[model]
    if len(values) != len(names):
        raise ForeignCalibrationError(f"COLMAP's {model} has {len(names)} parameters ({' '.join(names)}), "
                                      f"found {len(values)}")
    try:
        value = dict(zip(names, (float(v) for v in values), strict=True))
    except ValueError as exc:
        raise ForeignCalibrationError(f"COLMAP's {model} parameters are not all numbers: {' '.join(values)}") from exc
    fx, fy = value.get("fx", value.get("f")), value.get("fy", value.get("f"))
    distortion = [value.get(name, 0.0) for name in MODEL_DIST_NAMES[distortion_model]]
    return {"camera_name": "colmap", "image_width": int(width), "image_height": int(height),
            "camera_matrix": {"rows": 3, "cols": 3,
                              "data": [fx, 0.0, value["cx"] - 0.5, 0.0, fy, value["cy"] - 0.5, 0.0, 0.0, 1.0]},
            "distortion_model": distortion_model,
            "distortion_coefficients": {"rows": 1, "cols": len(distortion), "data": distortion}}


# COLMAP's camera model ids as cameras.bin stores them (src/colmap/sensor/models.h)
COLMAP_MODEL_IDS = ("SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV", "OPENCV_FISHEYE", "FULL_OPENCV",
                    "FOV", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE", "THIN_PRISM_FISHEYE",
                    "RAD_TAN_THIN_PRISM_FISHEYE", "SIMPLE_DIVISION", "DIVISION", "SIMPLE_FISHEYE", "FISHEYE", "EUCM",
                    "EQUIRECTANGULAR")
COLMAP_CAMERA_RECORD = struct.Struct("<iiQQ")  # camera_id, model_id, width, height; then the model's doubles
MAX_COLMAP_CAMERAS = 100_000


def is_colmap_binary(data: bytes) -> bool:
    """Whether a file's bytes begin as COLMAP's cameras.bin does (the default output of its mapper): a camera
    count, then the first camera's id, a known model id and an image size."""
    if len(data) < 8 + COLMAP_CAMERA_RECORD.size:
        return False
    (count,) = struct.unpack_from("<Q", data)
    _, model_id, width, height = COLMAP_CAMERA_RECORD.unpack_from(data, 8)
    return 1 <= count <= MAX_COLMAP_CAMERAS and 0 <= model_id < len(COLMAP_MODEL_IDS) and 0 < width * height < 2**40


def colmap_binary_content(data: bytes) -> dict[str, Any]:
    """The camera_info fields of COLMAP's binary cameras.bin, read as its cameras.txt would be (`colmap_content`):
    the same cameras, models and half-pixel shift. A model camera_info lacks is refused by name, since the
    parameter count of the cameras after it is then unknown; a file that ends early or runs on is refused."""
    (count,) = struct.unpack_from("<Q", data)
    lines, offset = [], 8
    for index in range(count):
        if offset + COLMAP_CAMERA_RECORD.size > len(data):
            raise ForeignCalibrationError(f"a COLMAP cameras.bin that ends after {index} of its {count} cameras")
        camera_id, model_id, width, height = COLMAP_CAMERA_RECORD.unpack_from(data, offset)
        offset += COLMAP_CAMERA_RECORD.size
        model = COLMAP_MODEL_IDS[model_id] if 0 <= model_id < len(COLMAP_MODEL_IDS) else f"id {model_id}"
        if model not in COLMAP_MODELS:
            raise ForeignCalibrationError(f"COLMAP's {model} model (camera {camera_id}) has no camera_info "
                                          f"counterpart; these do: {', '.join(COLMAP_MODELS)}")
        size = 8 * len(COLMAP_MODELS[model][0])
        if offset + size > len(data):
            raise ForeignCalibrationError(f"a COLMAP cameras.bin that ends inside camera {camera_id}'s parameters")
        values = struct.unpack_from(f"<{size // 8}d", data, offset)
        offset += size
        lines.append(" ".join([str(camera_id), model, str(width), str(height), *map(repr, values)]))
    if offset != len(data):
        raise ForeignCalibrationError(f"a COLMAP cameras.bin with {len(data) - offset} bytes after its {count} "
                                      "cameras: not a cameras.bin (images.bin and points3D.bin hold no calibration)")
    return colmap_content("\n".join(lines), source="cameras.bin")


# `name = [ 1 ; 2 ];` or `name = 3;`: the assignments of a MATLAB script such as the Bouguet toolbox writes
MATLAB_ASSIGNMENT = re.compile(r"^[ \t]*([A-Za-z_]\w*)[ \t]*=[ \t]*(\[[^\]\n]*\]|[^;%\n]+?)[ \t]*;", re.MULTILINE)
BOUGUET_SIZES = {"fc": 2, "cc": 2, "kc": 5, "nx": 1, "ny": 1}


def is_bouguet_results(text: str) -> bool:
    """Whether a calibration file is Bouguet's Camera Calibration Toolbox for Matlab's Calib_Results.m."""
    return {"fc", "cc", "kc"} <= {match.group(1) for match in MATLAB_ASSIGNMENT.finditer(text)}


def bouguet_content(text: str) -> dict[str, Any]:
    """The camera_info fields of the Bouguet toolbox's Calib_Results.m (its Save button): fc, cc (from the centre
    of the upper-left pixel, as OpenCV counts), kc (k1 k2 p1 p2 k3, OpenCV's order), nx and ny. A skew (alpha_c)
    is refused. Its uncertainties (the *_error vectors, about three standard deviations each, their correlations
    not written) are not taken as the calibration's covariance."""
    values: dict[str, list[float]] = {}
    for name, raw in MATLAB_ASSIGNMENT.findall(text):
        if name in (*BOUGUET_SIZES, "alpha_c") and name not in values:
            try:
                values[name] = [float(v) for v in re.split(r"[\s;,]+", raw.strip("[] \t")) if v]
            except ValueError as exc:
                raise ForeignCalibrationError(f"Calib_Results.m's {name} is not numbers: {raw.strip()}") from exc
    missing = [name for name in BOUGUET_SIZES if name not in values]
    if missing:
        raise ForeignCalibrationError(f"a Bouguet toolbox Calib_Results.m without {', '.join(missing)}"
                                      + (" (the image size: add nx = WIDTH; ny = HEIGHT;)"
                                         if {"nx", "ny"} & set(missing) else ""))
    for name, size in BOUGUET_SIZES.items():
        if len(values[name]) != size:
            raise ForeignCalibrationError(f"Calib_Results.m's {name} holds {len(values[name])} numbers, not {size}")
    if any(values.get("alpha_c", [0.0])):
        raise ForeignCalibrationError(f"Calib_Results.m has a skew (alpha_c = {values['alpha_c'][0]:g}); "
                                      "camera_info's models have none: calibrate again with est_alpha = 0")
    (fx, fy), (cx, cy), (width,), (height,) = values["fc"], values["cc"], values["nx"], values["ny"]
    if not (float(width).is_integer() and float(height).is_integer()):
        raise ForeignCalibrationError(f"Calib_Results.m's image size must be whole pixels, found {width}x{height}")
    return {"camera_name": "bouguet", "image_width": int(width), "image_height": int(height),
            "camera_matrix": {"rows": 3, "cols": 3, "data": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]},
            "distortion_model": "plumb_bob",
            "distortion_coefficients": {"rows": 1, "cols": 5, "data": values["kc"]}}
