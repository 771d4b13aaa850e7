"""The three nodes in one process with one executor (composed mode, the highest rate on one machine), and
the main job: synthetic camera -> calibration from board views -> Af of the cube, printed against truth."""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import yaml
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import String

from ..files import write_atomic
from ..sources import default_targets_content
from .area_node import AreaNode
from .calibration_node import CalibrationNode
from .camera_node import CameraNode
from .qos import RESULT_QOS
from .run import EXIT_FAILED, EXIT_OK, run_nodes


def run_graph(output: Path, measurements: int = 10, timeout_s: float = 300.0, rate_hz: float = 10.0,
              say: Callable[[str], None] = print) -> int:
    """Run camera -> calibration -> area (run_nodes, as graph_node) until `measurements` calibrated Af values
    are in; print them against the rendered cube's true area. 0 on success, 1 on timeout, 130 on Ctrl-C."""
    output.mkdir(parents=True, exist_ok=True)
    calibration_file = output / "graph_calibration.yaml"
    calibration_file.unlink(missing_ok=True)  # the demo calibrates from scratch every run
    results: list[dict] = []
    truth: list[float] = []
    sources = []

    def camera() -> CameraNode:
        node = CameraNode(parameter_overrides=[Parameter("rate_hz", value=rate_hz)])
        truth.append(node.source.true_area_m2)
        sources.append(node.source)
        say(f"graph: synthetic underwater endoscope -> calibration_node -> area_node (truth Af {truth[0]:.6f} m²)")
        return node

    def listener() -> Node:
        node = Node("veg_area_demo")

        def on_info(msg: String) -> None:
            summary = json.loads(msg.data)
            if summary["calibrated"]:
                results.append(summary)

        node.create_subscription(String, "projected_area/info", on_info, RESULT_QOS)
        return node

    def calibration() -> CalibrationNode:
        return CalibrationNode(parameter_overrides=[
            Parameter("camera_info_url", value=f"file://{calibration_file.resolve()}")])

    deadline = time.monotonic() + timeout_s
    code = run_nodes([camera, calibration, AreaNode, listener], args=[],
                     until=lambda: len(results) >= measurements or time.monotonic() > deadline)
    if code:
        return code
    if len(results) < measurements:
        say(f"graph: only {len(results)} calibrated measurements within {timeout_s:.0f} s")
        return EXIT_FAILED
    areas = np.array([r["area_m2"] for r in results[:measurements]])
    std = float(np.mean([r["area_std_m2"] for r in results[:measurements]]))
    error = 100 * (areas.mean() / truth[0] - 1)
    say(f"Af over {len(areas)} frames: {areas.mean():.6f} m² ± {std:.6f} (frame-to-frame sd "
        f"{areas.std():.2g}); true {truth[0]:.6f} m²; error {error:+.3f} %")
    result = {"areas_m2": areas.tolist(), "mean_area_m2": float(areas.mean()), "area_std_m2": std,
              "true_area_m2": truth[0], "error_pct": float(error), "calibration": str(calibration_file)}
    write_atomic(output / "graph_result.json", json.dumps(result, indent=1))
    frame_file, targets_file = output / "cube_frame.png", output / "targets.yaml"
    ok, png = cv2.imencode(".png", sources[0].scene_frame())
    if ok:
        write_atomic(frame_file, png.tobytes())
    write_atomic(targets_file, yaml.safe_dump(default_targets_content(), sort_keys=False, default_flow_style=None))
    say(f"calibration served and written to {calibration_file}; the figures in {output / 'graph_result.json'}; "
        f"a raw frame of the cube in {frame_file} and its targets in {targets_file}, to measure with veg-area measure")
    return EXIT_OK


def main(argv: list[str] | None = None) -> int:
    """graph_node: the three nodes composed in one process, each with its own parameters and names."""
    return run_nodes([CameraNode, CalibrationNode, AreaNode], argv if argv is not None else sys.argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
