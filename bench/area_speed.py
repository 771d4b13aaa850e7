"""Per-frame cost of the area node's core (track the targets, classify, Af with its uncertainty and the
threshold sweep, from precomputed raw-pixel weights) at 640x480 and 3872x2592, beside a plain memory copy
and a naive undistort-then-threshold of the same frame, the paper's idealize-then-count path, and the least
any histogram classification costs (one masked 1-D histogram of the ROI's grey band), measured in one run.
The frames are a steady camera's: the same scene with fresh sensor noise each frame. Prints ms per frame
and ratios, and the share of a 30 fps frame interval.

    .venv/bin/python bench/area_speed.py [--repeats N] [--video-frames N] [--dslr-video-frames N] [--video-runs N]
        [--skip-cores]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import itertools
import os
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "veg_area_ros"))

from timing import median_seconds  # bench/ is the script's folder, first on sys.path

from veg_area_ros.area import AreaMeasurer
from veg_area_ros.classify import Classifier
from veg_area_ros.sim.synthetic import (
    DSLR,
    ENDOSCOPE,
    FlatPort,
    cube_scene,
    render_scene,
    scene_targets,
)
from veg_area_ros.targets import TargetsSpec


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--video-frames", type=int, default=600, help="frames of the video case (0: skip)")
    parser.add_argument("--dslr-video-frames", type=int, default=90,
                        help="frames of the 3872x2592 video case (0: skip)")
    parser.add_argument("--skip-cores", action="store_true", help="only the video cases")
    parser.add_argument("--video-runs", type=int, default=5,
                        help="times the video case is measured (its ratio moves by a third run to run here)")
    parser.add_argument("--fitted-calibration", action="store_true",
                        help="the video cases' calibration file carries what `veg-area calibrate` records for "
                             "measuring: an edge trend (each frame then finds its object's boundary) and the "
                             "parameters' covariance (carried to Af once per target layout)")
    args = parser.parse_args()
    targets = scene_targets()
    for camera in () if args.skip_cores else (ENDOSCOPE, DSLR):
        frames = [render_scene(camera, cube_scene(), 0.7, FlatPort(), seed=seed,
                               supersample=1 if camera is DSLR else 3) for seed in range(4)]
        frame = frames[0]
        measurer = AreaMeasurer(camera, targets, Classifier(threshold=120), area_mode="count")
        measurer.measure(frame)  # pixel geometry and weights built once, as in the node
        subpixel = AreaMeasurer(camera, targets, Classifier(threshold=120), area_mode="subpixel")
        subpixel.measure(frame)
        weights = measurer.carried.weights.weights
        band = cv2.cvtColor(frame[weights.window], cv2.COLOR_BGR2GRAY)
        stream = itertools.cycle(frames)

        def naive(frame=frame, camera=camera) -> None:
            ideal = cv2.undistort(frame, camera.camera_matrix, camera.dist)
            cv2.threshold(cv2.cvtColor(ideal, cv2.COLOR_BGR2GRAY), 120, 255, cv2.THRESH_BINARY_INV)

        repeats = args.repeats if camera is ENDOSCOPE else max(3, args.repeats // 5)
        copy_ms = 1000 * median_seconds(lambda frame=frame: frame.copy(), repeats)
        histogram_ms = 1000 * median_seconds(
            lambda band=band, roi=weights.roi: cv2.calcHist([band], [0], roi, [256], [0, 256]), repeats)
        naive_ms = 1000 * median_seconds(naive, repeats)
        core_ms = 1000 * median_seconds(lambda m=measurer, s=stream: m.measure(next(s)), repeats)
        subpixel_ms = 1000 * median_seconds(lambda m=subpixel, s=stream: m.measure(next(s)), repeats)
        paper_ms = 1000 * median_seconds(lambda m=measurer, f=frame: m.measure_idealized(f), max(3, repeats // 3))
        width, height = camera.image_size
        print(f"{width}x{height} bgr8, median of {repeats}")
        print(f"  memory copy                         {copy_ms:9.3f} ms")
        print(f"  one histogram of the ROI (floor)    {histogram_ms:9.3f} ms  ({histogram_ms / copy_ms:6.1f}x copy)")
        print(f"  naive undistort + threshold         {naive_ms:9.3f} ms  ({naive_ms / copy_ms:6.1f}x copy)")
        print(f"  idealize-then-count (paper's path)  {paper_ms:9.3f} ms  ({paper_ms / copy_ms:6.1f}x copy)")
        print(f"  area core, count (Af + uncertainty) {core_ms:9.3f} ms  ({core_ms / copy_ms:6.1f}x copy, "
              f"{core_ms / naive_ms:.2f}x naive, {core_ms / (1000 / 30):.0%} of a 30 fps frame interval)")
        print(f"  area core, sub-pixel                {subpixel_ms:9.3f} ms  ({subpixel_ms / copy_ms:6.1f}x copy, "
              f"{subpixel_ms / core_ms:.2f}x count)")
        print(f"  weights built {measurer.rebuilds} and {subpixel.rebuilds} time(s) for {repeats + 1} frames each")
        noisy_cores(camera, targets, repeats)
        if camera is ENDOSCOPE:
            light_cases(targets, repeats)
    if args.video_frames:
        video_case(targets, args.video_frames, max(1, args.video_runs), fitted=args.fitted_calibration)
    if args.dslr_video_frames:  # a DSLR's video: decoding is most of the work (goal: at most twice it)
        video_case(targets, args.dslr_video_frames, max(1, args.video_runs), DSLR, 1.0, goal=2.0,
                   fitted=args.fitted_calibration)
    return 0


def noisy(clean: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    if sigma == 0:
        return clean
    grey_noise = rng.normal(0.0, sigma, clean.shape[:2]).astype(np.float32)[..., None]
    return np.clip(np.rint(clean + grey_noise), 0, 255).astype(np.uint8)


def noisy_cores(camera, targets: TargetsSpec, repeats: int) -> None:
    """The default (sub-pixel) core on a steady camera's frames with fresh sensor noise of 0, 2 and 4 DN each
    frame: its cost against the noise-free one, and how often the pixel weights were rebuilt."""
    clean = render_scene(camera, cube_scene(), 0.7, FlatPort(), noise_sigma=0.0,
                         supersample=1 if camera is DSLR else 3)
    rng = np.random.default_rng(0)
    base = None
    for sigma in (0.0, 2.0, 4.0):
        frames = [noisy(clean, sigma, rng) for _ in range(8)]
        measurer = AreaMeasurer(camera, targets, Classifier(threshold=120))
        measurer.measure(frames[0])
        stream = itertools.cycle(frames)
        core_ms = 1000 * median_seconds(lambda m=measurer, s=stream: m.measure(next(s)), repeats)
        base = base or core_ms
        print(f"  noise {sigma:g} DN: sub-pixel core {core_ms:8.3f} ms ({core_ms / base:.2f}x noise-free), weights "
              f"rebuilt {measurer.rebuilds - 1} of {repeats + 1} frames")


def light_cases(targets: TargetsSpec, repeats: int) -> None:
    """The sub-pixel core with the light evened (flat field fitted, levels from the classes' interiors, both
    carried on a steady camera) against the same core without (`even_light=False`, the sub-pixel core before
    light was evened), on even frames and on the flume's (30 % gradient, vignetting, 4 DN, 1 px blur), each
    with fresh noise per frame, measured in this run."""
    for name, degrade in (("even light, 4 DN", dict(noise_sigma=4.0)),
                          ("flume light", dict(noise_sigma=4.0, blur_sigma_px=1.0, light_gradient=0.3))):
        frames = [render_scene(ENDOSCOPE, cube_scene(), 0.7, FlatPort(), seed=seed, **degrade) for seed in range(8)]
        cost = {}
        for even in (False, True):
            measurer = AreaMeasurer(ENDOSCOPE, targets, Classifier(threshold=120), even_light=even)
            measurer.measure(frames[0])
            stream = itertools.cycle(frames)
            cost[even] = 1000 * median_seconds(lambda m=measurer, s=stream: m.measure(next(s)), repeats)
        print(f"  {name}: sub-pixel, light evened {cost[True]:8.3f} ms ({cost[True] / cost[False]:.2f}x the "
              f"sub-pixel core without evening, {cost[False]:.3f} ms)")


def fitted_metadata(camera) -> dict:
    """What a calibration file from `veg-area calibrate` gives measuring beyond the camera: an edge trend learned
    (as the webcam's, its white range wide enough for any frame) and the parameters' covariance (stds of the
    webcam's calibration, no correlations)."""
    from veg_area_ros.edge_trend import EdgeTrend
    from veg_area_ros.sim.synthetic import webcam_like_covariance

    trend = EdgeTrend(-0.0023, 0.0003, 128.0, (0.0, 255.0), 7, 0.013, "linear")
    return {"edge_trend": trend.as_dict(), "camera_covariance": webcam_like_covariance(camera)}


def video_case(targets: TargetsSpec, count: int, runs: int = 1, camera=ENDOSCOPE, distance_m: float = 0.7,
               goal: float = 3.0, fitted: bool = False) -> None:
    """`veg-area measure` of an MJPG video of the cube (in air, 3 DN of fresh sensor noise per frame, the true
    camera's calibration) beside decoding the same video with OpenCV, `runs` times (each a median of three; the
    command in this process, its imports done), the spread of the ratio over the runs, and the peak memory of
    the command run as its own process."""
    from veg_area_ros.calib_io import write_calibration
    from veg_area_ros.cli import main as veg_area

    clean = render_scene(camera, cube_scene(), distance_m, noise_sigma=0.0, supersample=1 if camera is DSLR else 3)
    width, height = camera.image_size
    rng = np.random.default_rng(3)
    with tempfile.TemporaryDirectory(prefix="veg_area_video_bench_") as folder:
        video = Path(folder) / "noisy.avi"
        writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30, camera.image_size)
        for _ in range(count):
            writer.write(noisy(clean, 3.0, rng))
        writer.release()
        metadata = {"medium": "air", **(fitted_metadata(camera) if fitted else {})}
        write_calibration(Path(folder) / "camera.yaml", camera, "camera", metadata)
        (Path(folder) / "targets.yaml").write_text(yaml.safe_dump(
            {"dictionary": targets.dictionary, "markers": {k: v.tolist() for k, v in targets.markers.items()}}))
        command = ["measure", str(video), "--calibration", str(Path(folder) / "camera.yaml"), "--targets",
                   str(Path(folder) / "targets.yaml"), "--threshold", "120", "-q", "--csv",
                   str(Path(folder) / "areas.csv")]

        def decode() -> None:
            capture = cv2.VideoCapture(str(video))
            while capture.read()[0]:
                pass
            capture.release()

        def measure() -> None:
            with contextlib.redirect_stdout(io.StringIO()):
                code = veg_area(command)
            assert code == 0

        def loop(overlapped: bool) -> None:  # the measurement over the video, decoding (and grey) overlapped or not
            from veg_area_ros.frames import decode_with_grey, decoded, iter_frames

            measurer = AreaMeasurer(camera, targets, Classifier(threshold=120), calibration_conditions=metadata)
            frames = iter_frames([video], encoded=True)
            for frame in decoded(frames) if overlapped else map(decode_with_grey, frames):
                measurer.measure(frame.image, grey=frame.grey)

        ratios = []
        for run in range(1, runs + 1):
            decode_s = median_seconds(decode, 3)
            measure_s = median_seconds(measure, 3)
            sequential_s = median_seconds(lambda: loop(False), 3)
            overlapped_s = median_seconds(lambda: loop(True), 3)
            ratios.append(measure_s / decode_s)
            print(f"veg-area measure of a {count}-frame {width}x{height} video with 3 DN noise"
                  f"{', the calibration with an edge trend and covariance' if fitted else ''} (run {run} of {runs}): "
                  f"{measure_s:.2f} s ({1000 * measure_s / count:.1f} ms a frame), decoding it alone {decode_s:.2f} s "
                  f"({measure_s / decode_s:.2f}x)")
            print(f"  decode + measure in one loop {sequential_s:.2f} s ({sequential_s / decode_s:.2f}x decoding); "
                  f"decoding overlapped {overlapped_s:.2f} s ({overlapped_s / decode_s:.2f}x decoding, "
                  f"{overlapped_s / sequential_s:.2f}x the plain loop)")
        print(f"the {width}x{height} video's ratio to its decoding over {runs} run(s): min {min(ratios):.2f}x, median "
              f"{float(np.median(ratios)):.2f}x, max {max(ratios):.2f}x; at most {goal:g}x in "
              f"{sum(r <= goal for r in ratios)} of {runs}")
        import subprocess

        # started by a small helper process: a child forked from this one (its frames cached) would count this
        # process's memory as its own peak
        helper = ("import os, subprocess, sys; child = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL); "
                  "_, status, usage = os.wait4(child.pid, 0); "
                  "print(usage.ru_maxrss // 1024, os.waitstatus_to_exitcode(status))")
        repository = Path(__file__).resolve().parents[1]
        done = subprocess.run([sys.executable, "-c", helper, sys.executable, "-m", "veg_area_ros.cli", *command],
                              capture_output=True, text=True, cwd=str(repository),
                              env={**os.environ, "PYTHONPATH": str(repository / "veg_area_ros")})
        peak_mb, code = done.stdout.split()
        print(f"  peak memory of the command as its own process: {peak_mb} MB (exit {code})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
