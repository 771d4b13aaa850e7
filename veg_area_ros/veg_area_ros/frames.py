"""Reading frames from images, folders of images, videos and rosbag2 bags, with a clear reason for everything
skipped.

No ROS here.
"""

from __future__ import annotations

import itertools
import math
import os
import struct
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from .archive import ArchiveError, is_archive, read_views, view_names
from .bit_depth import to_8_bit
from .decoder_messages import FFMPEG_MESSAGE, with_decoder_messages
from .exif import capture_time, is_tiff
from .files import glob_matches, in_name_order, special_file, too_many_pixels
from .jpeg import JPEG_STANDALONE_MARKERS, JPEG_START, jpeg_structure_problem
from .orientation import as_stored, orientation_note, stored_orientation, video_rotation_note
from .tiff_stack import frame_interval, page_orientations, stack_pages
from .video_container import hdr_note
from .video_damage import VideoDamage, decoder_words, one_thread_capture, video_keyframes

if TYPE_CHECKING:
    from collections.abc import Callable

    from .bags import BagFrame

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".jpe", ".jfif", ".png", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pnm", ".webp",
                  ".avif", ".jp2", ".j2k"}
# photos OpenCV does not read (a DSLR's raw files, a phone's HEIC): named, never passed over in silence
UNREAD_PHOTO_SUFFIXES = {".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".orf", ".rw2", ".raf",
                         ".dng", ".pef", ".srw", ".x3f", ".3fr", ".iiq", ".heic", ".heif"}
EXPORT_ADVICE = "OpenCV reads neither camera raw nor HEIC; export them as JPEG, PNG or TIFF"
# and camcorders' (AVCHD .mts/.m2ts), phones' (.3gp), broadcast and DV cameras' containers FFmpeg reads
VIDEO_SUFFIXES = {".avi", ".mp4", ".mov", ".mkv", ".m4v", ".mpg", ".mpeg", ".webm", ".wmv", ".mts", ".m2ts", ".ts",
                  ".3gp", ".flv", ".vob", ".asf", ".mxf", ".dv", ".ogv", ".mjpeg", ".mjpg"}


class InputError(ValueError):
    """An input that cannot be used at all (missing path, empty folder, unknown file type)."""


@dataclass(frozen=True)
class Frame:
    name: str  # file name, or "video.mp4#123" for frame 123 of a video
    image: np.ndarray | None  # None where the frame could not be read
    problem: str = ""  # why image is None
    time_s: float | None = None  # position in a video, seconds; a bag frame's header stamp; a photo's EXIF time taken
    stamp: tuple[int, int] | None = None  # a bag frame's header stamp (sec, nanosec)
    camera_info: object | None = None  # a bag frame's latest recorded CameraInfoFields
    lost: int = 0  # frames of the input this entry stands for that could not be read (damage); 1 for any unreadable
    position: int | None = None  # a video's frame index or a bag's image message index; None for an image file
    grey: np.ndarray | None = None  # a colour image in grey, where made beside the decoding (`with_grey`)
    camera_info_problem: str = ""  # a bag frame's: why its camera's camera_info is not given (another camera's)
    camera_metadata: str | None = None  # a bag frame's camera_info/metadata recorded beside its camera_info
    notes: tuple[str, ...] = ()  # what reading it assumed (a 16-bit file's depth), for the result's warnings

    def __post_init__(self) -> None:
        if self.image is None and self.lost == 0:
            object.__setattr__(self, "lost", 1)


def is_bag(path: Path) -> bool:
    """A rosbag2 folder (metadata.yaml, or .mcap/.db3 files), a single .mcap file or a ROS 1 .bag."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file() or any(path.glob("*.mcap")) or any(path.glob("*.db3"))
    return path.suffix.lower() in (".mcap", ".bag")


def decodable_ahead(files: list[Path]) -> bool:
    """Whether these inputs' frames may be decoded in another thread while earlier ones are used: videos and
    bags. Not image files: a JPEG's decoder warnings are caught by redirecting the process's stderr while it
    decodes (`read_image`), which would swallow other threads' lines."""
    return all(f.suffix.lower() in VIDEO_SUFFIXES or is_bag(f) for f in files)


MIN_IMAGE_SIDE = 16  # smaller holds no board and no targets


def header_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG, JPEG or BMP header, without decoding; None for other formats."""
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24:
        return struct.unpack(">II", data[16:24])
    if data[:2] == b"BM" and len(data) >= 26:
        width, height = struct.unpack("<ii", data[18:26])
        return abs(width), abs(height)
    if data[:2] == b"\xff\xd8":
        offset = 2
        while offset + 9 <= len(data):
            if data[offset] != 0xFF:
                return None
            marker = data[offset + 1]
            if marker in JPEG_STANDALONE_MARKERS:
                offset += 2
                continue
            (length,) = struct.unpack(">H", data[offset + 2:offset + 4])
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):  # a start of frame
                height, width = struct.unpack(">HH", data[offset + 5:offset + 9])
                return width, height
            offset += 2 + length
    return None


def read_image(path: Path, grey: bool = False, notes: list[str] | None = None) -> tuple[np.ndarray | None, str]:
    """Decode an image file (`grey`: to one channel, which for a JPEG skips its colour entirely); a truncated
    JPEG is refused rather than measured half-grey, and a header that declares an absurd size is refused
    before decoding; a device or pipe is refused unread. A 16-bit file is read at the depth its values use
    (`to_8_bit`), what was assumed appended to `notes`; a floating-point one is refused. Pixels are read as
    stored, the EXIF orientation not applied (`orientation`), and said in `notes` where it would have been."""
    data, problem = _file_bytes(path)
    return decode_image_file(data, grey, notes) if data is not None else (None, problem)


def _file_bytes(path: Path) -> tuple[bytes | None, str]:
    problem = special_file(path)
    if problem:
        return None, problem
    try:
        return path.read_bytes(), ""
    except OSError as exc:
        return None, f"cannot be read ({exc.strerror or exc})"


def read_photo(path: Path, grey: bool = False) -> Frame:
    """An image file as a frame (`read_image`), its time_s the moment it was taken where its EXIF says so
    (`exif.capture_time`: a timelapse's photos are a time series)."""
    notes: list[str] = []
    data, problem = _file_bytes(path)
    image, problem = decode_image_file(data, grey, notes) if data is not None else (None, problem)
    taken = capture_time(data) if data else None
    return Frame(shown_name(path), image, problem, time_s=taken[0] if taken else None, notes=tuple(notes))


def decode_image_file(data: bytes, grey: bool = False, notes: list[str] | None = None
                      ) -> tuple[np.ndarray | None, str]:
    """An image file's bytes decoded as `read_image` decodes a file (one inside an archive, say)."""
    if not data:
        return None, "is empty"
    size = header_size(data)
    if size is not None:
        width, height = size
        if excess := too_many_pixels(width, height):
            return None, f"declares {excess}"
        if min(width, height) < MIN_IMAGE_SIDE:
            return None, f"is {width}x{height} pixels, too small to hold a board or targets"
    orientation = stored_orientation(data)
    if orientation != 1 and notes is not None:
        notes.append(orientation_note(orientation))
    mode = (cv2.IMREAD_GRAYSCALE if grey else cv2.IMREAD_COLOR) | cv2.IMREAD_IGNORE_ORIENTATION

    def at_any_depth(flags: int) -> np.ndarray | None:  # a TIFF turned back: OpenCV turns it whatever the flags
        image = cv2.imdecode(np.frombuffer(data, np.uint8), flags | cv2.IMREAD_ANYDEPTH)
        return as_stored(image, orientation) if image is not None and is_tiff(data) else image

    if data[:2] != JPEG_START:
        return _at_its_depth(at_any_depth, grey, notes)
    # the image ends at its first end-of-image marker: a phone's motion photo appends its video after it, a
    # camera's MPF its preview (judging by the file's last bytes refused every motion photo as truncated)
    problem = jpeg_structure_problem(data)
    if problem:
        cut = problem.startswith("no end-of-image marker") or "runs past the file" in problem
        return None, f"is a {'truncated' if cut else 'corrupt'} JPEG ({problem})"
    image, warning = _decode_jpeg(data, mode)
    if image is None:
        return None, "is not an image OpenCV can decode"
    if warning:
        return None, f"is a corrupt JPEG (the decoder warned: {warning})"
    return image, ""


def _at_its_depth(load: Callable[[int], np.ndarray | None], grey: bool, notes: list[str] | None
                  ) -> tuple[np.ndarray | None, str]:
    """An image that is no JPEG, `load`ed with the given flags at any depth: 8 bits as they are, 16 bits at the
    depth their values use (`to_8_bit`), anything else refused."""
    mode = (cv2.IMREAD_GRAYSCALE if grey else cv2.IMREAD_COLOR) | cv2.IMREAD_IGNORE_ORIENTATION
    image = load(mode)
    if image is None:
        return None, "is not an image OpenCV can decode"
    if image.dtype == np.uint8:
        return image, ""
    if image.dtype != np.uint16:
        kind = "floating point" if image.dtype.kind == "f" else f"{8 * image.dtype.itemsize}-bit integers"
        return None, f"is a {image.dtype} image ({kind}); save it with 8 or 16 bits per channel"
    if grey:  # the depth judged on the colours, as a colour reading of the same file judges it
        image = load(cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    image, note = to_8_bit(image)
    if note and notes is not None:
        notes.append(note)
    return (cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if grey else image), ""


def tiff_pages(path: Path) -> list[int]:
    """The pages of a TIFF stack (ImageJ's and Fiji's, a scientific camera's burst) that are its frames
    (`tiff_stack.stack_pages`: the first page's size, no previews); [] for any other file."""
    if path.suffix.lower() not in (".tif", ".tiff") or special_file(path):  # a pipe is said by `read_photo`
        return []
    return stack_pages(path)


def iter_stack(path: Path, pages: list[int], grey: bool = False) -> Iterator[Frame]:
    """A TIFF stack's frames (`pages`), named STACK#frame (from 0, as a video's frames), each read from the
    file alone (a stack may be far larger than memory) at the depth its values use, timed by ImageJ's frame
    interval where the stack records one. Each page is kept in the grid it was stored in, its Orientation tag
    said where it has one (`orientation`: OpenCV turns a page whatever the flags, as it turns a lone TIFF)."""
    name = shown_name(path)
    interval = frame_interval(path)
    orientations = page_orientations(path)
    for frame, page in enumerate(pages):
        orientation = orientations[page] if page < len(orientations) else 1
        notes: list[str] = [orientation_note(orientation)] if orientation != 1 else []

        def load(flags: int, page: int = page, orientation: int = orientation) -> np.ndarray | None:
            done, images = cv2.imreadmulti(opencv_path(path), page, 1, None, flags | cv2.IMREAD_ANYDEPTH)
            return as_stored(images[0], orientation) if done and images else None

        image, problem = _at_its_depth(load, grey, notes)
        yield Frame(f"{name}#{frame}", image, problem, time_s=None if interval is None else frame * interval,
                    position=frame, notes=tuple(notes))


def _decode_jpeg(data: bytes, mode: int = cv2.IMREAD_COLOR) -> tuple[np.ndarray | None, str]:
    """Decode a JPEG, with libjpeg's warning (at most one per image) where it printed one: OpenCV decodes a
    corrupt scan without an error, so the warning is the only sign (`decoder_messages`)."""
    return with_decoder_messages(lambda: cv2.imdecode(np.frombuffer(data, np.uint8), mode))


def hidden_example(files: list[Path]) -> str:
    """A few hidden files' names, and what the `._` ones are."""
    names = [p.name for p in in_name_order(files)]
    shown = ", ".join(names[:3]) + (" ..." if len(names) > 3 else "")
    return shown + ("; `._` files are a Mac's metadata beside each file" if any(n.startswith("._") for n in names)
                    else "")


def _kinds(files: list[Path]) -> str:
    return ", ".join(sorted({f.suffix for f in files}))


def expand_inputs(paths: Sequence[str | Path], notes: list[str] | None = None, archives: bool = False) -> list[Path]:
    """Files named directly, and the image and video files inside named folders, in name order (numbers as
    numbers: `in_name_order`). Photos in a folder that OpenCV does not read (camera raw, HEIC) are said in
    `notes`; named directly, or all a folder holds, they are refused. `archives`: camera_calibration's archive
    of board views is an input (calibrating); otherwise it is refused with what it is for."""
    files: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if is_bag(path):
            files.append(path)
        elif is_archive(path) and path.exists():
            if not archives:
                raise InputError(f"{path}: an archive (camera_calibration saves its board views and ost.yaml as "
                                 "one): calibrate on its views (veg-area calibrate ARCHIVE) or measure with its "
                                 "calibration (--calibration ARCHIVE)")
            try:
                view_names(path, IMAGE_SUFFIXES)
            except ArchiveError as exc:
                raise InputError(f"{path}: {exc}") from exc
            files.append(path)
        elif path.is_dir():
            entries = [p for p in path.iterdir() if p.is_file()]
            # hidden files, as a file browser and the shell's * pass them over: a Mac's copies leave `._NAME.jpg`
            # beside each photo (its AppleDouble metadata), which were measured as unreadable frames, exit 1
            hidden = [p for p in entries if p.name.startswith(".") and p.suffix.lower() in IMAGE_SUFFIXES
                      | VIDEO_SUFFIXES]
            entries = [p for p in entries if not p.name.startswith(".")]
            if hidden and notes is not None:
                notes.append(f"{path}: {len(hidden)} hidden file{'s' if len(hidden) > 1 else ''} not read "
                             f"({hidden_example(hidden)})")
            inside = in_name_order(p for p in entries if p.suffix.lower() in IMAGE_SUFFIXES | VIDEO_SUFFIXES)
            unread = [p for p in entries if p.suffix.lower() in UNREAD_PHOTO_SUFFIXES]
            if not inside:
                raise InputError(f"{path}: folder holds no image or video files" + (
                    f" OpenCV reads: {len(unread)} photos are {_kinds(unread)} ({EXPORT_ADVICE})" if unread else "")
                    + (f" but hidden ones ({hidden_example(hidden)})" if hidden else ""))
            if unread and notes is not None:
                notes.append(f"{path}: {len(unread)} photos not read ({_kinds(unread)}: {EXPORT_ADVICE}); "
                             f"{len(inside)} other files read")
            files.extend(inside)
        elif path.is_file() and path.suffix.lower() in UNREAD_PHOTO_SUFFIXES:
            raise InputError(f"{path}: a {path.suffix} photo; {EXPORT_ADVICE}")
        elif path.is_file():
            files.append(path)
        elif path.exists():  # a FIFO, socket or device (or a symlink to one): nothing to read frames from
            raise InputError(f"{path}: not a regular file or folder (a pipe, socket or device)")
        elif path.is_symlink():
            raise InputError(f"{path}: a symlink to {os.readlink(path)}, which does not exist")
        elif (matches := glob_matches(str(raw))) is not None:
            # a pattern the shell left alone (quoted, or too many files for one command line: "Argument list
            # too long"), expanded as the shell would, as the camera node's source is
            if not matches:
                raise InputError(f"{raw}: matches no file")
            files.extend(expand_inputs(matches, notes, archives))
        else:
            raise InputError(f"{path}: no such file or folder")
    return files


def shown_name(path: Path) -> str:
    """A file's name as frames and rows carry it: its own, with any byte that is no UTF-8 shown as U+FFFD (the
    CSV and JSON are UTF-8)."""
    return path.name.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


_LINKS: list[str] = []  # folders of the links opencv_path made, removed at exit


def opencv_path(path: Path) -> str:
    """A name OpenCV can be given for `path`: its own, or where that is no UTF-8 (a byte such as 0xff, kept by
    Python as a surrogate: OpenCV's VideoCapture died of a segmentation fault on it) a symlink with a plain
    name in a private temporary folder."""
    text = str(path)
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        pass
    import atexit
    import shutil

    if not _LINKS:
        atexit.register(lambda: [shutil.rmtree(folder, ignore_errors=True) for folder in _LINKS])
    folder = tempfile.mkdtemp(prefix="veg_area_name_")
    _LINKS.append(folder)
    suffix = "".join(c for c in path.suffix if c.isascii() and (c.isalnum() or c == "."))
    link = os.path.join(folder, f"input{suffix}")
    os.symlink(os.path.abspath(path), link)
    return link


def video_frame_count(path: Path) -> int:
    capture = cv2.VideoCapture(opencv_path(path))
    try:
        return int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) if capture.isOpened() else 0
    finally:
        capture.release()


# Motion-JPEG frames this large are decoded by OpenCV's JPEG decoder on two threads (`decoded`); smaller ones by
# FFmpeg in one (their rows unchanged). The two decoders differ by up to 3 DN, which can flip a frame's sub-pixel
# decision: Af moved by up to 0.7 of its std on a 640x480 test video, 0.1 at 10 MP (test_pipeline).
PACKETS_FROM_PIXELS = 2_000_000


@dataclass(frozen=True)
class Packet:
    """A frame of a Motion-JPEG video not yet decoded: its JPEG, decoded where it is wanted (`decoded`), so that
    a 10 MP video's frames are decoded on both cores while they are measured."""
    name: str
    data: np.ndarray  # the frame's JPEG bytes
    time_s: float | None
    position: int
    notes: tuple[str, ...] = ()  # as Frame.notes


def _motion_jpeg_capture(path: Path) -> cv2.VideoCapture | None:
    """A capture that gives a large Motion-JPEG video's frames as their JPEG bytes (no decoding), or None:
    another codec, frames under PACKETS_FROM_PIXELS (decoded by FFmpeg as before: one core keeps up), or JPEGs
    without their Huffman tables (as some webcams write them, which only FFmpeg decodes)."""
    capture = cv2.VideoCapture(opencv_path(path), cv2.CAP_FFMPEG)
    fourcc = int(capture.get(cv2.CAP_PROP_FOURCC)) if capture.isOpened() else 0
    pixels = capture.get(cv2.CAP_PROP_FRAME_WIDTH) * capture.get(cv2.CAP_PROP_FRAME_HEIGHT)
    if fourcc.to_bytes(4, "little").upper() != b"MJPG" or pixels < PACKETS_FROM_PIXELS or \
            not capture.set(cv2.CAP_PROP_FORMAT, -1):
        capture.release()
        return None
    ok, first = capture.read()
    header = first.tobytes() if ok and first is not None else b""
    scan = header.find(b"\xff\xda")
    if not header.startswith(b"\xff\xd8") or scan < 0 or header.find(b"\xff\xc4", 0, scan) < 0:
        capture.release()
        return None
    capture.release()  # opened again at its start: a read cannot be put back
    capture = cv2.VideoCapture(opencv_path(path), cv2.CAP_FFMPEG)
    capture.set(cv2.CAP_PROP_FORMAT, -1)
    return capture


def _whole_jpeg(packet: np.ndarray) -> bool:
    """Whether a Motion-JPEG packet holds a whole JPEG (its end marker): a cut one would decode with a grey
    bottom and only a warning on stderr."""
    tail = packet.reshape(-1)[-64:].tobytes().rstrip(b"\x00")
    return packet.size > 4 and packet.reshape(-1)[:2].tobytes() == b"\xff\xd8" and tail.endswith(b"\xff\xd9")


def presented_time(capture: cv2.VideoCapture, index: int, fps: float) -> float | None:
    """The frame just read's presentation time in seconds, as a player shows it: a phone's video has a variable
    frame rate, and its frame number over the nominal rate was off by a tenth of a second within a few frames.
    The number over the rate where the stream records no times (FFmpeg then gives 0 for every frame)."""
    presented = capture.get(cv2.CAP_PROP_POS_MSEC) / 1000
    if math.isfinite(presented) and (presented > 0 or index == 0):
        return presented
    return index / fps if fps > 0 else None


def iter_video(path: Path, step: int = 1, start: int = 0, stop: int | None = None,
               spread: bool = False, encoded: bool = False) -> Iterator[Frame | Packet]:
    """Every `step`-th frame of a video (indices counted from its first frame), from index `start` up to
    `stop` (exclusive): a range of a long video for one worker. `spread`: one frame in each run of `step`, at a
    place that varies from run to run (`spread_offset`), so that a motion repeating every few frames (a
    camera's pose cycle) is not sampled at the same phase every time. `encoded`: a Motion-JPEG video's frames
    come as `Packet`s (see `decoded`), other videos' as frames."""
    capture = _motion_jpeg_capture(path) if encoded else None
    packets = capture is not None
    if capture is None:
        capture = one_thread_capture(opencv_path(path))
        capture.set(cv2.CAP_PROP_ORIENTATION_AUTO, 0)  # the sensor's grid, as images are read (`orientation`)
    if not capture.isOpened():
        yield Frame(shown_name(path), None, "is not a video OpenCV can open")
        return
    notes = tuple(note for note in (video_rotation_note(capture.get(cv2.CAP_PROP_ORIENTATION_META)), hdr_note(path))
                  if note)
    fps = capture.get(cv2.CAP_PROP_FPS)
    declared = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    if stop is not None:
        declared = min(declared, stop)
    index = start
    try:
        damage = VideoDamage(None if packets else video_keyframes(path, capture))

        def watched(call: Callable[[], Any]) -> tuple[Any, str]:  # a packet is checked where it is decoded
            return (call(), "") if packets else with_decoder_messages(call, FFMPEG_MESSAGE.match)

        if start:  # a seek decodes from the keyframe before `start`: damage there reaches the frames from `start`
            sought, said = watched(lambda: capture.set(cv2.CAP_PROP_POS_FRAMES, start))
            if not (sought and int(capture.get(cv2.CAP_PROP_POS_FRAMES)) == start):
                index = declared  # cannot be sought to: said below as frames that could not be read
            damage.note(start, said, seeking=True)
        while index < declared or stop is None:
            if index % step == (spread_offset(index // step, step) if spread else 0):
                (ok, image), said = watched(capture.read)
                if not ok or (packets and not _whole_jpeg(image)):  # a cut JPEG: the video ends here, as FFmpeg's
                    break
                name, time_s = f"{shown_name(path)}#{index}", presented_time(capture, index, fps)
                damaged = damage.note(index, said)
                if said and damage.intra_only:  # as a corrupt Motion-JPEG packet: its blocks are garbage, not guesses
                    yield Frame(name, None, f"this frame is corrupt (the decoder reported: {decoder_words(said)}; the "
                                "video is damaged here)", time_s=time_s, position=index)
                    index += 1
                    continue
                yield (Packet(name, image.reshape(-1), time_s, index, notes) if packets else
                       Frame(name, image, time_s=time_s, position=index, notes=notes + damaged))
            else:
                ok, said = watched(capture.grab)
                if not ok:
                    break
                damage.note(index, said)
            index += 1
    finally:
        capture.release()
    if index < declared:  # OpenCV cannot read past a frame it cannot decode: the rest of the video is lost
        lost = len(range(index + (-index % step), declared, step))
        if lost:
            yield Frame(f"{shown_name(path)}#{index}", None, f"frames {index} to {declared - 1} could not be decoded: "
                        f"the video is damaged or cut short ({index} of {declared} frames read)", lost=lost)


def iter_bag(path: Path, image_topic: str | None = None, start: int = 0, stop: int | None = None, step: int = 1,
             spread: bool = False) -> Iterator[Frame]:
    """The bag's image messages number `start` up to `stop` (exclusive), each with the camera_info recorded
    before it (read through the messages skipped); every `step`-th, as `iter_video` takes a video's (`spread`:
    one in each run of `step` at a varying place), the others never decoded."""
    from .bags import bag_image_count, iter_bag_frames

    declared = bag_image_count(path, image_topic)
    end = declared if stop is None else min(stop, declared)
    read, problem = start, ""
    try:
        for frame in iter_bag_frames(path, image_topic, start):
            if frame.index < start:
                continue
            if frame.index >= end:
                break
            read = frame.index + 1
            if frame.index % step == (spread_offset(frame.index // step, step) if spread else 0):
                yield _bag_frame(path, frame)
    except Exception as exc:  # rosbags raises its own classes for a damaged chunk: the rest is lost, said below
        problem = f" ({' '.join(str(exc).split())[:200]})"
    if read < end:  # the index lists more image messages than could be read: damaged chunks
        yield Frame(f"{shown_name(path)}#{read}", None, f"image messages {read} to {end - 1} could not be read: the "
                    f"bag is damaged{problem} ({read} of {declared} read); 'veg-area bag-recover' rebuilds what is "
                    "readable", lost=end - read)


UNSTAMPED_NOTE = ("header stamp 0: the camera driver does not stamp its images, so the frame is timed by when the "
                  "bag received it (time_s; stamp_sec and stamp_nanosec stay 0), late by the transport's delay")


def _bag_frame(path: Path, frame: BagFrame) -> Frame:
    """One bag image message as a Frame, with the reason where its pixels cannot be decoded. A 16-bit image's
    depth is judged on its own values, as a file's: a frame's reading must not depend on where a split of the
    bag (`--jobs`, a cluster) began."""
    from .cdr import ImageMessageError

    header = frame.image.header
    notes: list[str] = [frame.camera_info_note] if frame.camera_info_note else []
    try:
        image, problem = frame.image.pixels(notes=notes), ""
    except ImageMessageError as exc:
        image, problem = None, str(exc)
    time_s = header.seconds
    if header.nanoseconds == 0:  # a driver that does not stamp its images: every frame would be at time 0
        time_s = frame.timestamp_ns / 1e9
        notes.append(UNSTAMPED_NOTE)
    return Frame(f"{shown_name(path)}#{frame.index}", image, problem, time_s, (header.sec, header.nanosec),
                 frame.camera_info, position=frame.index, camera_info_problem=frame.camera_info_problem,
                 camera_metadata=frame.camera_metadata, notes=tuple(notes))


def spread_offset(window: int, step: int) -> int:
    """Where in the `window`-th run of `step` frames the frame is taken: the high bits of Knuth's 32-bit
    multiplicative hash (its low bits repeat with short periods), the same for every run of the program."""
    return ((window * 2654435761) % 2**32 >> 16) % step


def iter_frames(paths: Sequence[str | Path], video_step: int = 1, image_topic: str | None = None,
                frame_range: tuple[int, int] | None = None, grey: bool = False,
                spread: bool = False, encoded: bool = False, bag_step: int = 1) -> Iterator[Frame | Packet]:
    """Every frame of the inputs; unreadable ones come with image None and the reason. `frame_range`
    (start, stop): only those frames of a video or bag (one input). `grey`: every image in one channel (what
    a board's detection looks at; an image file is then decoded without its colour). `encoded`: Motion-JPEG
    videos' frames as `Packet`s, for `decoded` (not with `grey`). `bag_step`: every Nth frame of a bag, as
    `video_step` of a video (`spread` alike); calibrating samples a bag as a video, measuring takes every frame."""
    if encoded and grey:
        raise ValueError("encoded frames are decoded by `decoded`, in colour")
    start, stop = frame_range if frame_range is not None else (0, None)
    for path in expand_inputs(paths, archives=True):
        suffix = path.suffix.lower()
        if is_bag(path):
            yield from _greyed(iter_bag(path, image_topic, start, stop, bag_step, spread), grey)
        elif is_archive(path):
            yield from iter_archive(path, grey)
        elif suffix in VIDEO_SUFFIXES:
            yield from _greyed(iter_video(path, video_step, start, stop, spread, encoded), grey)
        elif suffix in IMAGE_SUFFIXES:
            pages = tiff_pages(path)
            # a stack's pages are its frames (only its first was measured, without a word)
            yield from iter_stack(path, pages, grey) if pages else [read_photo(path, grey)]
        else:
            # unknown extension: try as an image, then as a video, before giving up
            photo = read_photo(path, grey)
            if photo.image is not None:
                yield photo
            elif video_frame_count(path) > 0:
                yield from _greyed(iter_video(path, video_step), grey)
            else:
                yield Frame(shown_name(path), None, "is neither an image nor a video")


def iter_archive(path: Path, grey: bool = False) -> Iterator[Frame]:
    """The images inside a tar archive (camera_calibration's saved views), in name order, each named
    ARCHIVE#MEMBER; an archive that cannot be read further ends with a frame saying why."""
    try:
        for name, data, problem in read_views(path, IMAGE_SUFFIXES):
            notes: list[str] = []
            image, problem = decode_image_file(data, grey, notes) if data is not None else (None, problem)
            yield Frame(f"{shown_name(path)}#{name}", image, problem, notes=tuple(notes))
    except ArchiveError as exc:
        yield Frame(shown_name(path), None, str(exc))


def with_grey(frames: Iterator[Frame]) -> Iterator[Frame]:
    """The frames with each colour image's grey conversion beside it (`Frame.grey`): made where the frames are
    decoded (a reader thread), what the markers and a grey band are read from."""
    for frame in frames:
        yield decode_with_grey(frame)


def decode_with_grey(item: Frame | Packet) -> Frame:
    """A `Packet` decoded (OpenCV's JPEG decoder, as the same frame saved as a .jpg file would be read), and a
    colour frame's grey conversion beside it (`Frame.grey`)."""
    if isinstance(item, Packet):
        # a scrambled scan decodes into a grey smear without an error (0.4 ms a 10 MP frame to look)
        problem = jpeg_structure_problem(item.data.data)
        if problem:
            return Frame(item.name, None, f"this frame's JPEG is corrupt ({problem}; the video is damaged here)",
                         time_s=item.time_s, position=item.position)
        image = cv2.imdecode(item.data, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
        if image is None:
            return Frame(item.name, None, "this frame's JPEG could not be decoded (the video is damaged here)",
                         time_s=item.time_s, position=item.position)
        item = Frame(item.name, image, time_s=item.time_s, position=item.position, notes=item.notes)
    if item.image is not None and item.image.ndim == 3 and item.grey is None:
        item = replace(item, grey=cv2.cvtColor(item.image, cv2.COLOR_BGR2GRAY))
    return item


def decoded(items: Iterator[Frame | Packet], workers: int = 2) -> Iterator[Frame]:
    """The frames of `iter_frames(..., encoded=True)` in order, read ahead by a thread while earlier ones are
    used. A large Motion-JPEG video's packets are decoded (with their grey) by `workers` threads: their
    decoding, the larger part of measuring a 10 MP video, then runs on both cores. Frames the reader decoded
    already (FFmpeg's, at a camera's size) get their grey in the reader's thread: a pool would add Python's
    lock passed between three threads for a 0.05 ms conversion (640x480 measured 10 % slower with it). Chosen
    by the first item. Same frames as decoding them one after another."""
    from .pipeline import ordered_map, prefetched

    items = iter(items)
    first = next(items, None)
    if first is None:
        return
    if not isinstance(first, Packet):
        yield from prefetched(_then(first, items, decode_with_grey), depth=3)
        return
    for _, frame in ordered_map(decode_with_grey, prefetched(_then(first, items)), workers=workers,
                                ahead=2 * workers):
        yield frame


def _then(first: Frame, rest: Iterator[Frame], convert: Callable[[Frame], Frame] | None = None
          ) -> Iterator[Frame]:
    """`first`, then `rest`, each through `convert`; closing this closes `rest` (a video's capture released when
    a run stops early)."""
    try:
        for item in itertools.chain([first], rest):
            yield item if convert is None else convert(item)
    finally:
        close = getattr(rest, "close", None)
        if close is not None:
            close()


def _greyed(frames: Iterator[Frame], grey: bool) -> Iterator[Frame]:
    """The frames in one channel where `grey` (videos and bags give BGR or mono8)."""
    for frame in frames:
        if grey and frame.image is not None and frame.image.ndim == 3:
            frame = replace(frame, image=cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY))
        yield frame
