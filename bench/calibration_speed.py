"""Time to calibrate 15 and 50 views of 640x480 with veg_area_ros's bundle adjustment, beside
cv2.calibrateCamera on the very same detections; and a whole `veg-area calibrate` of --large-views rendered
photos at 1440x1080 (read, detect, calibrate with its uncertainty and cross-validation, write) beside
OpenCV's usual script on the same files (read, findChessboardCorners, cornerSubPix 11x11, calibrateCamera),
measured in one run. Prints ratios, not claims.

    .venv/bin/python bench/calibration_speed.py [--repeats N] [--large-views N] [--real FOLDER|VIDEO BOARD]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "veg_area_ros"))

from timing import median_seconds  # bench/ is the script's folder, first on sys.path

from veg_area_ros.board import BoardSpec
from veg_area_ros.calibration import View, calibrate
from veg_area_ros.camera_model import BrownCamera
from veg_area_ros.cli import main as veg_area
from veg_area_ros.cli.calibrate import collect_views
from veg_area_ros.sim.synthetic import ENDOSCOPE, board_views, render_board_views

# a 1440x1080 camera of the dome-port class, milder distortion than the endoscope
LARGE = BrownCamera(1440, 1080, c=1150.0, xp=722.0, yp=538.0, aspect=1.0, k1=-0.2, k2=0.08, k3=-0.01,
                    p1=0.0008, p2=-0.0005)


def opencv_script(files: list[Path], board: BoardSpec) -> tuple[float, int]:
    """What a user's OpenCV script does with the photos; returns its RMS and the views it found the board in."""
    columns, rows = board.cols, board.rows
    obj = np.zeros((columns * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:columns, 0:rows].T.reshape(-1, 2) * board.square
    objects, pixels, size = [], [], None
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.001)
    for path in files:
        grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        size = grey.shape[::-1]
        found, corners = cv2.findChessboardCorners(grey, (columns, rows), None)
        if found:
            objects.append(obj)
            pixels.append(cv2.cornerSubPix(grey, corners, (11, 11), (-1, -1), criteria))
    return cv2.calibrateCamera(objects, pixels, size, None, None)[0], len(objects)


def whole_command_case(label: str, files: list[Path], board: BoardSpec, repeats: int) -> None:
    """`veg-area calibrate` of the photos against OpenCV's script on them, in one run; and our fit's RMS against
    cv2.calibrateCamera's on our own detections (the same fit asked of both)."""
    with tempfile.TemporaryDirectory(prefix="veg_area_calib_out_") as output:
        command = ["calibrate", *map(str, files), "--board", str(board), "--medium", "air", "-q", "--force",
                   "-o", str(Path(output) / "calib.yaml"), "--json"]

        def ours() -> None:
            with contextlib.redirect_stdout(io.StringIO()):  # its result table: printed once below
                assert veg_area(command) == 0

        opencv = median_seconds(lambda: opencv_script(files, board), repeats)
        whole = median_seconds(ours, repeats)
        with contextlib.redirect_stdout(io.StringIO()) as printed:
            veg_area(command)
        summary = json.loads(printed.getvalue())
    script_rms, script_views = opencv_script(files, board)
    ours_rms, same_points_rms = rms_on_the_same_points(files, board)
    print(f"{len(files):5d} {label}, whole command: opencv script {opencv:.3f} s, veg-area calibrate "
          f"{whole:.3f} s ({whole / opencv:.2f}x); every fit converged: {summary['converged']}, views used "
          f"{summary['views_used']} (the script's {script_views}); RMS of the command's "
          f"{summary['distortion_model']} {summary['rms_px']:.4f} px; plumb_bob on the very points our fit kept: "
          f"ours {ours_rms:.4f} px, calibrateCamera's {same_points_rms:.4f} px (difference "
          f"{abs(ours_rms - same_points_rms):.4f}); the script's {script_rms:.4f} px on its own detections")


def rms_on_the_same_points(files: list[Path], board: BoardSpec) -> tuple[float, float]:
    """Our fit's RMS, and cv2.calibrateCamera's on exactly the points our fit kept (every view used, the
    points it rejected as outliers left out): the same least-squares problem asked of both."""
    found = collect_views(files, board, 1, lambda _line: None)
    result = calibrate(found.views, found.image_size)
    by_name = {view.name: view.detection for view in found.views}
    objects, pixels = [], []
    for report, points, inliers in zip(result.views, result.image_points, result.inliers, strict=True):
        objects.append(by_name[report.name].object_points[inliers].astype(np.float32))
        pixels.append(points[inliers].astype(np.float32))
    return result.rms_px, cv2.calibrateCamera(objects, pixels, found.image_size, None, None)[0]


def large_case(count: int, repeats: int) -> None:
    board = BoardSpec.parse("chessboard:8x6:0.04")
    rng = np.random.default_rng(1)
    print(f"rendering {count} synthetic 1440x1080 board photos (sensor noise 2 DN) ...", file=sys.stderr)
    poses = board_views(LARGE, board, count, 0.8, rng)
    images = render_board_views(LARGE, board, poses, rng=rng, noise_sigma=2.0, supersample=1)
    with tempfile.TemporaryDirectory(prefix="veg_area_calib_bench_") as folder:
        files = []
        for k, image in enumerate(images):
            files.append(Path(folder) / f"view{k:03d}.png")
            cv2.imwrite(str(files[-1]), image)
        whole_command_case("rendered views 1440x1080", files, board, repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--large-views", type=int, default=110, help="photos of the 1440x1080 case (0: skip)")
    parser.add_argument("--real", nargs=2, action="append", default=[], metavar=("FOLDER", "BOARD"),
                        help="also a folder of real photos of a chessboard BOARD (e.g. chessboard:8x6:0.03), or a "
                             "video, whose every frame is then written as a JPEG photo")
    args = parser.parse_args()
    board = BoardSpec.parse("chessboard:9x6:0.03")
    rng = np.random.default_rng(0)
    print("rendering 50 synthetic 640x480 board views ...", file=sys.stderr)
    poses = board_views(ENDOSCOPE, board, 50, 0.6, rng)
    images = render_board_views(ENDOSCOPE, board, poses, rng=rng)
    views = [View(f"v{i}", d) for i, image in enumerate(images) if (d := board.detect(image)) is not None]
    print(f"{'views':>5} {'opencv [s]':>11} {'veg_area [s]':>13} {'ratio':>7} {'rms opencv':>11} {'rms ours':>9}")
    for count in (15, 50):
        subset = views[:count]
        obj = [v.detection.object_points.astype(np.float32) for v in subset]
        img = [v.detection.image_points.astype(np.float32) for v in subset]
        opencv = median_seconds(lambda o=obj, i=img: cv2.calibrateCamera(o, i, ENDOSCOPE.image_size, None, None),
                                args.repeats)
        ours = median_seconds(lambda s=subset: calibrate(s, ENDOSCOPE.image_size), args.repeats)
        result = calibrate(subset, ENDOSCOPE.image_size)
        opencv_rms = cv2.calibrateCamera(obj, img, ENDOSCOPE.image_size, None, None)[0]  # all the views, as timed
        print(f"{len(subset):5d} {opencv:11.3f} {ours:13.3f} {ours / opencv:6.2f}x {opencv_rms:11.4f} "
              f"{result.rms_px:9.4f}")
    print("(ours includes OpenCV's initial estimate, the joint refinement, covariance and outlier checks)")
    if args.large_views:
        large_case(args.large_views, args.repeats)
    for source, board_spec in args.real:
        with tempfile.TemporaryDirectory(prefix="veg_area_calib_frames_") as scratch:
            folder = Path(source) if Path(source).is_dir() else video_as_photos(Path(source), Path(scratch))
            files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
            whole_command_case(f"real photos in {Path(source).name}", files, BoardSpec.parse(board_spec),
                               args.repeats)


def video_as_photos(video: Path, folder: Path) -> Path:
    """Every frame of a video as a JPEG (quality 95) in `folder`: the photos both commands then read."""
    capture = cv2.VideoCapture(str(video))
    count = 0
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        cv2.imwrite(str(folder / f"frame{count:05d}.jpg"), frame, [cv2.IMWRITE_JPEG_QUALITY, 95])
        count += 1
    capture.release()
    if not count:
        raise SystemExit(f"{video}: neither a folder nor a video OpenCV can read")
    return folder


if __name__ == "__main__":
    main()
