"""The measurement gives what it gave when the golden set was written (test/data/golden_area.json, made by
test/golden_area.py): every field of every frame's result over the paper-table scenes, flume scenes, frame
sequences (noise, a bump, a change of light, a hidden marker), the real photos, a flat port and each option,
with the cameras stored beside them. A change that moves any of it must say why and rewrite the set."""

from __future__ import annotations

import json
import math

import pytest
from golden_area import GOLDEN, measure_all


def _differences(found, kept, path: str = "") -> list[str]:
    """Where two JSON values differ: exactly for strings, integers, booleans and keys; floats to 1e-9
    relative (another machine's floating-point sums may differ in the last digits)."""
    if isinstance(kept, dict) and isinstance(found, dict):
        if set(found) != set(kept):
            return [f"{path}: keys {sorted(set(found) ^ set(kept))} differ"]
        return [d for key in kept for d in _differences(found[key], kept[key], f"{path}.{key}")]
    if isinstance(kept, list) and isinstance(found, list):
        if len(found) != len(kept):
            return [f"{path}: {len(found)} items, golden {len(kept)}"]
        return [d for k, (a, b) in enumerate(zip(found, kept, strict=True)) for d in _differences(a, b, f"{path}[{k}]")]
    if isinstance(kept, float) and isinstance(found, float | int) and not isinstance(found, bool):
        close = (math.isnan(kept) and math.isnan(found)) or math.isclose(found, kept, rel_tol=1e-9, abs_tol=1e-15)
        return [] if close else [f"{path}: {found!r}, golden {kept!r}"]
    return [] if found == kept and type(found) is type(kept) else [f"{path}: {found!r}, golden {kept!r}"]


@pytest.fixture(scope="module")
def golden_and_found():
    golden = json.loads(GOLDEN.read_text())
    return golden, measure_all(cameras=golden["cameras"])


def test_every_case_of_the_golden_set_is_measured(golden_and_found):
    golden, found = golden_and_found
    assert set(found) == set(golden)
    assert sum(len(rows) for name, rows in golden.items() if name != "cameras") > 150


def test_every_result_is_the_golden_ones(golden_and_found):
    """Bit for bit on the machine that wrote the set; where a row's floats differ in the last digits (another
    CPU's sums), its images' digests cannot be held to and are left out of that row's comparison."""
    golden, found = golden_and_found
    problems = []
    for name, rows in golden.items():
        if name == "cameras":
            continue
        for k, (row, kept) in enumerate(zip(found[name], rows, strict=True)):
            if row == kept:
                continue
            if "images" in kept:
                row, kept = {**row, "images": None}, {**kept, "images": None}
            problems += [f"{name} row {k}{where}" for where in _differences(row, kept)]
    assert not problems, "\n".join(problems[:40])


def test_the_golden_set_shows_a_change(golden_and_found):
    """The comparison can fail: a result moved by one part in 1e8 is reported."""
    golden, found = golden_and_found
    row = dict(found["flume 0"][0])
    row["area_m2"] *= 1 + 1e-8
    assert _differences(row, golden["flume 0"][0]) == [f".area_m2: {row['area_m2']!r}, golden "
                                                       f"{golden['flume 0'][0]['area_m2']!r}"]
