"""A number that cannot be right never leaves with exit 0: no object in the ROI gives Af 0 with a warning (not
the background's noise counted), reversed levels, a colour index on a grey image and targets in the wrong unit
are refused with the reason."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from helpers import OPENCV_LEFT, REPO, SOURCE, run_cli

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.classify import Classifier, ClassifyError
from veg_area_ros.sim.synthetic import (
    ENDOSCOPE,
    bush_scene,
    cube_scene,
    empty_scene,
    render_scene,
    scene_targets,
    scene_targets_content,
)
from veg_area_ros.targets import TargetsError, TargetsSpec


def render(scene, light: float, seed: int) -> np.ndarray:
    return render_scene(ENDOSCOPE, scene, 0.7, noise_sigma=4, light_gradient=light, seed=seed)


# not (190, 0.3): a fixed threshold inside the background's own range of light (a 30 % gradient spans 140-205)
# takes the dark end of an empty background for an object, and the light's surface cannot be fitted around it
@pytest.mark.parametrize("light, threshold", [(0.0, "otsu"), (0.3, "otsu"), (0.0, 120), (0.3, 120), (0.0, 190)])
def test_an_empty_scene_gives_af_0_and_says_no_object(light, threshold):
    for seed in range(3):
        result = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=threshold)).measure(
            render(empty_scene(cube_scene()), light, seed))
        assert result.area_m2 == 0 and result.pixel_count == 0
        assert result.warnings[0].startswith("no object found")
        # every term of the std is the std's: 0 (the threshold's term read up to 0.05 m² beside Af 0)
        assert all(value == 0 for key, value in result.summary().items() if key.endswith("_std_m2")), \
            result.summary()
        assert not any(w.startswith(("counted whole pixels", "threshold sweep")) for w in result.warnings)


@pytest.mark.parametrize("light", [0.0, 0.3])
@pytest.mark.parametrize("threshold", ["otsu", 120])
def test_an_object_is_never_taken_for_none(light, threshold):
    for scene in (cube_scene(), bush_scene()):
        for seed in range(3):
            result = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=threshold)).measure(
                render(scene, light, seed))
            assert abs(result.area_m2 / scene.true_area_m2 - 1) < 0.01
            assert not any(w.startswith("no object found") for w in result.warnings)


def test_a_small_object_on_an_empty_scene_is_still_found():
    frame = render(empty_scene(cube_scene()), 0.0, 1)
    cv2.circle(frame, (320, 240), 6, (40, 40, 40), -1)
    result = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold="otsu")).measure(frame)
    assert result.pixel_count > 80 and not any(w.startswith("no object found") for w in result.warnings)


@pytest.mark.parametrize("object_, levels", [("dark", (230, 40)), ("bright", (40, 230)), ("green", (60, 200))])
def test_reversed_levels_are_refused(object_, levels):
    with pytest.raises(ClassifyError, match="reversed"):
        AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120, object=object_), levels=levels)


def test_the_excess_green_index_refuses_a_grey_image():
    grey = cv2.cvtColor(cv2.cvtColor(render(cube_scene(), 0.0, 0), cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)
    with pytest.raises(ClassifyError, match="has no colour"):
        Classifier(object="green").index_image(grey)
    plant = grey.copy()
    plant[200:280, 280:360] = (40, 160, 60)
    assert Classifier(object="green").index_image(plant).max() > 150


@pytest.mark.parametrize("factor, hint", [(1000.0, "millimetres given as metres"), (1e13, "millimetres"),
                                          (1e-3, "metres given as kilometres")])
def test_targets_in_the_wrong_unit_are_refused(factor, hint):
    content = scene_targets_content()
    content["markers"] = {k: [x * factor, y * factor] for k, (x, y) in content["markers"].items()}
    with pytest.raises(TargetsError, match=hint):
        TargetsSpec.from_dict(content)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plausible")
    (folder / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    cv2.imwrite(str(folder / "empty.png"), render(empty_scene(cube_scene()), 0.0, 0))
    cv2.imwrite(str(folder / "cube.png"), render(cube_scene(), 0.0, 0))
    grey = cv2.cvtColor(cv2.imread(str(folder / "cube.png")), cv2.COLOR_BGR2GRAY)
    cv2.imwrite(str(folder / "grey.jpg"), cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR))
    return folder


def measure(folder, image, *extra):
    return run_cli("measure", str(folder / image), "--calibration", "none", "--targets",
                   str(folder / "targets.yaml"), *extra, cwd=folder)


def test_the_cli_says_no_object_and_exits_1_keeping_the_row(folder):
    done = measure(folder, "empty.png", "--json", "--csv", "empty.csv")
    assert done.returncode == 1 and "no object found in the frame measured" in done.stderr, done.stderr
    row = json.loads(done.stdout)
    assert row["area_m2"] == 0 and row["warnings"][0].startswith("no object found")
    assert [r["area_m2"] for r in csv.DictReader((folder / "empty.csv").open())] == ["0.0"]
    assert measure(folder, "cube.png").returncode == 0


@pytest.mark.parametrize("extra, code, message", [
    (("--levels", "230,40"), 2, "are reversed for a dark object"),
    (("--area-mode", "count", "--levels", "40,200"), 2, "they do not apply to count mode"),
    (("--object", "green"), 1, "has no colour"),
])
def test_the_cli_refuses_what_cannot_be_right(folder, extra, code, message):
    done = measure(folder, "grey.jpg", *extra)
    assert done.returncode == code and message in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_the_cli_refuses_targets_in_millimetres(folder):
    content = scene_targets_content()
    content["markers"] = {k: [1000 * x, 1000 * y] for k, (x, y) in content["markers"].items()}
    (folder / "mm.yaml").write_text(yaml.safe_dump(content))
    done = run_cli("measure", str(folder / "cube.png"), "--calibration", "none", "--targets", str(folder / "mm.yaml"),
                   cwd=folder)
    assert done.returncode == 1 and "millimetres given as metres" in done.stderr, done.stderr


def _real_views():
    from veg_area_ros.board import BoardSpec
    from veg_area_ros.calibration import View

    board = BoardSpec.parse("chessboard:9x6:1")
    views = []
    for path in sorted((REPO / "test" / "data" / "opencv-left").glob("*.jpg")):
        detection = board.detect(cv2.imread(str(path)))
        if detection is not None:
            views.append(View(path.name, detection))
    return views


def test_one_photograph_given_many_times_is_one_view():
    from veg_area_ros.calibration import CalibrationError, View, calibrate

    views = _real_views()
    copies = [View(f"copy{k}.jpg", views[0].detection) for k in range(15)]
    with pytest.raises(CalibrationError, match=r"1 usable views.*14 more repeat a view already counted"):
        calibrate(copies, (640, 480))


def test_a_repeated_view_counts_once_and_the_fit_says_so():
    from dataclasses import replace

    from veg_area_ros.calibration import View, calibrate

    views = _real_views()
    jittered = replace(views[2].detection, image_points=views[2].detection.image_points + 0.03)  # sensor noise
    result = calibrate([*views, View("again.jpg", views[2].detection), View("still.jpg", jittered)], (640, 480),
                       cross_validate=False)
    alone = calibrate(views, (640, 480), cross_validate=False)
    assert result.views_used == len(views) == alone.views_used
    assert set(result.rejected_views) == {"again.jpg", "still.jpg"}
    assert f"the same view as {views[2].name}" in result.rejected_views["again.jpg"]
    assert any("counted once" in w and f"{len(views)} distinct views" in w for w in result.warnings)
    # the fit without them, to 1e-6: the same fit run twice differs by ~1e-9 (threaded sums), a repeated view
    # counted moves c by ~1e-4
    assert result.camera.c == pytest.approx(alone.camera.c, rel=1e-6)
    assert not any("counted once" in w for w in alone.warnings)


def test_the_views_a_fit_used_are_neither_its_rejected_nor_its_repeated_ones():
    """What the views' judgement (tone curve, edge trend, reading) is given, in calibrate and the calibration
    node alike: a view whose corners the fit does not trust and a repeat are left out, the rest kept in order."""
    from dataclasses import replace

    from veg_area_ros.calibration import View, calibrate

    views = _real_views()
    corners = views[3].detection.image_points
    shaken = corners + np.random.default_rng(0).normal(0, 8, corners.shape)  # 8 px off: no corner to trust
    offered = [*views, View("again.jpg", views[2].detection),
               View("shaken.jpg", replace(views[3].detection, image_points=shaken.astype(corners.dtype)))]
    result = calibrate(offered, (640, 480), cross_validate=False)
    assert "outliers" in result.rejected_views["shaken.jpg"] and "again.jpg" in result.rejected_views
    assert [view.name for view in result.used(offered)] == [view.name for view in views]


def test_a_fifo_and_a_dangling_symlink_are_named_for_what_they_are(folder):
    import os

    fifo = folder / "frames.fifo"
    if not fifo.exists():
        os.mkfifo(fifo)
    done = measure(folder, "frames.fifo")
    assert done.returncode == 1 and "not a regular file or folder (a pipe, socket or device)" in done.stderr
    (folder / "gone.png").unlink(missing_ok=True)
    (folder / "gone.png").symlink_to(folder / "deleted.png")
    done = measure(folder, "gone.png")
    assert done.returncode == 1 and "a symlink to" in done.stderr and "which does not exist" in done.stderr


@pytest.mark.parametrize("extra, message", [
    (("--start-time", "nan"), "--start-time must be a time in seconds, got nan"),
    (("--start-time", "10", "--end-time", "5"), "--start-time 10 s lies after --end-time 5 s"),
    (("--end-time", "5"), "pick bag frames by their header stamp; the inputs hold no bag"),
    (("--roi", "0,0,1e9,0,1e9,1e9"), "lies beyond any image"),
])
def test_options_that_cannot_select_anything_are_refused_with_the_reason(folder, extra, message):
    done = measure(folder, "cube.png", *extra)
    assert done.returncode == 2 and message in done.stderr, done.stderr


def test_a_roi_outside_an_uncalibrated_frame_is_said_so(folder):
    done = measure(folder, "cube.png", "--roi", "2000,2000,2100,2000,2100,2100")
    assert done.returncode == 1 and "lies outside the 640x480 image" in done.stderr, done.stderr
    assert "target" not in done.stderr


def test_a_spreadsheets_csv_with_a_bom_is_read(tmp_path):
    from veg_area_ros.drag import DragError, read_runs

    rows = "velocity_m_s,force_n,area_m2\r\n0.2,0.05,0.01\r\n0.4,0.16,0.009\r\n0.6,0.3,0.008\r\n"
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbf" + rows.encode())
    (tmp_path / "plain.csv").write_bytes(rows.encode())
    with_bom, plain = read_runs(tmp_path / "bom.csv"), read_runs(tmp_path / "plain.csv")
    assert np.array_equal(with_bom[0], plain[0]) and np.array_equal(with_bom[1], plain[1])
    (tmp_path / "legacy.csv").write_bytes(rows.replace("velocity", "vélocité").encode("cp1252"))
    with pytest.raises(DragError, match="not UTF-8 text"):
        read_runs(tmp_path / "legacy.csv")
    (tmp_path / "other.csv").write_bytes(rows.replace("force_n", "F").encode())
    with pytest.raises(DragError, match=r"needs columns .*; it has 'velocity_m_s', 'F', 'area_m2'"):
        read_runs(tmp_path / "other.csv")


@pytest.mark.parametrize("args, message", [
    (("demo", "--measurements", "0"), "--measurements: must be a whole number of 1 or more, got 0"),
    (("vogel", "runs.csv", "--confidence", "1.5"), "--confidence: must be between 0 and 1"),
    (("vogel", "runs.csv", "--confidence", "nan"), "--confidence: must be between 0 and 1"),
    (("vogel", "runs.csv", "--confidence", "0"), "--confidence: must be between 0 and 1"),
    (("calibrate", "photos", "--board", "chessboard:9x6:1", "-o", "c.yaml", "--fit-water-index"),
     "--fit-water-index fits the water's index from underwater views through a port"),
    (("measure", "photos", "--calibration", "none", "--targets", "t.yaml", "--scheduler", "tcp://127.0.0.1:9",
      "--overlay", "over"), "--overlay is not written by a --scheduler run"),
    (("calibrate", "--port", "flat:0.02:0.006:1.49", "--lens", "lens.yaml", "-o", "p.yaml", "--distance", "0.5"),
     "--distance does not apply with --port/--lens"),
    (("calibrate", "--port", "flat:0.02:0.006:1.49", "--lens", "lens.yaml", "-o", "p.yaml", "--medium", "air",
      "--report", "plots"), "--medium air, --report do not apply with --port/--lens"),
    (("calibrate", "photos", "--board", "chessboard:9x6:1", "-o", "c.yaml", "--water-index", "1.34"),
     "--water-index applies only with --port and --lens"),
    (("calibrate", "photos", "--board", "chessboard:9x6:1", "-o", "c.yaml", "--outlier-sigma", "3",
      "--no-outlier-rejection"), "--no-outlier-rejection rejects none: give one of them"),
    (("measure", "photos", "--calibration", "none", "--targets", "t.yaml", "--idealized", "ideal"),
     "with --calibration none there is none"),
    (("measure", "photos", "--calibration", "none", "--targets", "t.yaml", "--object", "green", "--channel",
      "red"), "channel red does not apply to object green"),
    (("measure", "photos", "--calibration", "none", "--targets", "t.yaml", "--scheduler",
      "tcp://127.0.0.1:eighty"), "the port 'eighty' is not a number from 1 to 65535"),
    (("measure", "photos", "--calibration", "none", "--targets", "t.yaml", "--scheduler",
      "http://127.0.0.1:8787/status"), "is a web address (Dask's dashboard"),
    (("measure", "photos", "--calibration", "none", "--targets", "t.yaml", "--scheduler", "tpc://127.0.0.1:8786"),
     "the scheme tpc:// is not one this command speaks"),
    (("measure", "photos", "--calibration", "none", "--targets", "t.yaml", "--scheduler", "tls://127.0.0.1:8786"),
     "tls needs certificates"),
])
def test_numbers_and_options_that_cannot_apply_are_refused(tmp_path, args, message):
    """`demo --measurements 0` printed "Af over 0 frames: nan"; a confidence of 1.5, nan or 0 fitted;
    --fit-water-index without a port's underwater views, --overlay with --scheduler, the board fit's options
    with --port and the port's options without it, --outlier-sigma with --no-outlier-rejection, --idealized
    without a calibration (no frame written) and a channel with the excess-green index were ignored without a
    word."""
    from helpers import run_cli

    (tmp_path / "photos").mkdir()
    done = run_cli(*args, cwd=tmp_path)
    assert done.returncode == 2 and message in done.stderr, done.stderr


def test_calibrate_writes_no_calibration_that_measure_would_refuse(tmp_path):
    """OpenCV's 9x6 photos calibrated as a 7x5 board wrote fy/fx 44.5 and cx -306 (exit 0; measure then
    refused the file). Either refused, nothing written, the board named as the likely cause, or (the fit's fold
    lies near the covered region's edge: which side differs between machines) a file measure reads."""
    from veg_area_ros.calib_io import read_calibration
    from veg_area_ros.camera_model import implausibility

    done = run_cli("calibrate", str(OPENCV_LEFT), "--board", "chessboard:7x5:1", "-o", str(tmp_path / "c.yaml"),
                   "-q")
    if done.returncode == 0:
        assert implausibility(read_calibration(tmp_path / "c.yaml").camera) is None
    else:
        assert done.returncode == 1 and "is the board spec the board in the images?" in done.stderr, done.stderr
        assert not (tmp_path / "c.yaml").exists()


@pytest.mark.parametrize("factor, unit", [(100.0, "centimetres"), (1 / 0.0254, "inches")])
def test_targets_in_another_unit_are_refused(factor, unit):
    """Targets written in cm or inches were read as metres: Af 105.5 m² and 16.4 m², exit 0, only a
    "measuring at about 70.72 m" warning. A calibrated camera knows its focal length: such a plane would lie
    tens of metres away. Refused with the likely cause."""
    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.classify import Classifier
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets_content
    from veg_area_ros.targets import TargetsError, TargetsSpec

    content = scene_targets_content()
    content["markers"] = {k: [v * factor for v in xy] for k, xy in content["markers"].items()}
    targets = TargetsSpec.from_dict(content)
    frame = render_scene(ENDOSCOPE, cube_scene(), 0.7)
    with pytest.raises(TargetsError, match="are the targets file's coordinates in metres"):
        AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120)).measure(frame)
    right = AreaMeasurer(ENDOSCOPE, TargetsSpec.from_dict(scene_targets_content()), Classifier(threshold=120))
    assert right.measure(frame).area_m2 == pytest.approx(cube_scene().true_area_m2, rel=0.01)


@pytest.mark.parametrize("option", ["--calibration", "--targets", "--background"])
@pytest.mark.parametrize("special", ["/dev/zero", "fifo"])
def test_a_device_or_pipe_given_as_a_file_is_refused_unread(folder, option, special):
    """/dev/zero as --calibration, --targets or --background read 3 GB and died of a MemoryError; a FIFO hung
    (Ctrl-C too). Refused unread, naming what it is."""
    import os

    path = folder / "pipe.fifo"
    if special == "fifo" and not path.exists():
        os.mkfifo(path)
    given = str(path) if special == "fifo" else special
    args = {"--calibration": ("--calibration", given, "--targets", str(folder / "targets.yaml")),
            "--targets": ("--calibration", "none", "--targets", given),
            "--background": ("--calibration", "none", "--targets", str(folder / "targets.yaml"), "--background",
                             given)}[option]
    done = run_cli("measure", str(folder / "cube.png"), *args, cwd=folder)
    kind = "a pipe (FIFO)" if special == "fifo" else "a device"
    assert done.returncode in (1, 2) and f"is {kind}, not a file" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("command", ["measure --csv", "calibrate --output", "vogel", "bag-recover"])
@pytest.mark.parametrize("special", ["/dev/null", "fifo"])
def test_a_device_or_pipe_as_an_output_or_a_table_is_refused(folder, command, special):
    """A FIFO as `--csv` hung the run (the write waits for a reader), as `vogel`'s table or the bag to recover it
    hung the reading; as root, `calibrate --output /dev/null` would have renamed its temporary file over the
    device itself. Each refused, naming what it is, and /dev/null stays a device."""
    import os
    import stat

    path = folder / "out.fifo"
    if special == "fifo" and not path.exists():
        os.mkfifo(path)
    given = str(path) if special == "fifo" else special
    if command == "measure --csv":
        args = ("measure", str(folder / "cube.png"), "--calibration", "none", "--targets",
                str(folder / "targets.yaml"), "--csv", given)
    elif command == "calibrate --output":
        args = ("calibrate", str(OPENCV_LEFT), "--board", "chessboard:9x6:0.025", "--output", given)
    else:
        args = (command, given) if command == "vogel" else (command, given, str(folder / "recovered"))
    done = run_cli(*args, cwd=folder)
    kind = "a pipe (FIFO)" if special == "fifo" else "a device"
    assert done.returncode in (1, 2) and f"is {kind}, not a file" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_an_atomic_write_never_replaces_a_device(tmp_path):
    from veg_area_ros.files import FileWriteError, write_atomic

    with pytest.raises(FileWriteError, match="is a device, not a file"):
        write_atomic("/dev/null", "rows")


def test_a_plot_is_written_whole_or_not_at_all(tmp_path):
    """A Ctrl-C while the Af(t) plot was drawn left a 124-byte PNG over the last whole one: plots are written
    through a temporary file and a rename, as the CSV is."""
    from veg_area_ros.files import save_figure

    class Interrupted:
        def savefig(self, target, **options):
            Path(target).write_bytes(b"\x89PNG half")
            raise KeyboardInterrupt

    plot = tmp_path / "run_area.png"
    plot.write_bytes(b"the last whole plot")
    with pytest.raises(KeyboardInterrupt):
        save_figure(Interrupted(), plot)
    assert plot.read_bytes() == b"the last whole plot" and sorted(tmp_path.iterdir()) == [plot]


def test_a_closed_stdout_ends_calibrate_quietly(tmp_path):
    """`veg-area calibrate ... --json | head -c 10` ended in a BrokenPipeError traceback."""
    import subprocess
    import sys

    from helpers import OPENCV_LEFT

    command = (f"{sys.executable} -m veg_area_ros.cli calibrate {OPENCV_LEFT} --board chessboard:9x6:1 -o "
               f"{tmp_path / 'c.yaml'} --json -q | head -c 10")
    done = subprocess.run(["bash", "-o", "pipefail", "-c", command], capture_output=True, text=True, timeout=300,
                          env={**__import__("os").environ, "PYTHONPATH": str(SOURCE)})
    assert done.returncode == 0 and done.stdout == '{"distorti' and done.stderr == "", done.stderr


def test_a_reader_gone_before_the_last_bytes_is_handled_inside_the_command(tmp_path, monkeypatch):
    """What the pipe test above races on, made sure: the --json line (8.4 kB, over the 8 kB buffer) leaves its
    tail in the buffer; flushed at exit, after `head` has gone, it was an "Exception ignored ... BrokenPipeError"
    with exit 120 (CI saw it). The command flushes before it returns, where a closed pipe is handled: exit 0."""
    import io

    from helpers import OPENCV_LEFT

    from veg_area_ros.cli import main

    class GoneAfterOneWrite(io.RawIOBase):
        writes, gone_after = 0, 1

        def writable(self) -> bool:
            return True

        def write(self, data) -> int:
            self.writes += 1
            if self.writes > self.gone_after:
                raise BrokenPipeError(32, "Broken pipe")
            return len(data)

    raw = GoneAfterOneWrite()
    monkeypatch.setattr("sys.stdout", io.TextIOWrapper(io.BufferedWriter(raw, 8192), encoding="utf-8"))
    code = main(["calibrate", str(OPENCV_LEFT), "--board", "chessboard:9x6:1", "-o", str(tmp_path / "c.yaml"),
                 "--json", "-q"])
    assert code == 0 and raw.writes == 2  # the second write, the buffer's tail, failed inside main
    raw.gone_after = 10**9  # the stream's own close, when the test lets it go, writes what is left


def test_a_video_whose_name_is_not_utf8_is_measured(tmp_path):
    """A video named with the byte 0xff killed `measure` with a segmentation fault (OpenCV's VideoCapture on the
    name), no message. Measured: OpenCV is given a plain-named link, the rows carry the name with U+FFFD, and
    the CSV and plot are named after the file's own bytes."""
    import os

    from veg_area_ros.calib_io import write_calibration
    from veg_area_ros.sim.synthetic import ENDOSCOPE

    frame = render(cube_scene(), 0.0, 0)
    writer = cv2.VideoWriter(str(tmp_path / "plain.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10, (640, 480))
    for _ in range(3):
        writer.write(frame)
    writer.release()
    odd = os.fsdecode(b"run\xff.avi")
    (tmp_path / "plain.avi").rename(tmp_path / odd)
    write_calibration(tmp_path / "cal.yaml", ENDOSCOPE)
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    import subprocess
    import sys


    done = subprocess.run([sys.executable, "-m", "veg_area_ros.cli", "measure", odd, "--calibration", "cal.yaml",
                           "--targets", "targets.yaml", "--threshold", "120"], cwd=tmp_path, capture_output=True,
                          env={**os.environ, "PYTHONPATH": str(SOURCE)}, timeout=300)
    assert done.returncode == 0, done.stderr
    assert b"time series: run\xff_area.csv" in done.stderr  # the name's own bytes, as ls shows them
    rows = list(csv.DictReader((tmp_path / os.fsdecode(b"run\xff_area.csv")).open(encoding="utf-8")))
    assert [row["frame"] for row in rows] == ["run\ufffd.avi#0", "run\ufffd.avi#1", "run\ufffd.avi#2"]
    assert (tmp_path / os.fsdecode(b"run\xff_area.png")).stat().st_size > 1000
    # in a batch, whose summary names each input (a traceback after the work before), and on a terminal whose
    # encoding has no '±' or 'm²' (an ASCII locale: a traceback at the first result line before)
    cv2.imwrite(str(tmp_path / "still.png"), frame)
    for environment in ({}, {"LC_ALL": "C", "PYTHONUTF8": "0"}):
        done = subprocess.run([sys.executable, "-m", "veg_area_ros.cli", "measure", odd, "still.png",
                               "--calibration", "cal.yaml", "--targets", "targets.yaml", "--threshold", "120",
                               "--output-dir", "batch"], cwd=tmp_path, capture_output=True, timeout=300,
                              env={**os.environ, "PYTHONPATH": str(SOURCE), **environment})
        assert done.returncode == 0 and b"Traceback" not in done.stderr, done.stderr
        summary = list(csv.DictReader((tmp_path / "batch" / "batch_summary.csv").open(encoding="utf-8")))
        assert [row["input"] for row in summary] == ["run\ufffd.avi", "still.png"], summary
        assert b"still.png: Af = " in done.stdout


@pytest.mark.parametrize("points, said", [
    ([[[-50, 10], [0, 0]], [[600, 12], [0.4, 0]], [[610, 450], [0.4, 0.3]], [[20, 440], [0, 0.3]]],
     r"point 0 at \(-50, 10\) px lies outside the 640x480 frame"),
    ([[[100, 100], [0, 0]], [[300, 200], [0.2, 0.1]], [[500, 300], [0.4, 0.2]]], "lie on one line"),
])
def test_hand_picked_points_off_the_image_or_on_one_line_are_refused(points, said):
    """Points outside the image measured -76 %; three on one line gave 10.8 m², exit 0. Refused."""
    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.classify import Classifier
    from veg_area_ros.targets import TargetsError, TargetsSpec

    targets = TargetsSpec.from_dict({"points": [{"pixel": p, "plane": q} for p, q in points]})
    with pytest.raises(TargetsError, match=said):
        AreaMeasurer(None, targets, Classifier(threshold=120)).measure(render(cube_scene(), 0.0, 0))


def test_the_frame_itself_as_its_background_is_refused(folder):
    """`--background` naming the frame being measured evened the object away: -90 %, no warning. Refused."""
    done = measure(folder, "cube.png", "--background", str(folder / "cube.png"))
    assert done.returncode == 1 and "the --background image is this very frame" in done.stderr, done.stderr
    assert measure(folder, "cube.png", "--background", str(folder / "empty.png")).returncode == 0


@pytest.mark.parametrize("options, said", [
    (("--levels", "0,255"), "the sub-pixel shares make Af"),
    (("--threshold", "250"), "the object fills"),
    (("--object", "bright", "--threshold", "120"), "object surrounds the rest"),  # the dark cube's background
])
def test_levels_or_a_threshold_that_take_the_background_are_said(folder, options, said):
    """`--levels 0,255` measured +241 % and `--threshold 250` +1190 %, exit 0 without a word. Said in the result;
    the right settings stay silent."""
    done = measure(folder, "cube.png", "--json", *options)
    row = json.loads(done.stdout.splitlines()[0])
    assert any(w.startswith(said) for w in row["warnings"]), row["warnings"]
    fine = json.loads(measure(folder, "cube.png", "--json", "--threshold", "120").stdout.splitlines()[0])
    assert not any(w.startswith(("the sub-pixel shares", "the object fills", "object surrounds")) for w in
                   fine["warnings"])


def test_a_plant_crossing_the_roi_is_not_taken_for_the_background():
    """A bush cut by a ROI drawn across it touches the ROI's border and is said to be cut there; it does not
    surround the rest, so it is not called the background."""
    from veg_area_ros.settings import MeasurementSettings
    from veg_area_ros.sources import SyntheticSource, default_targets

    source = SyntheticSource(scene="bush")
    across = [250.0, 200.0, 400.0, 200.0, 400.0, 300.0, 250.0, 300.0]
    result = MeasurementSettings(roi=across).measurer(source.camera, default_targets()).measure(source.read())
    assert any(w.startswith("object touches the ROI's border") for w in result.warnings), result.warnings
    assert not any(w.startswith("object surrounds") for w in result.warnings), result.warnings


def test_a_ctrl_c_while_the_command_starts_is_one_line():
    """A Ctrl-C while `veg-area` loads its imports ended in a KeyboardInterrupt traceback."""
    import contextlib
    import os
    import signal
    import subprocess
    import sys
    import time


    process = subprocess.Popen([sys.executable, "-c", "import sys; from veg_area_ros.launcher import main; "
                                "sys.exit(main())", "measure", "--help"], env={**os.environ, "PYTHONPATH": str(SOURCE)},
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    maps = Path(f"/proc/{process.pid}/maps")
    deadline = time.monotonic() + 60
    while process.poll() is None and time.monotonic() < deadline:  # numpy's library loaded: inside main's imports
        with contextlib.suppress(OSError):
            if "numpy" in maps.read_text():
                break
        time.sleep(0.002)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert "Traceback" not in stderr, stderr
    assert process.returncode in (130, 0), (process.returncode, stderr)  # 0: --help was done before the Ctrl-C
    if process.returncode == 130:
        assert stderr == "veg-area: interrupted\n", stderr


def test_the_default_csv_is_checked_before_any_work(tmp_path):
    """Run where nothing can be written (here /proc; a read-only folder alike), a video's default CSV
    (<video>_area.csv in the current folder) failed with a traceback after every frame was measured; the docs
    say outputs are checked first. Refused before any work."""
    from helpers import run_cli

    from veg_area_ros.calib_io import write_calibration
    from veg_area_ros.sim.synthetic import ENDOSCOPE

    writer = cv2.VideoWriter(str(tmp_path / "clip.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10, (640, 480))
    for _ in range(3):
        writer.write(render(cube_scene(), 0.0, 0))
    writer.release()
    write_calibration(tmp_path / "cal.yaml", ENDOSCOPE)
    (tmp_path / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    done = run_cli("measure", str(tmp_path / "clip.avi"), "--calibration", str(tmp_path / "cal.yaml"), "--targets",
                   str(tmp_path / "targets.yaml"), "--threshold", "120", cwd=Path("/proc"))
    assert done.returncode == 2 and "--csv clip_area.csv: cannot be written" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and "[1/" not in done.stdout


@pytest.mark.parametrize("options, said", [
    (("--csv", "a" * 300 + ".csv"), "has a name of 304 bytes, more than a file system allows (255)"),
    (("--csv", "/".join(["d" * 200] * 22) + "/x.csv"), "longer than the system allows"),
    (("--csv", "loop1"), "is a symlink loop"),
    (("--csv", "res", "--overlay", "res"), "name the same path: a file and a folder cannot be one"),
])
def test_outputs_that_cannot_be_written_are_said_before_the_work(folder, options, said):
    """A 300-character name, a 4.4 k path, a symlink loop as --csv and `--csv res --overlay res` all ended in
    tracebacks after the work. Refused before it, in one line."""
    loop = folder / "loop1"
    if not loop.is_symlink():
        loop.symlink_to(folder / "loop2")
        (folder / "loop2").symlink_to(loop)
    done = measure(folder, "cube.png", *options)
    assert done.returncode == 2 and said in done.stderr and "Traceback" not in done.stderr, done.stderr


@pytest.mark.parametrize("roi, holds", [
    (None, ""),  # the default ROI cuts the marker squares out
    ([190.0, 140.0, 450.0, 140.0, 450.0, 340.0, 190.0, 340.0], ""),  # between the targets
    ([31.6, 23.8, 319.8, 23.8, 319.8, 455.7, 31.6, 455.7], "0, 3"),  # over the left markers
])
def test_a_roi_over_a_marker_is_said(roi, holds):
    """A ROI drawn over a marker (in the console, or --roi) counts its dark print as object: said in the result."""
    from veg_area_ros.settings import MeasurementSettings
    from veg_area_ros.sources import SyntheticSource, default_targets

    source = SyntheticSource(scene="cube")
    result = MeasurementSettings(roi=roi).measurer(source.camera, default_targets()).measure(source.read())
    said = [w for w in result.warnings if w.startswith("the ROI holds marker")]
    assert said == ([f"the ROI holds marker(s) {holds}: their dark print is classified like the object and counted "
                     "in Af (draw the ROI between the targets, or use the default ROI, which cuts the markers out)"]
                    if holds else [])


def test_an_object_with_many_edge_pixels_is_not_taken_for_none():
    """A chessboard of 14-16 px squares, blurred by 1.2 px, its blacks crushed at 0: a third of its white
    pixels are mixed, and they widened the background's spread to 74 DN, so its peaks 207 DN apart read as
    "one class" and Af as 0. The histogram falls to a twentieth of its peaks between them: two classes, and
    the board's black area inside its rectangle is measured within 0.5 %."""
    from veg_area_ros.board import BoardSpec
    from veg_area_ros.sim.synthetic import board_views, render_board_views
    from veg_area_ros.tone_evidence import board_case

    board = BoardSpec.parse("chessboard:9x6:0.02")
    poses = board_views(ENDOSCOPE, board, 4, 0.7, np.random.default_rng(5), max_tilt_deg=25)
    measured = 0
    for image in render_board_views(ENDOSCOPE, board, poses, noise_sigma=2.0, rng=np.random.default_rng(1),
                                    blur_sigma_px=1.2):
        detection = board.detect(image)
        case = None if detection is None else board_case("view", detection, board, ENDOSCOPE)
        if case is None:
            continue
        assert case.square_px < 17
        result = AreaMeasurer(ENDOSCOPE, case.targets, Classifier(threshold="otsu"), roi=case.roi).measure(image)
        assert not any(w.startswith("no object found") for w in result.warnings), result.warnings
        assert abs(result.area_m2 / case.true_area_m2(board, case.first_black(image)) - 1) < 0.005
        measured += 1
    assert measured >= 2
