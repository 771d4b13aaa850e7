"""Classes of bad input replayed through `veg-area` as a user runs it, each in its own process under
a time and memory watch: no traceback, no result that is wrong with exit 0, every refusal in under 2 s (beyond
the interpreter's start-up, measured in the same run) and 500 MB, and no existing file lost."""

from __future__ import annotations

import os
import resource
import struct
import subprocess
import sys
import time
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from veg_area_ros.calib_io import to_camera_info_dict, write_calibration
from veg_area_ros.sim.synthetic import (
    ENDOSCOPE,
    cube_scene,
    empty_scene,
    render_scene,
    scene_targets_content,
)

REPO = Path(__file__).resolve().parents[2]
MEMORY_LIMIT = 500 * 2**20  # what a refusal may cost at most
TIME_LIMIT_S = 2.0
ADDRESS_SPACE_CAP = 4 * 2**30  # a runaway input fails fast here instead of taking the machine's 24 GB


@dataclass
class Run:
    code: int
    stdout: str
    stderr: str
    seconds: float
    peak_rss: int  # bytes


# the child writes its own peak resident memory at exit: VmHWM, its address space's high-water mark (kB).
# Not ru_maxrss: Linux carries the forking process's peak across exec into it (a pytest grown to 515 MB made
# every child read 515 MB); nor RUSAGE_CHILDREN, the largest child so far
CHILD = ("import atexit, os, sys\n"
         "def peak():\n"
         "    status = open('/proc/self/status').read().split('VmHWM:')[1].split()[0]\n"
         "    open(os.environ['PEAK_FILE'], 'w').write(status)\n"
         "atexit.register(peak)\n"
         "from veg_area_ros.cli import main\n"
         "sys.exit(main(sys.argv[1:]))\n")


def children_cpu_seconds() -> float:
    """CPU seconds of the children waited for: what a run cost, which a busy machine does not stretch."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_capped(args: list[str], cwd: Path) -> Run:
    """`veg-area ARGS` (the CLI's main, as `python -m veg_area_ros.cli` runs it) with its peak memory and CPU
    time, under an address-space cap."""
    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE_CAP, ADDRESS_SPACE_CAP))

    peak_file = cwd / f"peak_{time.monotonic_ns()}.txt"
    env = dict(os.environ, PYTHONPATH=str(REPO), PEAK_FILE=str(peak_file))
    started = children_cpu_seconds()
    process = subprocess.Popen([sys.executable, "-c", CHILD, *args], cwd=cwd, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=cap)
    try:
        stdout, stderr = process.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        process.kill()
        stdout, stderr = process.communicate()
    seconds = children_cpu_seconds() - started  # CPU time: a loaded machine stretches wall time, not this
    peak = int(peak_file.read_text()) * 1024 if peak_file.exists() else MEMORY_LIMIT * 100
    peak_file.unlink(missing_ok=True)
    return Run(process.returncode, stdout.decode(errors="replace"), stderr.decode(errors="replace"), seconds, peak)


def png_declaring(width: int, height: int) -> bytes:
    _, png = cv2.imencode(".png", np.zeros((48, 64, 3), np.uint8))
    bomb = bytearray(png.tobytes())
    bomb[16:24] = struct.pack(">II", width, height)
    return bytes(bomb)


def valid_huge_png(side: int) -> bytes:
    """A real, decodable side x side grey PNG, streamed (a few hundred kB: all zeros)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    compressor, row, body = zlib.compressobj(9), bytes(side + 1), []
    for _ in range(side):
        body.append(compressor.compress(row))
    body.append(compressor.flush())
    header = struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", b"".join(body)) + chunk(b"IEND", b"")


ALIAS_BOMB = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{chr(98 + k)}: &{chr(98 + k)} [" + ", ".join([f"*{chr(97 + k)}"] * 9) + "]\n" for k in range(8))


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("worst")
    write_calibration(folder / "camera.yaml", ENDOSCOPE, "endoscope", {"medium": "air"})
    (folder / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7)
    cv2.imwrite(str(folder / "cube.png"), frame)
    (folder / "bomb.png").write_bytes(png_declaring(100000, 100000))
    (folder / "huge.png").write_bytes(valid_huge_png(20000))
    cv2.imwrite(str(folder / "tiny.png"), np.zeros((1, 1, 3), np.uint8))
    _, jpeg = cv2.imencode(".jpg", frame)
    scrambled = bytearray(jpeg.tobytes())
    scrambled[len(scrambled) // 3:len(scrambled) // 3 + 2000] = np.random.default_rng(0).integers(
        0, 256, 2000, dtype=np.uint8).tobytes()
    (folder / "scrambled.jpg").write_bytes(bytes(scrambled))
    (folder / "alias_targets.yaml").write_text(ALIAS_BOMB)
    (folder / "alias_camera.yaml").write_text(ALIAS_BOMB)
    info = to_camera_info_dict(ENDOSCOPE, "endoscope")
    text = yaml.safe_dump(info, sort_keys=False)
    (folder / "alias_name.yaml").write_text(text.replace("camera_name: endoscope",
                                                         "camera_name: &n [x, x, x]\nbomb: [*n, *n, *n]"))
    longer = [v * 1.06 for v in info["camera_matrix"]["data"]]  # a second camera_matrix: a plain load takes the last
    (folder / "duplicate_key.yaml").write_text(f"{text}camera_matrix:\n  rows: 3\n  cols: 3\n  data: {longer}\n")
    write_calibration(folder / "k1.yaml", replace(ENDOSCOPE, k1=1e6), "endoscope")
    markers = scene_targets_content()["markers"]
    ids = sorted(markers)
    permuted = {a: markers[b] for a, b in zip(ids, ids[1:] + ids[:1], strict=True)}
    (folder / "permuted.yaml").write_text(yaml.safe_dump(scene_targets_content(permuted)))
    mistyped = dict(markers)
    mistyped[ids[2]] = [markers[ids[2]][0] * 10, markers[ids[2]][1]]
    (folder / "mistyped.yaml").write_text(yaml.safe_dump(scene_targets_content(mistyped)))
    (folder / "a_file").write_text("not a folder")
    (folder / "targets_5x5.yaml").write_text(yaml.safe_dump({**scene_targets_content(), "dictionary": "DICT_5X5_50"}))
    for name, factor in (("mm", 1e3), ("huge", 1e13), ("km", 1e-3)):  # coordinates in the wrong unit
        scaled = {k: [x * factor, y * factor] for k, (x, y) in markers.items()}
        (folder / f"targets_{name}.yaml").write_text(yaml.safe_dump(scene_targets_content(scaled)))
    cv2.imwrite(str(folder / "empty.png"), render_scene(ENDOSCOPE, empty_scene(cube_scene()), 0.7, noise_sigma=3))
    cv2.imwrite(str(folder / "grey.png"), cv2.cvtColor(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR))
    os.mkfifo(folder / "frames.fifo")
    (folder / "runs.csv").write_text("velocity_m_s,force_n,area_m2\n0.2,0.05,0.01\n0.4,0.16,0.009\n0.6,0.3,0.008\n")
    return folder


def measure(*extra: str, image: str = "cube.png", calibration: str = "camera.yaml",
            targets: str = "targets.yaml") -> list[str]:
    return ["measure", image, "--calibration", calibration, "--targets", targets, "--threshold", "120", *extra]


# name -> (arguments, the words the refusal must hold)
CASES = {
    "png declaring 100000x100000": (measure(image="bomb.png"), "declares 100000x100000"),
    "valid 20000x20000 png": (measure(image="huge.png"), "declares 20000x20000"),
    "1x1 png": (measure(image="tiny.png"), "too small"),
    "corrupt jpeg": (measure(image="scrambled.jpg"), "corrupt JPEG"),
    "close radius 100000": (measure("--close", "100000"), "morphology radii must be at most"),
    "csv under a file": (measure("--csv", "a_file/areas.csv"), "a_file"),
    "csv under /proc": (measure("--csv", "/proc/areas.csv"), "/proc"),
    "overlay under a file": (measure("--overlay", "a_file/o.png"), "a_file"),
    "calibration output under a file": (["calibrate", "cube.png", "--board", "chessboard:9x6:0.03", "-o",
                                         "a_file/c.yaml"], "a_file"),
    "targets alias bomb": (measure(targets="alias_targets.yaml"), "alias"),
    "calibration alias bomb": (measure(calibration="alias_camera.yaml"), "alias"),
    "alias in camera_name": (measure(calibration="alias_name.yaml"), "alias"),
    "duplicate camera_matrix": (measure(calibration="duplicate_key.yaml"), "camera_matrix"),
    "k1 = 1e6": (measure(calibration="k1.yaml"), "implausible camera model"),
    "permuted marker ids": (measure(targets="permuted.yaml"), "do not match the board"),
    "mistyped coordinate": (measure(targets="mistyped.yaml"), "do not match the board"),
    "board square in millimetres": (["calibrate", "cube.png", "--board", "chessboard:9x6:25", "-o", "mm.yaml"],
                                    "millimetres given as metres"),
    "idealized folder named as an image": (measure("--idealized", "ideal.png"), "give a folder name"),
    "vogel plot not a png": (["vogel", "runs.csv", "--plot", "none"], "ending in .png"),
    "calibration distance in millimetres": (["calibrate", "cube.png", "--board", "chessboard:9x6:0.03", "-o",
                                             "d.yaml", "--distance", "700"], "millimetres given as metres"),
    "water index of air": (["calibrate", "--lens", "camera.yaml", "--port", "flat:0.02:0.006:1.49", "-o", "p.yaml",
                            "--water-index", "1.0"], "1 is air's"),
    "bag-recover of a missing path": (["bag-recover", "nowhere.mcap", "out_bag"], "no such bag"),
    "bag-recover of a mangled file": (["bag-recover", "cube.png", "out_bag2"], "not an MCAP file"),
    "roi off the image": (measure("--roi", "2000,2000,2100,2000,2100,2100"), "lies outside"),
    # plausibility: a number that cannot be right never leaves with exit 0
    "reversed levels": (measure("--levels", "230,40"), "reversed for a dark object"),
    "reversed levels, far apart": (measure("--levels", "250,5"), "reversed for a dark object"),
    "reversed levels, bright object": (measure("--levels", "40,230", "--object", "bright"),
                                       "reversed for a bright object"),
    "green on a grey image": (measure("--object", "green", image="grey.png"), "has no colour"),
    "targets in millimetres": (measure(targets="targets_mm.yaml"), "millimetres given as metres"),
    "targets 1e13 too large": (measure(targets="targets_huge.yaml"), "millimetres given as metres"),
    "targets in kilometres": (measure(targets="targets_km.yaml"), "metres given as kilometres"),
    "no object, fixed threshold": (measure(image="empty.png"), "no object found"),
    "targets of another dictionary": (measure(targets="targets_5x5.yaml"), "the frame holds 4X4 markers (ids up to "
                                      "3), not DICT_5X5_50's: is the targets file's dictionary DICT_4X4_50?"),
    "no object, otsu": (measure("--threshold", "otsu", image="empty.png"), "no object found"),
    "roi at 1e9 px": (measure("--roi", "0,0,1e9,0,1e9,1e9"), "beyond any image"),
    # outputs over inputs
    "csv over the image": (measure("--csv", "cube.png"), "is the input cube.png"),
    "overlay over the image": (measure("--overlay", "cube.png"), "is the input cube.png"),
    "csv over the calibration": (measure("--csv", "camera.yaml"), "is the input camera.yaml"),
    "csv over the targets": (measure("--csv", "targets.yaml"), "is the input targets.yaml"),
    # messages that name the real cause
    "a fifo as input": (measure(image="frames.fifo"), "not a regular file or folder"),
    "start time nan": (measure("--start-time", "nan"), "got nan"),
    "start after end": (measure("--start-time", "9", "--end-time", "3"), "lies after --end-time"),
    "time range without a bag": (measure("--end-time", "3"), "the inputs hold no bag"),
    "image topic without a bag": (measure("--image-topic", "/left/image_raw"), "the inputs hold no bag"),
    "video step on an image": (measure("--video-step", "5"), "the inputs are images"),
    "record over a file": (["record", "-o", "cube.png"], "exists already"),
    "record under a file": (["record", "-o", "a_file/bag"], "a_file is a file"),
    "record a bad topic": (["record", "a//b", "-o", "new_bag"], "'//'"),
    "record all and topics": (["record", "--all", "image_raw", "-o", "new_bag"], "not both"),
    "play a plain file": (["play", "cube.png"], "not a rosbag2 bag"),
    # outputs checked before the work, not after it
    "vogel plot under a file": (["vogel", "runs.csv", "--plot", "a_file/plot.png"], "a_file is a file"),
    "vogel plot over its table": (["vogel", "runs.csv", "--plot", "runs.csv"], "is the input runs.csv"),
    "calibration report that is a file": (["calibrate", "cube.png", "--board", "chessboard:9x6:0.03", "-o",
                                           "fresh.yaml", "--report", "a_file"], "exists and is not a folder"),
    "demo output under a file": (["demo", "--output", "a_file/demo"], "a_file is a file"),
    "calibration demo output under a file": (["calibration-demo", "--output", "a_file/demo"], "a_file is a file"),
}


@pytest.fixture(scope="module")
def startup_s(workspace) -> float:
    """The interpreter and the imports a measurement needs, best of three: the part of each run's time that is
    not the refusal's."""
    def imports() -> float:
        env = dict(os.environ, PYTHONPATH=str(REPO))
        started = children_cpu_seconds()
        subprocess.run([sys.executable, "-c", "import veg_area_ros.cli, veg_area_ros.area, veg_area_ros.calibration"],
                       env=env, check=True, timeout=120)
        return children_cpu_seconds() - started

    return min(imports() for _ in range(3))


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_is_refused_quickly_and_clearly(workspace, startup_s, name):
    args, words = CASES[name]
    existing = workspace / "areas_existing.csv"
    existing.write_text("frame,area_m2\nyesterday,0.0105\n")
    run = run_capped([*args, "--csv", str(existing)] if args[0] == "measure" and "--csv" not in args else args,
                     workspace)
    assert run.code != 0 and "Traceback" not in run.stderr, run.stderr[-3000:]
    assert words in run.stderr, run.stderr[-3000:]
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith(f"veg-area {args[0]}: "), last  # one line that names the command and the reason
    assert run.seconds - startup_s < TIME_LIMIT_S, (run.seconds, startup_s)
    assert run.peak_rss < MEMORY_LIMIT, run.peak_rss / 2**20
    assert existing.read_text() == "frame,area_m2\nyesterday,0.0105\n"  # a user's series is never replaced
    assert not (workspace / "fresh.yaml").exists()  # nothing written before an output was found unwritable


def test_good_input_still_measures_under_the_same_watch(workspace, startup_s):
    """The control: the same command on a good frame succeeds with the true area (so the caps above are not
    met by refusing everything)."""
    run = run_capped([*measure("--json")], workspace)
    assert run.code == 0, run.stderr
    import json

    result = json.loads(run.stdout)
    assert abs(result["area_m2"] / cube_scene().true_area_m2 - 1) < 0.005
    assert run.peak_rss < MEMORY_LIMIT
