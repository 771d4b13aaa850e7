"""Draw the docs' pictures of what the command line writes, with the command line itself: a calibration's
residuals and coverage (OpenCV's real webcam photos in test/data/), a bush's mask overlay and Af time series (a
rendered bush in front of the endoscope, 3 DN of fresh noise per frame, its true area known), and the Vogel
plot of six flume runs (a table made from a known exponent, 3 % noise on the force).

    PYTHONPATH=veg_area_ros .venv/bin/python tools/doc_figures.py docs/images"""

from __future__ import annotations

import argparse
import csv
import shutil
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
import yaml

from veg_area_ros.calib_io import write_calibration
from veg_area_ros.cli import main as veg_area
from veg_area_ros.sim.synthetic import (
    ENDOSCOPE,
    bush_scene,
    render_scene,
    scene_targets_content,
    webcam_like_covariance,
)

REPOSITORY = Path(__file__).resolve().parents[1]
FRAMES = 60
NOISE_DN = 3.0


def calibration_figures(out: Path, work: Path) -> None:
    report = work / "report"
    code = veg_area(["calibrate", str(REPOSITORY / "test" / "data" / "opencv-left"), "--board", "chessboard:9x6:0.025",
                     "--medium", "air", "-o", str(work / "left.yaml"), "--report", str(report), "-q"])
    if code:
        raise SystemExit(f"calibrate failed ({code})")
    for name in ("residuals", "coverage"):
        shutil.copyfile(report / f"{name}.png", out / f"calibration_{name}.png")


def bush_figures(out: Path, work: Path) -> None:
    scene = bush_scene()
    clean = render_scene(ENDOSCOPE, scene, noise_sigma=0.0)
    rng = np.random.default_rng(5)
    video = work / "bush.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, ENDOSCOPE.image_size)
    for index in range(FRAMES):
        frame = np.clip(clean + rng.normal(0.0, NOISE_DN, clean.shape), 0, 255).astype(np.uint8)
        writer.write(frame)
        if index == 0:
            cv2.imwrite(str(work / "bush.png"), frame)
    writer.release()
    # the webcam calibration's stds: Af's std then holds the calibration's term
    write_calibration(work / "camera.yaml", ENDOSCOPE, "endoscope",
                      {"medium": "air", "camera_covariance": webcam_like_covariance(ENDOSCOPE)})
    (work / "targets.yaml").write_text(yaml.safe_dump(scene_targets_content()))
    common = ["--calibration", str(work / "camera.yaml"), "--targets", str(work / "targets.yaml"), "-q"]
    if veg_area(["measure", str(work / "bush.png"), *common, "--overlay", str(out / "measure_overlay.png")]):
        raise SystemExit("measuring the frame failed")
    if veg_area(["measure", str(video), *common, "--csv", str(work / "bush_area.csv")]):
        raise SystemExit("measuring the video failed")
    shutil.copyfile(work / "bush_area.png", out / "measure_series.png")
    with open(work / "bush_area.csv", newline="") as rows:
        table = list(csv.DictReader(rows))
    areas = np.array([float(row["area_m2"]) for row in table])
    stds = np.array([float(row["area_std_m2"]) for row in table])
    print(f"the bush over {areas.size} frames: Af {areas.mean():.6g} m², true {scene.true_area_m2:.6g} m² "
          f"({100 * (areas.mean() / scene.true_area_m2 - 1):+.3f} %); frame-to-frame sd {areas.std(ddof=1):.3g} m², "
          f"Af's std (median) {np.median(stds):.3g} m²")


VOGEL_EXPONENT = -0.7  # Cd·Af ∝ U^ψ of the made-up runs
FORCE_NOISE = 0.03


def vogel_figure(out: Path, work: Path) -> None:
    rng = np.random.default_rng(11)
    velocity = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    cd_area = 0.012 * (velocity / 0.1) ** VOGEL_EXPONENT
    force = 0.5 * 998.2 * velocity**2 * cd_area * (1 + rng.normal(0, FORCE_NOISE, velocity.size))
    area = 0.0048 * (velocity / 0.1) ** -0.35  # the bush reconfigures: its Af falls with the flow
    table = work / "runs.csv"
    with open(table, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["velocity_m_s", "force_n", "area_m2", "velocity_std_m_s", "force_std_n", "area_std_m2"])
        for u, f, a in zip(velocity, force, area, strict=True):
            writer.writerow([f"{u:.3f}", f"{f:.5f}", f"{a:.6f}", "0.005", f"{FORCE_NOISE * f:.5f}", "0.00002"])
    if veg_area(["vogel", str(table), "--plot", str(out / "vogel.png")]):
        raise SystemExit("the Vogel fit failed")
    print(f"the runs were made with psi {VOGEL_EXPONENT}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder for the PNGs (docs/images)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="veg_area_doc_figures_") as folder:
        calibration_figures(args.out, Path(folder))
        bush_figures(args.out, Path(folder))
        vogel_figure(args.out, Path(folder))
    return 0


if __name__ == "__main__":
    sys.exit(main())
