"""An HDR phone video (HLG or PQ, named in its MP4 / QuickTime colour box) is measured and says in every row
that its levels follow a curve neither tone curve reads; an SDR one, or a file that is no ISO base media, says
nothing. The colour box is written here by hand into OpenCV's MP4, as a phone's muxer writes it."""

from __future__ import annotations

import json
import struct

import cv2
import pytest
import yaml
from helpers import run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from veg_area_ros.calib_io import write_calibration
from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content
from veg_area_ros.video_container import hdr_note, transfer_characteristics

PATH_TO_ENTRIES = (b"moov", b"trak", b"mdia", b"minf", b"stbl", b"stsd")


def with_colour_box(data: bytes, transfer: int, kind: bytes = b"nclx", colours: int = 9) -> bytes:
    """The MP4 with a colour box (`colours`' primaries and matrix, 9 = BT.2020 as HDR video has, and this
    transfer) appended to its first video sample entry, every enclosing box's size grown by it. OpenCV writes
    `moov` after the media data, so no chunk offset moves."""
    body = kind + struct.pack(">HHH", colours, transfer, colours) + (b"\x00" if kind == b"nclx" else b"")
    colr = struct.pack(">I4s", 8 + len(body), b"colr") + body
    starts, offset, end = [], 0, len(data)
    for name in PATH_TO_ENTRIES:  # each box's offset on the way down (the first of its kind inside the last)
        while True:
            size, found = struct.unpack_from(">I4s", data, offset)
            if found == name:
                break
            offset += size
            assert offset < end, name
        starts.append(offset)
        end = offset + size
        offset += 8 + (8 if name == b"stsd" else 0)  # stsd: version, flags and the entry count before the entries
    entry = offset
    starts.append(entry)
    (entry_size,) = struct.unpack_from(">I", data, entry)
    data = data[:entry + entry_size] + colr + data[entry + entry_size:]
    for start in starts:
        (size,) = struct.unpack_from(">I", data, start)
        data = data[:start] + struct.pack(">I", size + len(colr)) + data[start + 4:]
    return data


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hdr")
    writer = cv2.VideoWriter(str(folder / "sdr.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 10, (640, 480))
    for k in range(3):
        writer.write(render_scene(ENDOSCOPE, cube_scene(), 0.7, seed=k))
    writer.release()
    plain = (folder / "sdr.mp4").read_bytes()
    (folder / "hlg.mp4").write_bytes(with_colour_box(plain, 18))
    (folder / "pq.mov").write_bytes(with_colour_box(plain, 16, b"nclc"))
    (folder / "bt709.mp4").write_bytes(with_colour_box(plain, 1, colours=1))
    write_calibration(folder / "endoscope.yaml", ENDOSCOPE, "endoscope", {"medium": "air"})
    (folder / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    return folder


def test_the_colour_box_is_read_where_a_phone_writes_it(clips):
    assert [transfer_characteristics(clips / name) for name in ("sdr.mp4", "hlg.mp4", "pq.mov", "bt709.mp4")] == [
        None, 18, 16, 1]
    assert "HLG" in hdr_note(clips / "hlg.mp4") and "PQ" in hdr_note(clips / "pq.mov")
    assert hdr_note(clips / "bt709.mp4") == "" and hdr_note(clips / "sdr.mp4") == ""


def test_an_hdr_video_is_measured_and_every_row_says_its_curve(clips):
    """Each HDR row says why it is less trustworthy; the SDR video's and the BT.709-tagged one's say nothing
    of it. OpenCV's FFmpeg reads the box too: the same samples decode brighter as HLG or PQ (the first frame's
    mean grey 114 untagged, 140 as HLG, 130 as PQ), so their Af is not the SDR video's; tagged BT.709 they
    decode within a level of the untagged ones, and Af stays within 0.2 %."""
    rows = {}
    for name in ("sdr.mp4", "hlg.mp4", "pq.mov", "bt709.mp4"):
        done = run_cli("measure", str(clips / name), "--calibration", str(clips / "endoscope.yaml"), "--targets",
                       str(clips / "targets.yaml"), "--json", "--csv", str(clips / f"{name}.csv"), cwd=clips)
        assert done.returncode == 0, done.stderr
        rows[name] = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
        assert len(rows[name]) == 3
    assert [r["area_m2"] for r in rows["bt709.mp4"]] == pytest.approx([r["area_m2"] for r in rows["sdr.mp4"]],
                                                                     rel=0.002)
    grey = {name: cv2.cvtColor(cv2.VideoCapture(str(clips / name)).read()[1], cv2.COLOR_BGR2GRAY).mean()
            for name in ("sdr.mp4", "hlg.mp4", "pq.mov")}
    assert grey["hlg.mp4"] > grey["sdr.mp4"] + 10 and grey["pq.mov"] > grey["sdr.mp4"] + 5, grey
    assert all(any(w.startswith("HDR video (HLG") for w in r["warnings"]) for r in rows["hlg.mp4"])
    assert all(any(w.startswith("HDR video (PQ") for w in r["warnings"]) for r in rows["pq.mov"])
    assert not any("HDR" in w for name in ("sdr.mp4", "bt709.mp4") for r in rows[name] for w in r["warnings"])


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400), st.integers(0, 3))
def test_any_bytes_give_a_transfer_or_none_and_never_an_error(tmp_path_factory, data, cut):
    """Broken, cut or foreign files: the box walk stops where a box does not fit."""
    path = tmp_path_factory.mktemp("bytes") / "clip.mp4"
    moov = struct.pack(">I4s", 8 + len(data), b"moov") + data
    for content in (data, moov, moov[:len(moov) - cut]):
        path.write_bytes(content)
        assert transfer_characteristics(path) is None or isinstance(transfer_characteristics(path), int)
