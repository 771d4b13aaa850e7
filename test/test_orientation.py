"""Photos a phone or a DSLR tagged with which way up it was held (EXIF orientation): read in the sensor's grid."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from helpers import run_cli
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from veg_area_ros.calib_io import write_calibration
from veg_area_ros.frames import read_image
from veg_area_ros.orientation import stored_orientation
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content

OPENCV_LEFT = Path(__file__).parent / "data" / "opencv-left"


def _exif_segment(orientation: int) -> bytes:
    """A JPEG APP1 segment holding only the orientation tag, as Pillow (not this package) writes EXIF."""
    exif = Image.Exif()
    exif[0x0112] = orientation
    payload = exif.tobytes()
    return b"\xff\xe1" + (len(payload) + 2).to_bytes(2, "big") + payload


def tagged_jpeg(data: bytes, orientation: int) -> bytes:
    """The same JPEG, every pixel's bytes as they were, with an orientation tag inserted after its start."""
    return data[:2] + _exif_segment(orientation) + data[2:]


def _saved(image: np.ndarray, suffix: str, orientation: int) -> bytes:
    picture = Image.fromarray(image)
    exif = picture.getexif()
    exif[0x0112] = orientation
    out = io.BytesIO()
    options = {"lossless": True} if suffix == "webp" else {}
    picture.save(out, format={"tif": "TIFF"}.get(suffix, suffix.upper()), exif=exif.tobytes(), **options)
    return out.getvalue()


def _cube_jpeg() -> bytes:
    return cv2.imencode(".jpg", render_scene(ENDOSCOPE, cube_scene(), 0.7), [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()


def _measured(folder: Path, photos: dict[str, bytes]) -> dict[str, dict]:
    """Each photo written to `folder` and measured by `veg-area measure` with the true camera and the scene's
    targets: its JSON row."""
    write_calibration(folder / "endoscope.yaml", ENDOSCOPE, "endoscope", {"medium": "air"})
    (folder / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    rows = {}
    for name, data in photos.items():
        (folder / name).write_bytes(data)
        done = run_cli("measure", str(folder / name), "--calibration", str(folder / "endoscope.yaml"),
                       "--targets", str(folder / "targets.yaml"), "--json", cwd=folder)
        assert done.returncode == 0, done.stderr
        rows[name] = json.loads(done.stdout)
    return rows


@pytest.mark.parametrize("suffix", ["png", "tif", "webp"])
@pytest.mark.parametrize("orientation", range(1, 9))
def test_every_orientation_of_each_format_is_read_as_stored_and_said(tmp_path, suffix, orientation):
    """OpenCV turns a tagged image as a photo viewer does (a TIFF even when told not to): read here as stored,
    the pixels exactly the file's, and a frame that a viewer would turn says so."""
    rng = np.random.default_rng(orientation)
    stored = rng.integers(0, 256, (48, 64), np.uint8)
    path = tmp_path / f"photo.{suffix}"
    path.write_bytes(_saved(stored, suffix, orientation))
    assert stored_orientation(path.read_bytes()) == orientation
    shown = cv2.imdecode(np.frombuffer(path.read_bytes(), np.uint8), cv2.IMREAD_GRAYSCALE)
    assert (shown.shape == stored.shape) == (orientation <= 4)  # what OpenCV alone gives: a viewer's
    notes: list[str] = []
    image, problem = read_image(path, grey=True, notes=notes)
    assert problem == "" and np.array_equal(image, stored)
    colour, _ = read_image(path)
    assert np.array_equal(colour[..., 0], stored)
    said = [note for note in notes if note.startswith("EXIF orientation")]
    assert len(said) == (orientation != 1) and all(f"EXIF orientation {orientation} not applied" in n for n in said)


def test_a_jpegs_tag_does_not_turn_it(tmp_path):
    plain = (OPENCV_LEFT / "left01.jpg").read_bytes()
    for orientation in range(1, 9):
        path = tmp_path / f"left01_{orientation}.jpg"
        path.write_bytes(tagged_jpeg(plain, orientation))
        assert stored_orientation(path.read_bytes()) == orientation
        image, problem = read_image(path)
        assert problem == "" and np.array_equal(image, read_image(OPENCV_LEFT / "left01.jpg")[0])


def test_photos_held_either_way_calibrate_as_the_sensor_and_measure(tmp_path):
    """Real photos (OpenCV's 13 of one webcam), every third tagged as turned 90° clockwise, as a phone or a DSLR
    held by hand around a board tags them: read turned, 5 of the 13 were skipped ("640x480 differs from the
    first image's 480x640") and the fit was the sensor's turned; now the calibration is the untagged set's (to
    the solver's last digits) and says once what it did not apply. A tagged photo of the cube measures as the
    untagged one (it was refused: "frame is 480x640 but the calibration is for 640x480") and its row says the
    tag was not applied."""
    untagged, tagged = tmp_path / "untagged", tmp_path / "tagged"
    shutil.copytree(OPENCV_LEFT, untagged)
    tagged.mkdir()
    for k, photo in enumerate(sorted(untagged.glob("*.jpg"))):
        data = photo.read_bytes()
        (tagged / photo.name).write_bytes(tagged_jpeg(data, 6) if k % 3 == 0 else data)
    fits = {}
    for folder in (untagged, tagged):
        done = run_cli("calibrate", str(folder), "--board", "chessboard:9x6:0.025", "--medium", "air",
                       "--output", str(tmp_path / f"{folder.name}.yaml"), cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        fits[folder.name] = (yaml.safe_load((tmp_path / f"{folder.name}.yaml").read_text()), done.stdout + done.stderr)
    for key in ("camera_matrix", "distortion_coefficients"):  # equal but for the solver's last digits (threads)
        assert fits["tagged"][0][key]["data"] == pytest.approx(fits["untagged"][0][key]["data"], rel=1e-7, abs=1e-9)
    assert fits["tagged"][0]["image_width"] == 640
    assert "5 of 13 frames: EXIF orientation 6 not applied" in fits["tagged"][1], fits["tagged"][1]
    assert "differs from" not in fits["tagged"][1] and "EXIF" not in fits["untagged"][1]

    cube = _cube_jpeg()
    rows = _measured(tmp_path, {"cube.jpg": cube, "cube_turned.jpg": tagged_jpeg(cube, 8)})
    assert rows["cube_turned.jpg"]["area_m2"] == rows["cube.jpg"]["area_m2"]
    assert any("EXIF orientation 8 not applied" in w for w in rows["cube_turned.jpg"]["warnings"])
    assert not any("EXIF" in w for w in rows["cube.jpg"]["warnings"])


@settings(max_examples=300, deadline=None)
@given(prefix=st.sampled_from([b"\xff\xd8", b"\x89PNG\r\n\x1a\n", b"RIFF\x00\x00\x00\x00WEBP", b"II*\x00", b"MM\x00*"]),
       body=st.binary(max_size=200))
def test_any_bytes_give_an_orientation_or_none_never_an_error(prefix, body):
    assert stored_orientation(prefix + body) in range(1, 9)
    assert stored_orientation(prefix + b"\xff\xe1\x00\x10Exif\x00\x00MM\x00*" + body) in range(1, 9)


def rotated_mp4(data: bytes, degrees: int) -> bytes:
    """The same MP4 with its video track's display matrix turned by `degrees` (90, 180, 270), as a phone writes
    a video taken upright: the frames' bytes as they were."""
    import struct

    box = data.find(b"tkhd")
    assert box > 0 and data[box + 4] == 0  # version 0: 32-bit times before the matrix
    matrix = box + 4 + 4 + 20 + 8 + 8
    one = 0x10000
    cos, sin = {90: (0, 1), 180: (-1, 0), 270: (0, -1)}[degrees]
    turned = struct.pack(">9i", cos * one, sin * one, 0, -sin * one, cos * one, 0, 0, 0, 0x40000000)
    return data[:matrix] + turned + data[matrix + 36:]


def test_a_phones_video_is_read_as_stored_and_says_its_rotation(tmp_path):
    """A video whose container says "show it turned 90°" (a phone held upright): OpenCV turned its frames, so
    a calibration of the sensor refused them ("frame is 480x640 but the calibration is for 640x480"); read as
    stored, each frame measures as the unturned video's and says the rotation was not applied."""
    write_calibration(tmp_path / "endoscope.yaml", ENDOSCOPE, "endoscope", {"medium": "air"})
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    writer = cv2.VideoWriter(str(tmp_path / "clip.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 10, (640, 480))
    for k in range(3):
        writer.write(render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=k))
    writer.release()
    (tmp_path / "clip_upright.mp4").write_bytes(rotated_mp4((tmp_path / "clip.mp4").read_bytes(), 90))
    capture = cv2.VideoCapture(str(tmp_path / "clip_upright.mp4"))
    assert capture.read()[1].shape == (640, 480, 3)  # what OpenCV alone gives: a player's
    capture.release()
    rows = {}
    for name in ("clip.mp4", "clip_upright.mp4"):
        done = run_cli("measure", str(tmp_path / name), "--calibration", str(tmp_path / "endoscope.yaml"),
                       "--targets", str(tmp_path / "targets.yaml"), "--json", "--csv", str(tmp_path / f"{name}.csv"),
                       cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        rows[name] = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert [r["area_m2"] for r in rows["clip_upright.mp4"]] == [r["area_m2"] for r in rows["clip.mp4"]]
    assert len(rows["clip.mp4"]) == 3
    assert all(any("video rotation 90° not applied" in w for w in r["warnings"]) for r in rows["clip_upright.mp4"])
    assert not any("rotation" in w for r in rows["clip.mp4"] for w in r["warnings"])


def test_a_phones_motion_photo_is_measured_as_its_still_and_a_cut_one_is_still_refused(tmp_path):
    """A Pixel's or a Galaxy's motion photo is a JPEG with its short video (MP4) appended after the image's
    end marker, as a camera's MPF preview is: judged by the file's last bytes it was refused as "a truncated
    JPEG". Now the image ends at its own end marker: the still measures as the same JPEG alone does. A JPEG cut
    inside its image data is still refused as truncated."""
    still = _cube_jpeg()
    video = b"\x00\x00\x00\x18ftypmp42\x00\x00\x00\x00mp42isom" + np.random.default_rng(7).bytes(20000)
    rows = _measured(tmp_path, {"still.jpg": still, "PXL_20260502_100003.MP.jpg": still + video})
    assert rows["PXL_20260502_100003.MP.jpg"]["area_m2"] == rows["still.jpg"]["area_m2"]
    (tmp_path / "cut.jpg").write_bytes(still[: len(still) // 2])
    image, problem = read_image(tmp_path / "cut.jpg")
    assert image is None and problem.startswith("is a truncated JPEG"), problem
