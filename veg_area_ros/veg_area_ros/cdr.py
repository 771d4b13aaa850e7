"""sensor_msgs/Image and sensor_msgs/CameraInfo as the CDR bytes that DDS carries and rosbag2 stores.

No ROS here: the nodes publish these bytes with rclpy (`publisher.publish(bytes)`) and take them with
`raw=True` subscriptions, and the offline tools read them from bags, so a frame goes from a numpy buffer to
the wire and back with one copy and a zero-copy view. The layout is ROS 2's default: a 4-byte encapsulation
header (CDR, little endian), then the fields, each aligned to its own size counted from after the header.
Tested byte for byte against rclpy's serialize_message.
"""

from __future__ import annotations

import functools
import struct
from array import array
from collections.abc import Iterable
from dataclasses import dataclass
from types import ModuleType

import cv2
import numpy as np

from .bit_depth import StreamDepth, to_8_bit
from .files import MAX_IMAGE_PIXELS
from .jpeg import JPEG_START, jpeg_structure_problem

# a serialized message or an image's bytes, as they arrive: bytes, a view, rclpy's array, rosbags' numpy array
Buffer = bytes | bytearray | memoryview | array | np.ndarray

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE, no options
# channels of each 8-bit encoding of sensor_msgs/image_encodings (8UC1/8UC3 read as cv_bridge reads them)
CHANNELS = {"bgr8": 3, "rgb8": 3, "mono8": 1, "8UC1": 1, "8UC3": 3, "bgra8": 4, "rgba8": 4, "8UC4": 4,
            "bayer_rggb8": 1, "bayer_bggr8": 1, "bayer_gbrg8": 1, "bayer_grbg8": 1, "yuv422": 2, "yuv422_yuy2": 2}
# and of each 16-bit one a camera publishes grey levels in (a machine-vision camera's 10-16-bit sensor)
CHANNELS_16 = {"mono16": 1, "bgr16": 3, "rgb16": 3, "16UC3": 3, "bgra16": 4, "rgba16": 4, "16UC4": 4,
               "bayer_rggb16": 1, "bayer_bggr16": 1, "bayer_gbrg16": 1, "bayer_grbg16": 1}
# to BGR; OpenCV names a Bayer pattern by its second row's second and third pixels, ROS by the first two rows'
TO_BGR = {"rgb8": cv2.COLOR_RGB2BGR, "bgra8": cv2.COLOR_BGRA2BGR, "8UC4": cv2.COLOR_BGRA2BGR,
          "rgba8": cv2.COLOR_RGBA2BGR, "bayer_rggb8": cv2.COLOR_BayerBG2BGR, "bayer_bggr8": cv2.COLOR_BayerRG2BGR,
          "bayer_gbrg8": cv2.COLOR_BayerGR2BGR, "bayer_grbg8": cv2.COLOR_BayerGB2BGR,
          "yuv422": cv2.COLOR_YUV2BGR_UYVY, "yuv422_yuy2": cv2.COLOR_YUV2BGR_YUY2}
TO_BGR.update({name.replace("8", "16"): code for name, code in TO_BGR.items()
               if name.replace("8", "16") in CHANNELS_16})
NOT_GREY_LEVELS = {"16UC1": "16UC1 is how depth cameras publish distances (mm), not grey levels; a grey camera's "
                            "16-bit images are mono16"}


class ImageMessageError(ValueError):
    """An Image (message or CDR bytes) that cannot be turned into a frame; the message says why."""


@dataclass(frozen=True)
class Header:
    sec: int
    nanosec: int
    frame_id: str

    @property
    def seconds(self) -> float:
        return self.sec + self.nanosec * 1e-9

    @property
    def nanoseconds(self) -> int:
        return self.sec * 1_000_000_000 + self.nanosec


STAMP = struct.Struct("<iI")  # header.stamp (sec, nanosec): the first field of every stamped message
STAMP_END = len(ENCAPSULATION) + STAMP.size


def _require_stamp(buffer: Buffer) -> None:
    if len(buffer) < STAMP_END:
        raise ImageMessageError("CDR data too short for a header stamp")


def restamp(buffer: Buffer, sec: int, nanosec: int) -> bytes:
    """A serialized stamped message (Image, CameraInfo, ...) with another header stamp, nothing else changed."""
    _require_stamp(buffer)
    return bytes(buffer[:len(ENCAPSULATION)]) + STAMP.pack(sec, nanosec) + bytes(buffer[STAMP_END:])


def stamp_ns(buffer: Buffer) -> int:
    """The header stamp of a serialized stamped message, in nanoseconds."""
    _require_stamp(buffer)
    sec, nanosec = STAMP.unpack_from(buffer, len(ENCAPSULATION))
    return sec * 1_000_000_000 + nanosec


def unstamped(buffer: Buffer) -> bytes:
    """A serialized stamped message without its stamp: equal for the same content sent at other times."""
    return bytes(buffer[STAMP_END:])


def frame_pixels(data: Buffer, height: int, width: int, encoding: str, step: int, is_bigendian: bool = False,
                 depth: StreamDepth | None = None, notes: list[str] | None = None) -> np.ndarray:
    """A BGR (H, W, 3) or grey (H, W) uint8 frame from an Image's fields: a view of `data` when the rows are
    packed bgr8/mono8 (no copy), a converted copy for the other encodings (RGB, with alpha, a camera's raw
    Bayer mosaic, YUV 4:2:2) or padded rows. A 16-bit encoding is read at the depth its values use, held over
    the stream by `depth` (`bit_depth.to_8_bit`), what was assumed appended to `notes`. ImageMessageError says
    what is wrong."""
    channels = CHANNELS.get(encoding) or CHANNELS_16.get(encoding)
    if channels is None:
        wide = any(mark in encoding for mark in ("32", "64", "FC"))
        reason = NOT_GREY_LEVELS.get(encoding) or f"encoding {encoding!r} is not supported" + (
            " (float and 32-bit images are not measured: publish an 8- or 16-bit encoding)" if wide else "")
        raise ImageMessageError(f"{reason}; these are: {', '.join([*CHANNELS, *CHANNELS_16])}")
    if encoding.startswith("yuv422") and width % 2:
        raise ImageMessageError(f"a {encoding} image needs an even width, not {width}")
    if width == 0 or height == 0:
        raise ImageMessageError(f"empty image ({width}x{height})")
    size = 2 if encoding in CHANNELS_16 else 1
    if step < width * channels * size:
        raise ImageMessageError(f"step {step} is shorter than a {width}-pixel {encoding} row")
    data = np.frombuffer(data, np.uint8)
    if data.size != step * height:
        raise ImageMessageError(f"data holds {data.size} bytes, {height} rows of step {step} need {step * height}")
    rows = data.reshape(height, step)[:, : width * channels * size]
    if size == 2:
        rows = np.ascontiguousarray(rows).view(">u2" if is_bigendian else "<u2").astype(np.uint16, copy=False)
    image = rows.reshape(height, width, channels) if channels in (3, 4) else rows
    if encoding.startswith("yuv422"):
        image = rows.reshape(height, width, 2)
    if encoding in TO_BGR:
        image = cv2.cvtColor(np.ascontiguousarray(image), TO_BGR[encoding])
    if size == 2:
        image, note = to_8_bit(image, depth)
        if note and notes is not None:
            notes.append(note)
    return np.ascontiguousarray(image)


class _Writer:
    def __init__(self) -> None:
        self.parts: list[bytes] = [ENCAPSULATION]
        self.size = 0  # bytes after the encapsulation header: alignment counts from there
        self.padding: list[range] = []  # where alignment bytes went (rclpy leaves them uninitialised)

    def _align(self, n: int) -> None:
        pad = -self.size % n
        if pad:
            self.padding.append(range(4 + self.size, 4 + self.size + pad))
            self.parts.append(bytes(pad))
            self.size += pad

    def pack(self, fmt: str, *values) -> None:
        self._align(struct.calcsize(fmt[-1]))
        raw = struct.pack("<" + fmt, *values)
        self.parts.append(raw)
        self.size += len(raw)

    def string(self, text: str) -> None:
        raw = text.encode() + b"\x00"
        self.pack("I", len(raw))
        self.parts.append(raw)
        self.size += len(raw)

    def header(self, sec: int, nanosec: int, frame_id: str) -> None:
        self.pack("iI", sec, nanosec)
        self.string(frame_id)

    def doubles(self, values: Iterable[float], count: int | None = None) -> None:
        values = [float(v) for v in values]
        if count is None:
            self.pack("I", len(values))
        elif len(values) != count:
            raise ValueError(f"expected {count} numbers, got {len(values)}")
        if values:
            self.pack(f"{len(values)}d", *values)

    def blob(self, data: Buffer) -> None:
        self.pack("I", len(data))
        self.parts.append(data)
        self.size += len(data)

    def bytes(self) -> bytes:
        return b"".join(self.parts)  # the one copy of the pixels


class CdrReader:
    """Reads a serialized message's fields in order, each aligned as ROS 2's CDR aligns it."""

    def __init__(self, buffer: Buffer) -> None:
        self.view = memoryview(buffer).cast("B")
        if len(self.view) < 4 or bytes(self.view[:2]) != b"\x00\x01":
            raise ImageMessageError("not little-endian CDR (the encapsulation header is not 00 01)")
        self.offset = 4

    def unpack(self, fmt: str) -> tuple:
        self.offset += -(self.offset - 4) % struct.calcsize(fmt[-1])
        size = struct.calcsize("<" + fmt)
        if self.offset + size > len(self.view):
            raise ImageMessageError("CDR data ends inside a field (truncated message)")
        values = struct.unpack_from("<" + fmt, self.view, self.offset)
        self.offset += size
        return values

    def string(self) -> str:
        (length,) = self.unpack("I")
        raw = self.take(length)
        return bytes(raw[:-1]).decode(errors="replace") if length else ""

    def octets(self) -> memoryview:
        """A uint8[] field: its length, then its bytes (a view, no copy)."""
        (length,) = self.unpack("I")
        return self.take(length)

    def take(self, length: int) -> memoryview:
        if self.offset + length > len(self.view):
            raise ImageMessageError(f"CDR data ends {self.offset + length - len(self.view)} bytes early")
        chunk = self.view[self.offset:self.offset + length]
        self.offset += length
        return chunk

    def header(self) -> Header:
        sec, nanosec = self.unpack("iI")
        return Header(sec, nanosec, self.string())

    def doubles(self, count: int | None = None) -> list[float]:
        if count is None:
            (count,) = self.unpack("I")
        return list(self.unpack(f"{count}d")) if count else []


def encode_image(image: np.ndarray, sec: int, nanosec: int, frame_id: str) -> bytes:
    """bgr8 for (H, W, 3) uint8, mono8 for (H, W) uint8, as serialized sensor_msgs/Image bytes."""
    return _image_writer(image, sec, nanosec, frame_id).bytes()


def image_layout(image: np.ndarray) -> tuple[str, int]:
    """(encoding, step) an Image of this frame carries: bgr8 for (H, W, 3) uint8, mono8 for (H, W) uint8."""
    if image.dtype != np.uint8 or image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise ImageMessageError(f"cannot publish an image of shape {image.shape} and type {image.dtype}")
    return ("bgr8", 3 * image.shape[1]) if image.ndim == 3 else ("mono8", image.shape[1])


def _image_writer(image: np.ndarray, sec: int, nanosec: int, frame_id: str) -> _Writer:
    encoding, step = image_layout(image)
    writer = _Writer()
    writer.header(sec, nanosec, frame_id)
    writer.pack("II", *image.shape[:2])
    writer.string(encoding)
    writer.pack("B", 0)
    writer.pack("I", step)
    writer.blob(memoryview(np.ascontiguousarray(image)).cast("B"))
    return writer


@dataclass(frozen=True)
class ImageFields:
    header: Header
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: memoryview  # a view into the CDR buffer

    def pixels(self, depth: StreamDepth | None = None, notes: list[str] | None = None) -> np.ndarray:
        """The frame as `frame_pixels` makes it (`depth` and `notes`: a 16-bit stream's, see there)."""
        return frame_pixels(self.data, self.height, self.width, self.encoding, self.step, bool(self.is_bigendian),
                            depth, notes)


def decode_image(buffer: Buffer) -> ImageFields:
    """Serialized sensor_msgs/Image -> its fields, the pixel data a view (no copy) of `buffer`."""
    reader = CdrReader(buffer)
    header = reader.header()
    height, width = reader.unpack("II")
    encoding = reader.string()
    (is_bigendian,) = reader.unpack("B")
    (step,) = reader.unpack("I")
    return ImageFields(header, height, width, encoding, is_bigendian, step, reader.octets())


@dataclass(frozen=True)
class CompressedImageFields:
    """sensor_msgs/CompressedImage as image_transport's `compressed` plugin writes it: `format` is
    "<original encoding>; <jpeg|png> compressed <encoding of the compressed data>" (or a bare "jpeg"/"png"); or
    its `zstd` plugin's, format "zstd" (`zstd_image`)."""
    header: Header
    format: str
    data: memoryview  # a view into the CDR buffer

    def pixels(self, depth: StreamDepth | None = None, notes: list[str] | None = None) -> np.ndarray:
        """A BGR (H, W, 3) or grey (H, W) uint8 frame, decoded as OpenCV decodes the same JPEG or PNG file; a
        16-bit PNG (a mono16 camera's) read as `frame_pixels` reads a 16-bit Image."""
        kind = self.format.lower()
        if "compresseddepth" in kind.replace(" ", ""):
            raise ImageMessageError(f"a depth image (format {self.format!r}) holds no grey levels to measure")
        if kind.strip() == "zstd":
            return zstd_image(self.header, self.data).pixels(depth, notes)
        if self.data[:2] == JPEG_START:  # a scrambled scan decodes into a grey smear with a warning on stderr only
            problem = jpeg_structure_problem(self.data)
            if problem:
                raise ImageMessageError(f"the compressed image (format {self.format!r}) is a corrupt JPEG "
                                        f"({problem})")
        image = cv2.imdecode(np.frombuffer(self.data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise ImageMessageError(f"the compressed image (format {self.format!r}, {len(self.data)} bytes) cannot "
                                    "be decoded")
        if image.dtype not in (np.uint8, np.uint16):
            raise ImageMessageError(f"a {image.dtype} compressed image (format {self.format!r}): only 8- and "
                                    "16-bit images are measured")
        if image.ndim == 3 and image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        stored = kind.rsplit("compressed", 1)[-1].strip() if "compressed" in kind else ""
        if image.ndim == 3 and stored.startswith("rgb"):  # the encoder was given RGB rows as they were
            image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        image, note = to_8_bit(image, depth)
        if note and notes is not None:
            notes.append(note)
        return image


@functools.cache
def zstd_module() -> ModuleType:
    """Python's zstd (compression.zstd from 3.14, its backport before), found once: a failed import is tried
    again at every call, and a zstd stream decodes every frame."""
    try:
        from compression import zstd
    except ImportError:
        from backports import zstd
    return zstd


MAX_IMAGE_BYTES = 8 * MAX_IMAGE_PIXELS  # four 16-bit channels
ZSTD_IMAGE_HEADER = struct.Struct("<IIBII")  # height, width, is_bigendian, step, the encoding's length


def zstd_image(header: Header, data: memoryview) -> ImageFields:
    """The Image inside zstd_image_transport's CompressedImage (format "zstd"): a little-endian header (height,
    width, is_bigendian, step, the encoding's length, the encoding) before the zstd frame of the rows. The rows are
    never inflated past step x height bytes (a frame that claims more is refused)."""
    if len(data) < ZSTD_IMAGE_HEADER.size:
        raise ImageMessageError(f"a zstd image of {len(data)} bytes: shorter than its header")
    height, width, is_bigendian, step, length = ZSTD_IMAGE_HEADER.unpack_from(data)
    start = ZSTD_IMAGE_HEADER.size + length
    if start > len(data) or length > 64:
        raise ImageMessageError(f"a zstd image whose encoding ({length} bytes) runs past its {len(data)} bytes")
    encoding = bytes(data[ZSTD_IMAGE_HEADER.size:start]).decode("ascii", "replace")
    expected = step * height
    if not 0 < expected <= MAX_IMAGE_BYTES:
        raise ImageMessageError(f"a zstd image of {width}x{height} with {step}-byte rows: no camera's frame")
    zstd = zstd_module()
    decompressor = zstd.ZstdDecompressor()
    try:
        rows = decompressor.decompress(bytes(data[start:]), max_length=expected)
    except zstd.ZstdError as exc:
        raise ImageMessageError(f"a zstd image that cannot be decompressed ({exc})") from exc
    if len(rows) != expected or not decompressor.eof:
        held = f"{len(rows)} bytes" if decompressor.eof else "more bytes"
        raise ImageMessageError(f"a zstd image whose rows hold {held}, not its {step} x {height}")
    return ImageFields(header, height, width, encoding, is_bigendian, step, memoryview(rows))


FOXGLOVE_RAW_IMAGE = "foxglove_msgs/msg/RawImage"
FOXGLOVE_COMPRESSED_IMAGE = "foxglove_msgs/msg/CompressedImage"
FOXGLOVE_ENCODINGS = {"uyvy": "yuv422", "yuyv": "yuv422_yuy2"}  # Foxglove's names for two of ROS's encodings


def decode_foxglove_raw_image(buffer: Buffer) -> ImageFields:
    """Serialized foxglove_msgs/RawImage -> the fields of the Image it is: its timestamp and frame_id lie as a
    std_msgs/Header does; then width before height, the encoding, step (16-bit data little-endian), the data."""
    reader = CdrReader(buffer)
    header = reader.header()
    width, height = reader.unpack("II")
    encoding = reader.string()
    (step,) = reader.unpack("I")
    return ImageFields(header, height, width, FOXGLOVE_ENCODINGS.get(encoding, encoding), 0, step, reader.octets())


def decode_foxglove_compressed_image(buffer: Buffer) -> CompressedImageFields:
    """Serialized foxglove_msgs/CompressedImage (timestamp, frame_id, data, format: jpeg, png, webp) -> the
    fields of the CompressedImage it is."""
    reader = CdrReader(buffer)
    header = reader.header()
    data = reader.octets()
    return CompressedImageFields(header, reader.string(), data)


def decode_compressed_image(buffer: Buffer) -> CompressedImageFields:
    """Serialized sensor_msgs/CompressedImage -> its fields, the data a view (no copy) of `buffer`."""
    reader = CdrReader(buffer)
    header = reader.header()
    image_format = reader.string()
    return CompressedImageFields(header, image_format, reader.octets())


def encode_compressed_image(data: bytes, image_format: str, sec: int, nanosec: int, frame_id: str) -> bytes:
    """Serialized sensor_msgs/CompressedImage bytes of already compressed `data`."""
    writer = _Writer()
    writer.header(sec, nanosec, frame_id)
    writer.string(image_format)
    writer.blob(memoryview(data).cast("B"))
    return writer.bytes()


@dataclass(frozen=True)
class CameraInfoFields:
    header: Header
    height: int
    width: int
    distortion_model: str
    d: list[float]
    k: list[float]
    r: list[float]
    p: list[float]
    binning: tuple[int, int] = (0, 0)
    roi: tuple[int, int, int, int, bool] = (0, 0, 0, 0, False)  # x_offset, y_offset, height, width, rectify


def encode_camera_info(info: CameraInfoFields) -> bytes:
    return _camera_info_writer(info).bytes()


def _camera_info_writer(info: CameraInfoFields) -> _Writer:
    writer = _Writer()
    writer.header(info.header.sec, info.header.nanosec, info.header.frame_id)
    writer.pack("II", info.height, info.width)
    writer.string(info.distortion_model)
    writer.doubles(info.d)
    writer.doubles(info.k, 9)
    writer.doubles(info.r, 9)
    writer.doubles(info.p, 12)
    writer.pack("II", *info.binning)
    writer.pack("IIII", *info.roi[:4])
    writer.pack("B", int(info.roi[4]))
    return writer


def decode_string(buffer: Buffer) -> str:
    """A std_msgs/String message's text."""
    return CdrReader(buffer).string()


def decode_camera_info(buffer: Buffer) -> CameraInfoFields:
    reader = CdrReader(buffer)
    header = reader.header()
    height, width = reader.unpack("II")
    model = reader.string()
    d = reader.doubles()
    k, r, p = reader.doubles(9), reader.doubles(9), reader.doubles(12)
    binning = reader.unpack("II")
    x, y, h, w = reader.unpack("IIII")
    (rectify,) = reader.unpack("B")
    return CameraInfoFields(header, height, width, model, d, k, r, p, binning, (x, y, h, w, bool(rectify)))
