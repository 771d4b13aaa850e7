"""The README is a test: its commands, read from the README (never retyped here), run as a newcomer's shell
runs them, and give what the README shows.

A newcomer's shell is `env -i` with only PATH (without any virtual environment's folder), a fresh HOME and
LANG: no ROS_*, FASTDDS_*, RMW_*, AMENT_* or PYTHONPATH. Commands run from a view of the repository root (every
top-level entry linked, so `.venv` and the sources are the repository's) with an output folder of its own,
so a run leaves the checkout as it was. ROS processes are wrapped in a private network namespace with only
loopback (the wrapper adds no variable: the process itself starts under `env -i`); where none can be made the
ROS parts are skipped, because the default transport would then reach other machines.

A fenced `text` block right after a `bash` block is what its last command prints: each of its lines must be
found in the output, `…` standing for any text and each number agreeing within one unit of its last digit or
0.1 % (runs differ in the last digits of a fitted calibration).
"""

from __future__ import annotations

import json
import math
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import REPO

from veg_area_ros.cli import build_parser
from veg_area_ros.ros.confine import confined, netns_available, remove_new_shm, shm_files

README = REPO / "README.md"
DOCS = REPO / "docs"
NOT_MIRRORED = {".git", "veg_area_demo", "build", "log", "install", ".pytest_cache", ".hypothesis", ".ruff_cache"}
NEEDS_NETNS = pytest.mark.skipif(not netns_available(), reason="no private network namespace (unshare as root): "
                                 "a newcomer's ROS process would use the default transport, which reaches other "
                                 "machines")
NUMBER = r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?"


# ---- the README as data -------------------------------------------------------------------------------------

def fenced_blocks(text: str) -> list[tuple[str, list[str]]]:
    """(info string, lines) of every fenced code block, in order."""
    blocks, current, info = [], None, ""
    for line in text.splitlines():
        if line.startswith("```"):
            if current is None:
                current, info = [], line[3:].strip()
            else:
                blocks.append((info, current))
                current = None
        elif current is not None:
            current.append(line)
    return blocks


def block_commands(lines: list[str]) -> list[str]:
    """A bash block's commands: continuation lines joined, comments and blank lines dropped."""
    commands, pending = [], ""
    for line in lines:
        pending += line.rstrip()
        if pending.endswith("\\"):
            pending = pending[:-1] + " "
            continue
        command = pending.split(" #", 1)[0].strip() if not pending.lstrip().startswith("#") else ""
        if command:
            commands.append(command)
        pending = ""
    return commands


def readme_steps() -> list[tuple[list[str], list[str] | None]]:
    """Each bash block's commands with the text block shown after it (None when there is none)."""
    blocks = fenced_blocks(README.read_text())
    steps = []
    for i, (info, lines) in enumerate(blocks):
        if info == "bash":
            shown = blocks[i + 1][1] if i + 1 < len(blocks) and blocks[i + 1][0] == "text" else None
            steps.append((block_commands(lines), shown))
    return steps


def kind(command: str) -> str:
    if command in ("make demo", "make test"):
        return command
    if command.startswith(".venv/bin/veg-area "):
        return "veg-area"
    if command.startswith(".venv/lib/veg_area_ros/"):
        return "node"
    if command.startswith(("ros2 run veg_area_ros ", "ros2 launch veg_area_ros ")):
        return "ros2"
    return "unknown"


def all_commands() -> list[str]:
    return [command for commands, _ in readme_steps() for command in commands]


# ---- a newcomer's shell -------------------------------------------------------------------------------------

def newcomer_environment(home: Path) -> dict[str, str]:
    path = os.pathsep.join(p for p in os.environ.get("PATH", "/usr/bin:/bin").split(os.pathsep)
                           if p and not (Path(p) / "activate").exists())
    return {"PATH": path, "HOME": str(home), "LANG": "C.UTF-8"}


def as_newcomer(command: str, env: dict[str, str]) -> list[str]:
    """`command` split as a shell splits it, started by `env -i` with exactly `env`."""
    return ["env", "-i", *(f"{key}={value}" for key, value in env.items()), *shlex.split(command)]


@pytest.fixture(scope="module")
def checkout(tmp_path_factory) -> Path:
    """The repository root as a newcomer sees it: every entry linked, outputs (veg_area_demo/) its own."""
    root = tmp_path_factory.mktemp("checkout")
    for entry in REPO.iterdir():
        if entry.name not in NOT_MIRRORED:
            (root / entry.name).symlink_to(entry)
    if not (REPO / ".venv" / "lib" / "veg_area_ros" / "area_node").exists():
        if os.environ.get("VEG_AREA_REQUIRE_INSTALL"):
            pytest.fail(".venv has no installed package: the install step did not run")
        pytest.skip(".venv is not installed; `make test` installs it")
    return root


@pytest.fixture(scope="module")
def home(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("newcomer_home")


@pytest.fixture(scope="module")
def demo(checkout, home) -> subprocess.CompletedProcess:
    """`make demo` exactly as the README prints it, in the scrubbed shell, confined; run once."""
    if not netns_available():
        pytest.skip("no private network namespace (unshare as root): the demo's default transport would reach "
                    "other machines")
    (command,) = [c for c in all_commands() if c == "make demo"]
    before = shm_files()
    try:
        return subprocess.run(confined(as_newcomer(command, newcomer_environment(home))), cwd=checkout,
                              capture_output=True, text=True, timeout=900)
    finally:
        remove_new_shm(before)


def last_digit(number: str) -> float:
    """The value of one unit in a printed number's last digit: 0.01 for "3.14", 1e-06 for "1.5e-05"."""
    mantissa, _, exponent = number.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 10.0 ** (int(exponent or 0) - decimals)


def shows(shown: str, output: str) -> bool:
    """Whether a line the README shows is in the output (see the module's docstring)."""
    pattern = ""
    for piece in re.split(f"(…|{NUMBER})", " ".join(shown.split())):
        if piece == "…":
            pattern += ".*?"
        elif re.fullmatch(NUMBER, piece):
            pattern += f"({NUMBER})"
        else:
            pattern += re.escape(piece)
    wanted = [float(n) for n in re.findall(NUMBER, shown.replace("…", " "))]
    places = [last_digit(n) for n in re.findall(NUMBER, shown.replace("…", " "))]
    for line in output.splitlines():
        match = re.search(pattern, " ".join(line.split()))
        if not match:
            continue
        got = [float(g) for g in match.groups()]
        close = (math.isclose(g, w, rel_tol=1e-3, abs_tol=p * (1 + 1e-9))
                 for g, w, p in zip(got, wanted, places, strict=True))
        if all(close):
            return True
    return False


# ---- the tests ----------------------------------------------------------------------------------------------

def test_the_readme_is_short_and_its_set_up_is_two_commands():
    lines = README.read_text().splitlines()
    assert len(lines) <= 150, len(lines)
    first, _ = readme_steps()[0]
    assert first == ["make demo", "make test"]
    ci = [line.strip() for line in (REPO / ".ci" / "run").read_text().splitlines()
          if line.strip() and not line.startswith("#")]
    assert ci[-1] == "make test"  # CI runs the README's test command, nothing else
    assert "Status" not in {line.lstrip("# ").strip() for line in lines if line.startswith("#")}
    assert not re.search(r"issue #\d+|\(#\d+\)", README.read_text())


def test_every_readme_command_is_one_this_test_knows_how_to_run():
    unknown = [c for c in all_commands() if kind(c) == "unknown"]
    assert not unknown, f"README commands the README test cannot run: {unknown}"
    kinds = {kind(c) for c in all_commands()}
    assert {"make demo", "make test", "veg-area", "node", "ros2"} <= kinds


def test_the_shown_line_matcher_can_fail():
    assert shows("RMS 0.1812 px, max 0.5327 px", "views 13; RMS 0.1813 px, max 0.5327 px")
    assert not shows("RMS 0.1812 px, max 0.5327 px", "views 13; RMS 0.1850 px, max 0.5327 px")
    assert shows("Af = 0.01055 ± … m² (… px)", "[1/1] x: Af = 0.0105488 ± 1.5e-05 m² (10160 px)")
    assert not shows("Af = 0.01055 ± … m² (… px)", "[1/1] x: Af = 0.0112 ± 1.5e-05 m² (10160 px)")
    assert not shows("threshold 120, homography scale", "threshold 120, affine scale")
    assert not shows("± 1.5e-05 m²", "± 1.9e-05 m²") and shows("± 1.5e-05 m²", "± 1.5e-05 m²")
    assert last_digit("1.5e-05") == pytest.approx(1e-6) and last_digit("0.1812") == pytest.approx(1e-4)


def test_make_demo_as_printed_runs_in_a_newcomers_shell(demo, checkout):
    assert demo.returncode == 0, demo.stdout[-3000:] + demo.stderr[-6000:]
    output = demo.stdout + demo.stderr
    transport = [line for line in output.splitlines() if "transport:" in line]
    assert transport and "found via" in transport[0] and "Fast DDS defaults" not in transport[0], transport
    result = json.loads((checkout / "veg_area_demo" / "graph_result.json").read_text())
    assert abs(result["error_pct"]) <= 0.5, result
    (shown,) = [shown for commands, shown in readme_steps() if commands == ["make demo", "make test"]]
    for line in shown:
        assert shows(line, output), (line, output[-3000:])


def test_the_quick_start_commands_give_what_the_readme_shows(demo, checkout, home):
    assert demo.returncode == 0, "the demo writes what the quick start measures"
    steps = [(commands, shown) for commands, shown in readme_steps() if all(kind(c) == "veg-area" for c in commands)]
    assert len(steps) >= 2 and any("calibrate" in c[0] for c, _ in steps) and any("measure" in c[0] for c, _ in steps)
    for commands, shown in steps:
        for command in commands:
            done = subprocess.run(as_newcomer(command, newcomer_environment(home)), cwd=checkout,
                                  capture_output=True, text=True, timeout=600)
            assert done.returncode == 0, (command, done.stderr[-3000:])
        for line in shown or []:
            assert shows(line, done.stdout + done.stderr), (command, line, done.stdout[-3000:])


@NEEDS_NETNS
def test_the_node_commands_start_say_their_transport_and_stop_on_ctrl_c(checkout, home):
    nodes = [c for c in all_commands() if kind(c) == "node"]
    assert {shlex.split(c)[0].rsplit("/", 1)[1] for c in nodes} >= {"camera_node", "calibration_node", "area_node"}
    spec = {"commands": nodes, "env": newcomer_environment(home), "cwd": str(checkout), "timeout": 90}
    before = shm_files()
    try:  # the driver is the harness; the nodes it starts get exactly the newcomer's environment
        done = subprocess.run(confined([sys.executable, str(REPO / "test" / "readme_nodes.py"), json.dumps(spec)]),
                              capture_output=True, text=True, timeout=240)
    finally:
        remove_new_shm(before)
    lines = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    assert done.returncode == 0 and lines, done.stdout[-2000:] + done.stderr[-4000:]
    for node in json.loads(lines[-1][len("RESULT "):]):
        assert node["transport_logged"] and node["alive_before_sigint"] and node["exit"] == 0, (
            node["command"], node["exit"], node["stopped_after_s"], node["output"][-2500:])
        transport = next(line for line in node["output"].splitlines() if "transport:" in line)
        assert "found via" in transport and "Fast DDS defaults" not in transport, transport


def test_every_subcommand_answers_help_in_a_newcomers_shell(checkout, home):
    parser = build_parser()
    subcommands = next(a for a in parser._actions if a.dest == "command").choices
    assert {"calibrate", "measure", "record", "play", "vogel", "demo", "doctor"} <= set(subcommands)
    for name in [None, *subcommands]:
        args = [name, "--help"] if name else ["--help"]
        done = subprocess.run(as_newcomer(".venv/bin/veg-area " + " ".join(args), newcomer_environment(home)),
                              cwd=checkout, capture_output=True, text=True, timeout=60)
        assert done.returncode == 0 and "usage: veg-area" in done.stdout and not done.stderr, (name, done.stderr)


def test_the_ros2_commands_name_what_the_install_provides(checkout):
    prefix = REPO / ".venv"
    for command in (c for c in all_commands() if kind(c) == "ros2"):
        words = shlex.split(command)
        if words[1] == "run":
            assert (prefix / "lib" / "veg_area_ros" / words[3]).is_file(), command
        else:
            assert (prefix / "share" / "veg_area_ros" / "launch" / words[3]).is_file(), command


def markdown_links(path: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)  # code is not a link
    return re.findall(r"\[[^\]]*\]\(([^)\s]+)\)", text)


def anchors(path: Path) -> set[str]:
    """GitHub's anchors for a markdown file's headings."""
    found = set()
    for line in re.sub(r"```.*?```", "", path.read_text(), flags=re.S).splitlines():
        if line.startswith("#"):
            title = line.lstrip("#").strip().lower()
            found.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return found


def test_every_relative_link_in_the_readme_and_docs_resolves():
    pages = [README, *sorted(DOCS.glob("*.md"))]
    assert len(pages) >= 8
    checked = 0
    for page in pages:
        for link in markdown_links(page):
            if re.match(r"[a-z]+://|mailto:", link):
                continue
            target, _, anchor = link.partition("#")
            path = (page.parent / target).resolve() if target else page
            assert path.exists(), f"{page.relative_to(REPO)}: {link} does not exist"
            if anchor:
                assert anchor in anchors(path), f"{page.relative_to(REPO)}: {link}: no heading #{anchor}"
            checked += 1
    assert checked >= 10
    linked = {(README.parent / link.partition("#")[0]).resolve() for link in markdown_links(README)}
    assert {p.resolve() for p in DOCS.glob("*.md")} <= linked, "a page of docs/ the README never links"
