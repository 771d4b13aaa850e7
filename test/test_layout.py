"""The installed package has the ament layout `ros2 run veg_area_ros <node>` resolves, and package.xml is
a proper format-3 ament_python manifest."""

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml
from helpers import SOURCE, installed

NODES = ["camera_node", "calibration_node", "area_node", "graph_node", "record_node", "drag_node", "play_node",
         "console_node"]


@pytest.fixture(scope="module")
def prefix():
    return installed("share/ament_index", "ament layout")


def test_ament_index_finds_the_package_and_its_executables(prefix):
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix))
    code = ("from ament_index_python import get_package_prefix, get_package_share_directory;"
            "print(get_package_prefix('veg_area_ros')); print(get_package_share_directory('veg_area_ros'))")
    out = subprocess.run([str(prefix / "bin" / "python"), "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=60).stdout.split()
    assert Path(out[0]).resolve() == prefix.resolve()
    assert (Path(out[1]) / "package.xml").is_file()
    for node in NODES:  # what `ros2 run veg_area_ros <node>` executes
        exe = Path(out[0]) / "lib" / "veg_area_ros" / node
        assert exe.is_file() and os.access(exe, os.X_OK), exe
    # the message package beside it (its share/, type support libraries and Python module: test_msgs.py)
    code = ("from ament_index_python import get_package_share_directory, get_resource;"
            "print(get_package_share_directory('veg_area_msgs')); print(get_resource('rosidl_interfaces', "
            "'veg_area_msgs')[0].split())")
    done = subprocess.run([str(prefix / "bin" / "python"), "-c", code], env=env, capture_output=True, text=True,
                          check=True, timeout=60).stdout.splitlines()
    assert Path(done[0]).resolve() == (prefix / "share" / "veg_area_msgs").resolve()
    assert "msg/ProjectedArea.msg" in done[1] and "msg/CalibrationProgress.msg" in done[1], done


def test_installed_command_line_runs(prefix):
    result = subprocess.run([str(prefix / "bin" / "veg-area"), "--version"], capture_output=True, text=True,
                            timeout=60, env=dict(os.environ, HOME=os.environ.get("HOME", "/tmp")))
    assert result.returncode == 0 and result.stdout.startswith("veg_area_ros "), result.stderr


def test_package_xml_is_an_ament_python_manifest():
    root = ET.parse(SOURCE / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == "veg_area_ros"
    assert root.find("export/build_type").text == "ament_python"
    depends = {e.text for e in root.findall("exec_depend")}
    assert depends >= {"rclpy", "sensor_msgs", "std_msgs", "std_srvs", "python3-opencv", "python3-numpy",
                       "python3-scipy", "python3-yaml"}
    assert (SOURCE / "resource" / "veg_area_ros").is_file()
    setup_cfg = (SOURCE / "setup.cfg").read_text()
    assert "script_dir=$base/lib/veg_area_ros" in setup_cfg and "install_scripts=$base/lib/veg_area_ros" in setup_cfg


def test_config_and_launch_are_installed_and_the_launch_file_is_valid_python(prefix):
    share = prefix / "share" / "veg_area_ros"
    for name in ("camera_node.yaml", "calibration_node.yaml", "area_node.yaml", "fastdds.xml", "fastdds_local.xml"):
        assert (share / "config" / name).is_file(), name
    launch = share / "launch" / "veg_area.launch.py"
    compile(launch.read_text(), str(launch), "exec")  # launch_ros is not installable here; it must parse
    for name in ("camera_node", "calibration_node", "area_node"):
        parameters = yaml.safe_load((share / "config" / f"{name}.yaml").read_text())
        assert list(parameters) == [name] and "ros__parameters" in parameters[name]
    ET.parse(share / "config" / "fastdds.xml")
    ET.parse(share / "config" / "fastdds_local.xml")


def test_installed_node_executable_starts_and_stops_cleanly(prefix, tmp_path):
    """What `ros2 run veg_area_ros area_node` runs: it starts, waits for frames, and exits 0 on SIGINT.
    Without any ament or Fast DDS setting (an unsourced .venv), so the node finds its own profile; kept on this
    machine by the shipped local profile (shared memory, UDP on 127.0.0.1 only), private domain. The README's
    test runs the same with the default profile, confined to a private network namespace."""
    import time

    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "RMW_", "AMENT_"))}
    env.update(HOME=str(tmp_path), ROS_DOMAIN_ID="199", VEG_AREA_TRANSPORT="local")
    process = subprocess.Popen([str(prefix / "lib" / "veg_area_ros" / "area_node")], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        started = ""  # its first log line says the transport: rclpy is up and the node is being made
        deadline = time.monotonic() + 60
        while "transport:" not in started and process.poll() is None and time.monotonic() < deadline:
            started += process.stdout.readline()
        assert "transport:" in started and process.poll() is None, started + process.stdout.read()
        assert "fastdds_local.xml (found via" in started, started
        stop_cleanly(process)
    finally:
        reap(process)


def stop_cleanly(process: subprocess.Popen) -> None:
    """Ctrl-C, and the node must end with exit code 0."""
    import signal

    process.send_signal(signal.SIGINT)
    assert process.wait(20) == 0


def reap(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.kill()
        process.wait()


def test_the_installed_console_serves_its_page_from_the_install(prefix, tmp_path):
    """`ros2 run veg_area_ros console_node`: the page's files come from the installed package (run outside the
    source tree), every file the page loads is served by the node, and it stops cleanly on SIGINT."""
    import socket
    import time
    import urllib.request

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "RMW_", "AMENT_"))}
    env.pop("PYTHONPATH", None)
    env.update(HOME=str(tmp_path), ROS_DOMAIN_ID="198", VEG_AREA_TRANSPORT="local")
    process = subprocess.Popen([str(prefix / "lib" / "veg_area_ros" / "console_node"), "--ros-args", "-p",
                                f"port:={port}"], env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    try:
        started = ""
        deadline = time.monotonic() + 60
        while "console on" not in started and process.poll() is None and time.monotonic() < deadline:
            started += process.stdout.readline()
        assert f"console on http://127.0.0.1:{port}/ (this machine only)" in started, started + process.stdout.read()
        import re

        page = urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10).read().decode()
        loaded = re.findall(r'(?:src|href)="([^"]+)"', page)
        assert sorted(loaded) == ["/console.css", "/console.js"]
        for path in loaded:
            assert urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10).status == 200
        stop_cleanly(process)
    finally:
        reap(process)
    installed = [p for p in (prefix / "lib").glob("python3*/site-packages/veg_area_ros/console_page/*")]
    assert sorted(p.name for p in installed) == ["console.css", "console.js", "index.html"]


def _package_imports(path: Path) -> set[str]:
    """The veg_area_ros modules (dotted, below the package) and the top-level packages a file imports."""
    import ast

    package = path.relative_to(SOURCE).with_suffix("").parts[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package[:len(package) - node.level + 1]
            found.add(".".join((*base, *(node.module.split(".") if node.module else ()))))
        elif isinstance(node, ast.ImportFrom):
            found.add(node.module)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return found


def _in_package(module: str, *packages: str) -> bool:
    """Whether a dotted module is one of `packages` or inside one (veg_area_ros.ros1_bag is not in .ros)."""
    return any(module == package or module.startswith(package + ".") for package in packages)


def test_imports_only_go_down_the_architecture():
    """The README's picture as a rule: the core imports neither rclpy nor the nodes nor the command line, and
    the simulator only through the camera node's sources; no node imports another but the composed graph."""
    root = SOURCE / "veg_area_ros"
    for path in root.glob("*.py"):
        if path.name == "launcher.py":  # the `veg-area` entry point above everything: it imports the command line
            assert _package_imports(path) <= {"__future__", "signal", "sys", "veg_area_ros.cli"}, path
            continue
        imports = _package_imports(path)
        assert not {i for i in imports if i.split(".")[0] == "rclpy"}, path
        assert not {i for i in imports if _in_package(i, "veg_area_ros.ros", "veg_area_ros.cli")}, path
        if path.name != "sources.py":
            assert not {i for i in imports if _in_package(i, "veg_area_ros.sim")}, path
    for path in (root / "sim").glob("*.py"):
        assert not {i for i in _package_imports(path) if _in_package(i, "veg_area_ros.ros", "veg_area_ros.cli")}
    nodes = {p.stem for p in (root / "ros").glob("*_node.py")}
    assert {"area_node", "camera_node", "calibration_node"} <= nodes
    for path in (root / "ros").glob("*.py"):
        imports = _package_imports(path)
        imported = {i.rsplit(".", 1)[-1] for i in imports if i.startswith("veg_area_ros.ros.")}
        assert not (imported & nodes) or path.stem == "graph", (path, imported & nodes)
        assert not {i for i in imports if _in_package(i, "veg_area_ros.sim")}, path  # defaults come from sources
    for path in (root / "cli").glob("*.py"):
        uses_ros = any(_in_package(i, "veg_area_ros.ros") for i in _package_imports(path))
        assert not uses_ros or path.stem in ("bags", "demos"), path


def _module_graph() -> dict[str, set[str]]:
    """Every module of the package and the package modules it imports (at the top or inside a function alike:
    a lazy import still ties the two together)."""
    import ast

    root = SOURCE / "veg_area_ros"

    def name(path: Path) -> str:
        parts = path.relative_to(SOURCE).with_suffix("").parts
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)

    modules = {name(path): path for path in root.rglob("*.py")}
    graph = {}
    for module, path in modules.items():
        package = path.relative_to(SOURCE).with_suffix("").parts[:-1]
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = ".".join(package[:len(package) - node.level + 1]) if node.level else ""
                target = ".".join(filter(None, (base, node.module or "")))
                for alias in node.names:  # `from . import area` names a module, `from .area import X` does not
                    found.add(f"{target}.{alias.name}" if f"{target}.{alias.name}" in modules else target)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names)
        graph[module] = {m for m in found if m in modules and m != module}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan): each is an import circle."""
    import sys

    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph)))

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        for other in graph[module]:
            if other not in index:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in stack:
                low[module] = min(low[module], index[other])
        if low[module] == index[module]:
            component = []
            while True:
                other = stack.pop()
                component.append(other)
                if other == module:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return circles


def test_no_module_imports_one_that_imports_it_back():
    """Imports only go down: no circle between modules, directly or around several (lazy imports count)."""
    assert _cycles(_module_graph()) == []


def test_the_circle_finder_finds_circles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e2"}, "e2": {"e"}}
    assert sorted(_cycles(graph)) == [["a", "b", "c"], ["e", "e2"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_the_ground_floor_imports_nothing_of_the_package():
    graph = _module_graph()
    assert graph["veg_area_ros.files"] == set()
    assert all("veg_area_ros.files" in graph[f"veg_area_ros.{module}"] for module in ("calib_io", "frames", "bags"))


def test_a_node_refuses_a_choice_parameter_outside_its_choices(tmp_path):
    """`-p medium:=lava` was accepted in silence (the calibration file then said medium 'lava'). A value that
    is none of a parameter's choices stops the node at start with one line naming it and the choices. Kept on
    this machine as the test above."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "RMW_", "AMENT_"))}
    env.update(HOME=str(tmp_path), ROS_DOMAIN_ID="198", VEG_AREA_TRANSPORT="local", PYTHONPATH=str(SOURCE))
    done = subprocess.run([sys.executable, "-m", "veg_area_ros.ros.calibration_node", "--ros-args", "-p",
                           "medium:=lava", "-p", f"camera_info_url:=file://{tmp_path}/c.yaml"], env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode != 0, done.stdout + done.stderr
    assert "parameter medium: 'lava' is not one of air, water" in done.stdout + done.stderr
    assert "Traceback" not in done.stdout + done.stderr


def test_a_mistyped_parameter_is_said_and_malformed_ros_args_in_one_line(tmp_path):
    """`-p rate:=30.0` (for rate_hz) was accepted in silence; `-p rate_hz` (no :=) ended in an RCLError
    traceback. The first is said with the parameter meant; the second is one line, exit 2."""
    import signal
    import time

    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "RMW_", "AMENT_"))}
    env.update(HOME=str(tmp_path), ROS_DOMAIN_ID="197", VEG_AREA_TRANSPORT="local", PYTHONPATH=str(SOURCE))
    done = subprocess.run([sys.executable, "-m", "veg_area_ros.ros.camera_node", "--ros-args", "-p", "rate_hz"],
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.strip().splitlines()[-1].startswith("veg_area_ros: ROS cannot start with these --ros-args")
    env_lab = dict(env, ROS_DOMAIN_ID="lab")
    lab = subprocess.run([sys.executable, "-m", "veg_area_ros.ros.camera_node"], env=env_lab, capture_output=True,
                         text=True, timeout=120)
    assert lab.returncode == 2 and "ROS_DOMAIN_ID is not an integral number" in lab.stderr, lab.stderr
    assert "Traceback" not in lab.stderr
    process = subprocess.Popen([sys.executable, "-m", "veg_area_ros.ros.camera_node", "--ros-args", "-p",
                                "rate:=30.0"], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        said, deadline = "", time.monotonic() + 60
        while "did you mean" not in said and process.poll() is None and time.monotonic() < deadline:
            said += process.stdout.readline()
        assert "parameter 'rate' is not one of camera_node's parameters: ignored (did you mean 'rate_hz'?)" in said
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


# the parameters each node applies when they change at run time; every other parameter is read at start only
# and must be declared read-only, so that `ros2 param set` is refused instead of accepted and ignored
APPLIED_AT_RUN_TIME = {
    "area_node": {"threshold", "threshold_mode", "object", "channel", "roi", "open_px", "close_px", "area_mode",
                  "levels", "tone_curve", "targets_file", "background_file", "preview_rate_hz", "uncalibrated_frames"},
    "camera_node": {"rate_hz"},
    "calibration_node": {"model"},
}


def test_a_parameter_a_node_does_not_apply_at_run_time_is_read_only():
    import ast

    found = {}
    for path in sorted((SOURCE / "veg_area_ros" / "ros").glob("*_node.py")):
        for call in ast.walk(ast.parse(path.read_text())):
            if isinstance(call, ast.Call) and getattr(call.func, "id", None) == "declare":
                name = call.args[1].value
                read_only = any(k.arg == "read_only" and getattr(k.value, "value", False) for k in call.keywords)
                found[(path.stem, name)] = read_only
    assert len(found) > 40 and ("drag_node", "density") in found
    wrong = [(node, name) for (node, name), read_only in found.items()
             if read_only == (name in APPLIED_AT_RUN_TIME.get(node, set()))]
    assert not wrong, f"applied at run time and read-only, or neither: {wrong}"


def test_make_test_runs_each_module_whole_on_one_worker():
    """The check below compares the host's /dev/shm while this module's nodes are the only ones that write
    there: it holds only if no other worker runs them beside it."""
    recipe = (SOURCE.parent / "Makefile").read_text().split("\ntest:", 1)[1].split("\n\n", 1)[0]
    assert "-m pytest -n auto --dist loadfile" in recipe, recipe


KILLED_NODE = """
import os, signal, time
import rclpy
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
node = Node("doomed")
publisher = node.create_publisher(String, "chatter", 10)
for _ in range(5):
    publisher.publish(String(data="x" * 100_000))  # over shared memory: Fast DDS's segment in /dev/shm
    time.sleep(0.05)
print("published", flush=True)
os.kill(os.getpid(), signal.SIGKILL)  # a node killed leaves its segment and port locks behind
"""


def test_a_killed_node_leaves_nothing_in_the_hosts_shared_memory(tmp_path):
    """Confined runs clean up after nodes that could not: a node killed mid-run leaves Fast DDS files that a
    private /dev/shm takes away with it, or that the harness removes from the host's. In this module because
    its other nodes are the suite's only ones on the host's /dev/shm: `make test` runs a module whole on one
    worker (`--dist loadfile`), so none of them runs beside this comparison."""
    import sys

    from veg_area_ros.ros.confine import run_confined, shm_files

    before = shm_files()
    done = run_confined([sys.executable, "-c", KILLED_NODE], tmp_path, timeout=60)
    assert "published" in done.stdout, done.stderr[-2000:]
    assert done.returncode != 0, done.returncode  # killed (-9; unshare reports its child's death as 1)
    assert shm_files() - before == set()
