"""Which pages of a TIFF are a stack's frames: read from the directories (classic TIFF and BigTIFF), previews
and pages of another size left out, and a stack with a thumbnail measured as its frames alone."""

from __future__ import annotations

import struct

import cv2
import numpy as np
import pytest

from veg_area_ros.frames import iter_frames
from veg_area_ros.tiff_stack import stack_pages


def _tiff(pages: list[tuple[int, int, int]], big: bool = False, order: str = "<", loop: bool = False) -> bytes:
    """A TIFF's directories alone (no pixels: the page reader looks at no more), each page (width, height,
    NewSubfileType) with the three tags written as LONG (classic) or LONG8 (BigTIFF)."""
    count_format, entry_size, offset_format, kind = ("Q", 20, "Q", 16) if big else ("H", 12, "I", 4)
    header = (b"II" if order == "<" else b"MM") + (struct.pack(order + "HHHQ", 43, 8, 0, 16) if big
                                                  else struct.pack(order + "HI", 42, 8))
    entry_count, offset_size = struct.calcsize(count_format), struct.calcsize(offset_format)
    directory_size = entry_count + 3 * entry_size + offset_size
    data, start = b"", len(header)
    for k, (width, height, subfile) in enumerate(pages):
        following = start + (k + 1) * directory_size if k + 1 < len(pages) else (start if loop else 0)
        entries = b"".join(struct.pack(order + "HH", tag, kind) + struct.pack(order + offset_format, 1)
                           + struct.pack(order + offset_format, value)
                           for tag, value in ((254, subfile), (256, width), (257, height)))
        data += struct.pack(order + count_format, 3) + entries + struct.pack(order + offset_format, following)
    return header + data


@pytest.mark.parametrize("big", [False, True])
@pytest.mark.parametrize("order", ["<", ">"])
def test_the_pages_of_the_first_pages_size_and_no_preview_are_the_frames(tmp_path, big, order):
    path = tmp_path / "stack.tif"
    for pages, frames in (([(640, 480, 2)] * 4, [0, 1, 2, 3]),
                          ([(640, 480, 0), (160, 120, 1)], []),  # one photo and its thumbnail
                          ([(640, 480, 2), (160, 120, 0), (640, 480, 2), (640, 480, 2)], [0, 2, 3]),
                          ([(640, 480, 2), (640, 480, 1), (640, 480, 2)], [0, 2]),  # a full-size preview
                          ([(1024, 1024, 0), (512, 512, 0), (256, 256, 0)], []),  # a pyramid
                          ([(640, 480, 0)], [])):
        path.write_bytes(_tiff(pages, big, order))
        assert stack_pages(path) == frames, pages
    path.write_bytes(_tiff([(640, 480, 2)] * 3, big, order, loop=True))  # a chain that loops ends
    assert stack_pages(path) == [0, 1, 2]
    path.write_bytes(_tiff([(640, 480, 2)] * 3, big, order)[:-10])  # cut short: read as one image, as before
    assert stack_pages(path) == []
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(40))
    assert stack_pages(path) == []


def test_a_stack_with_a_thumbnail_is_read_as_its_frames_and_a_photo_with_one_as_one_image(tmp_path):
    """A camera's TIFF with a preview page was one image, and stays one; a stack's preview is no frame."""
    rng = np.random.default_rng(2)
    frames = [rng.integers(0, 256, (120, 160, 3)).astype(np.uint8) for _ in range(3)]
    thumbnail = cv2.resize(frames[0], (40, 30))
    assert cv2.imwritemulti(str(tmp_path / "stack.tif"), [*frames, thumbnail])
    assert cv2.imwritemulti(str(tmp_path / "photo.tif"), [frames[0], thumbnail])
    read = list(iter_frames([tmp_path / "stack.tif", tmp_path / "photo.tif"]))
    assert [frame.name for frame in read] == ["stack.tif#0", "stack.tif#1", "stack.tif#2", "photo.tif"]
    assert all(np.array_equal(frame.image, image) for frame, image in zip(read, [*frames, frames[0]], strict=True))


def _with_description(data: bytes, text: str) -> bytes:
    """A little-endian TIFF with `text` as its first page's ImageDescription (the page's directory copied to the
    end with the tag added, in tag order, and the header pointed at it)."""
    first = struct.unpack("<I", data[4:8])[0]
    (count,) = struct.unpack("<H", data[first:first + 2])
    entries = [data[first + 2 + 12 * k:first + 14 + 12 * k] for k in range(count)]
    following = data[first + 2 + 12 * count:first + 6 + 12 * count]
    body = data + b"\0" * (len(data) % 2)
    description = text.encode() + b"\0"
    entries.append(struct.pack("<HHII", 270, 2, len(description), len(body)))
    entries.sort(key=lambda entry: struct.unpack("<H", entry[:2])[0])
    body += description + b"\0" * (len(description) % 2)
    directory = struct.pack("<H", len(entries)) + b"".join(entries) + following
    return data[:4] + struct.pack("<I", len(body)) + body[8:] + directory


def test_an_imagej_timelapse_stack_is_timed_by_its_frame_interval(tmp_path):
    """A timelapse saved by ImageJ or Fiji records its frame interval (`finterval=`, in `tunit`) in its first
    page's description: its frames are a time series in seconds, as a video's; without one, frame numbers."""
    from veg_area_ros.tiff_stack import frame_interval

    rng = np.random.default_rng(4)
    frames = [rng.integers(0, 256, (120, 160, 3)).astype(np.uint8) for _ in range(3)]
    assert cv2.imwritemulti(str(tmp_path / "plain.tif"), frames)
    plain = (tmp_path / "plain.tif").read_bytes()
    assert plain[:2] == b"II"
    for name, description, interval in (
            ("half.tif", "ImageJ=1.54f\nimages=3\nframes=3\nfinterval=0.5\nloop=false\n", 0.5),
            ("minutes.tif", "ImageJ=1.54f\nimages=3\nframes=3\nfinterval=2\ntunit=min\n", 120.0),
            ("unset.tif", "ImageJ=1.54f\nimages=3\nframes=3\n", None),
            ("other.tif", "finterval=0.5\n", None)):  # not ImageJ's: its keys are not read
        (tmp_path / name).write_bytes(_with_description(plain, description))
        assert frame_interval(tmp_path / name) == interval, name
        read = list(iter_frames([tmp_path / name]))
        assert [frame.time_s for frame in read] == ([None] * 3 if interval is None else [0, interval, 2 * interval])
        assert all(np.array_equal(frame.image, image) for frame, image in zip(read, frames, strict=True))
    assert frame_interval(tmp_path / "plain.tif") is None


def _set_orientations(data: bytes, orientations: list[int]) -> bytes:
    """A little-endian classic TIFF whose pages (in their chain) each carry an Orientation entry, with those
    entries' values set to `orientations`, page by page."""
    data, offset = bytearray(data), struct.unpack("<I", data[4:8])[0]
    for orientation in orientations:
        (count,) = struct.unpack("<H", data[offset:offset + 2])
        entries = [offset + 2 + 12 * k for k in range(count)]
        (at,) = [entry for entry in entries if struct.unpack("<H", data[entry:entry + 2])[0] == 274]
        assert struct.unpack("<HI", data[at + 2:at + 8]) == (3, 1)  # SHORT, one value, held in the entry
        data[at + 8:at + 10] = struct.pack("<H", orientation)
        offset = struct.unpack("<I", data[offset + 2 + 12 * count:offset + 6 + 12 * count])[0]
    assert offset == 0
    return bytes(data)


def test_a_stacks_pages_stay_in_their_stored_grid_and_say_their_orientation(tmp_path):
    """OpenCV turns a stack's page by its Orientation tag whatever the flags (a 160x120 page came out 120x160,
    nothing said): each page is read as stored, the sensor's grid the calibration holds for, as a lone TIFF or
    JPEG is, and one whose tag would have turned it says so."""
    from PIL import Image

    from veg_area_ros.tiff_stack import page_orientations

    rng = np.random.default_rng(6)
    frames = [rng.integers(0, 256, (120, 160, 3)).astype(np.uint8) for _ in range(3)]
    tags = Image.Exif()
    tags[274] = 6
    pages = [Image.fromarray(frame[:, :, ::-1]) for frame in frames]
    pages[0].save(tmp_path / "written.tif", save_all=True, append_images=pages[1:], exif=tags)
    written = (tmp_path / "written.tif").read_bytes()
    assert written[:2] == b"II"
    path = tmp_path / "stack.tif"
    path.write_bytes(_set_orientations(written, [6, 1, 3]))
    assert page_orientations(path) == [6, 1, 3] and stack_pages(path) == [0, 1, 2]
    turned = cv2.imreadmulti(str(path), 0, 1, None, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)[1][0]
    assert turned.shape == (160, 120, 3)  # what OpenCV gives: the page turned for showing
    read = list(iter_frames([path]))
    assert [frame.name for frame in read] == ["stack.tif#0", "stack.tif#1", "stack.tif#2"]
    assert all(np.array_equal(frame.image, image) for frame, image in zip(read, frames, strict=True))
    assert ["EXIF orientation 6 not applied" in " ".join(frame.notes) for frame in read] == [True, False, False]
    assert "EXIF orientation 3 not applied" in " ".join(read[2].notes)
    grey = list(iter_frames([path], grey=True))
    assert all(np.abs(frame.image.astype(int) - cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)).max() <= 1
               for frame, image in zip(grey, frames, strict=True))  # OpenCV's grey reading rounds its own way
    path.write_bytes(_set_orientations(written, [1, 1, 1]))
    assert page_orientations(path) == [1, 1, 1]
    assert not any(frame.notes for frame in iter_frames([path]))
