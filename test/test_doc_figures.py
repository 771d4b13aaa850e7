"""tools/doc_figures.py, which draws the docs' pictures of the command line's outputs, runs and draws what the
docs say: the bush's Af within its std of the true area, the frames' scatter a small part of that std."""

import re
import subprocess
import sys
from pathlib import Path

import cv2

REPO = Path(__file__).resolve().parents[1]


def test_the_doc_figures_tool_draws_every_picture_and_the_bushs_area_holds(tmp_path):
    environment = {"PYTHONPATH": str(REPO / "veg_area_ros"), "HOME": str(tmp_path)}
    done = subprocess.run([sys.executable, str(REPO / "tools" / "doc_figures.py"), str(tmp_path)], capture_output=True,
                          text=True, cwd=tmp_path, env=environment, timeout=600)
    assert done.returncode == 0, done.stderr
    for name in ("calibration_residuals", "calibration_coverage", "measure_overlay", "measure_series", "vogel"):
        image = cv2.imread(str(tmp_path / f"{name}.png"))
        assert image is not None and min(image.shape[:2]) > 300, name
    lines = done.stdout.strip().splitlines()
    line = next(text for text in lines if text.startswith("the bush over"))
    numbers = re.search(r"Af (\S+) m², true (\S+) m² .* sd (\S+) m², Af's std \(median\) (\S+) m²", line)
    assert numbers, line
    mean, true, scatter, std = map(float, numbers.groups())
    assert abs(mean - true) < std  # the docs' caption: -0.08 %, within half its std
    assert scatter < 0.3 * std  # the band is Af's uncertainty, not the frames' scatter
    low, high = map(float, re.search(r"psi = \S+, 95% interval \[(\S+), (\S+)\]", done.stdout).groups())
    made_with = float(re.search(r"made with psi (\S+)", done.stdout).group(1))
    assert low < made_with < high and high - low < 0.2  # the fit finds the exponent the runs were made with
