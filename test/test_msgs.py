"""veg_area_msgs: the wheels' CMake files made usable (tools/wheel_cmake.py), the message package's install
layout, ProjectedArea filled from a frame's result, and its definition as rosbags reads it equal to the
generated class's bytes."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO, installed

MESSAGES = REPO / "veg_area_msgs"


def _wheel_cmake():
    spec = importlib.util.spec_from_file_location("wheel_cmake", REPO / "tools" / "wheel_cmake.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


EXPORT = ('set_target_properties(std_msgs__rosidl_generator_py PROPERTIES\n  INTERFACE_INCLUDE_DIRECTORIES '
          '"/opt/python/cp311-cp311/include/python3.11;/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/'
          '_core/include"\n)\n')


def test_the_wheels_container_include_folders_are_pointed_at_this_machines(tmp_path):
    wheel_cmake = _wheel_cmake()
    cmake = tmp_path / "share" / "std_msgs" / "cmake"
    cmake.mkdir(parents=True)
    (cmake / "export_std_msgs__rosidl_generator_pyExport.cmake").write_text(EXPORT)
    (cmake / "std_msgsConfig.cmake").write_text("# nothing of the container here\n")
    changed = wheel_cmake.patch_prefix(tmp_path)
    assert [p.name for p in changed] == ["export_std_msgs__rosidl_generator_pyExport.cmake"]
    text = changed[0].read_text()
    python, numpy_include = wheel_cmake.local_includes()
    assert "/opt/python" not in text and f'"{python};{numpy_include}"' in text
    assert Path(python, "Python.h").is_file() and Path(numpy_include, "numpy", "arrayobject.h").is_file()
    assert wheel_cmake.patch_prefix(tmp_path) == []  # a second run changes nothing
    assert (cmake / "std_msgsConfig.cmake").read_text() == "# nothing of the container here\n"


def test_a_container_path_it_does_not_know_stops_the_build_by_name(tmp_path):
    wheel_cmake = _wheel_cmake()
    cmake = tmp_path / "share" / "odd_msgs" / "cmake"
    cmake.mkdir(parents=True)
    odd = cmake / "odd.cmake"
    odd.write_text('INTERFACE_LINK_DIRECTORIES "/opt/python/cp311-cp311/lib/libpython3.11.so"\n')
    with pytest.raises(SystemExit, match=r"odd\.cmake.*/opt/python/cp311-cp311/lib/libpython3\.11\.so"):
        wheel_cmake.patch_prefix(tmp_path)
    assert "/opt/python" in odd.read_text()  # left as it was
    done = subprocess.run([sys.executable, str(REPO / "tools" / "wheel_cmake.py")], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and "PREFIX" in done.stderr


def test_the_message_package_is_an_ament_cmake_interface_package():
    root = ET.parse(MESSAGES / "package.xml").getroot()
    assert root.get("format") == "3" and root.findtext("name") == "veg_area_msgs"
    assert root.find("export/build_type").text == "ament_cmake"
    assert root.findtext("member_of_group") == "rosidl_interface_packages"
    assert {e.text for e in root.findall("buildtool_depend")} == {"ament_cmake", "rosidl_default_generators"}
    # every message definition of the package is generated
    listed = (MESSAGES / "CMakeLists.txt").read_text()
    assert all(f"msg/{path.name}" in listed for path in (MESSAGES / "msg").glob("*.msg"))
    assert len(list((MESSAGES / "msg").glob("*.msg"))) == 3
    ours = ET.parse(REPO / "veg_area_ros" / "package.xml").getroot()
    assert "veg_area_msgs" in {e.text for e in ours.findall("exec_depend")}
    # colcon finds both: the repository root is not itself a package (it would hide the other)
    assert not (REPO / "package.xml").exists() and not (REPO / "setup.py").exists()


@pytest.fixture(scope="module")
def prefix():
    return installed("share/veg_area_msgs", "veg_area_msgs")


def test_the_message_package_is_installed_as_ros_finds_it(prefix):
    share = prefix / "share" / "veg_area_msgs"
    assert (share / "package.xml").is_file() and (share / "msg" / "ProjectedArea.msg").is_file()
    assert (share / "msg" / "ProjectedArea.idl").is_file()
    assert (share / "msg" / "ProjectedArea.msg").read_text() == (MESSAGES / "msg" / "ProjectedArea.msg").read_text()
    index = prefix / "share" / "ament_index" / "resource_index"
    assert (index / "packages" / "veg_area_msgs").is_file()
    assert "msg/ProjectedArea.msg" in (index / "rosidl_interfaces" / "veg_area_msgs").read_text()
    for kind in ("rosidl_generator_c", "rosidl_typesupport_c", "rosidl_typesupport_fastrtps_c",
                 "rosidl_typesupport_introspection_c", "rosidl_typesupport_cpp", "rosidl_generator_py"):
        assert (prefix / "lib" / f"libveg_area_msgs__{kind}.so").is_file(), kind
    # the generated class imports and serializes in a user's shell: no ROS environment, no LD_LIBRARY_PATH
    code = ("from rclpy.serialization import serialize_message, deserialize_message;"
            "from veg_area_msgs.msg import ProjectedArea;"
            "m = ProjectedArea(area_m2=0.0105, warnings=['exposure: clipped']);"
            "back = deserialize_message(serialize_message(m), ProjectedArea);"
            "print(back.area_m2, back.warnings[0])")
    done = subprocess.run([str(prefix / "bin" / "python"), "-c", code], capture_output=True, text=True, timeout=60,
                          env={"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/tmp")}, cwd="/")
    assert done.returncode == 0 and done.stdout.split() == ["0.0105", "exposure:", "clipped"], done.stderr


def test_a_frames_result_fills_every_field_and_rosbags_reads_the_bytes_alike(prefix):
    from rclpy.serialization import serialize_message

    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.bags import our_message_files, typestore
    from veg_area_ros.classify import Classifier
    from veg_area_ros.ros.messages import projected_area
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets

    frame = render_scene(ENDOSCOPE, cube_scene(), 0.5)
    frame[:40, :40] = 255  # a clipped corner far from the cube: the result must carry whatever it warns
    from veg_area_ros.camera_uncertainty import CameraCovariance

    covariance = CameraCovariance.from_std(dict.fromkeys(ENDOSCOPE.param_names, 1e-3), {})
    result = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120.0),
                          calibration_conditions={"camera_covariance": covariance.as_dict()}).measure(frame)
    assert result.calibration_std_m2 > 0
    from builtin_interfaces.msg import Time

    msg = projected_area(result, Time(sec=12, nanosec=5), "camera", "calibration_file /data/endoscope.yaml")
    assert (msg.area_m2, msg.area_std_m2, msg.pixel_count) == (result.area_m2, result.area_std_m2,
                                                              result.pixel_count)
    terms = [msg.scale_std_m2, msg.threshold_std_m2, msg.discretisation_std_m2, msg.levels_std_m2,
             msg.plane_offset_std_m2, msg.exposure_std_m2, msg.glare_std_m2, msg.edge_trend_std_m2,
             msg.calibration_std_m2]
    assert msg.area_std_m2 == pytest.approx(float(np.hypot.reduce(terms)), rel=1e-9)
    assert (msg.area_mode, msg.subpixel_applied, msg.threshold, msg.tone_curve) == (
        result.area_mode, result.subpixel_applied, result.threshold, result.tone_curve)
    assert list(msg.warnings) == result.warnings and msg.calibrated == result.calibrated
    # rosbags, with the definition registered from the installed .msg, decodes rclpy's bytes field for field
    assert our_message_files()[0].is_relative_to(prefix / "share" / "veg_area_msgs")
    decoded = typestore().deserialize_cdr(serialize_message(msg), "veg_area_msgs/msg/ProjectedArea")
    for name in msg.get_fields_and_field_types():
        if name != "header":
            assert getattr(decoded, name) == (list(getattr(msg, name)) if name == "warnings"
                                              else getattr(msg, name)), name
    assert (decoded.header.stamp.sec, decoded.header.frame_id) == (12, "camera")
    # the type hash rosbags writes into a bag's metadata is the one rosidl generated (ros2 bag info, Foxglove)
    import json

    for name in ("ProjectedArea", "CalibrationProgress", "DragCoefficient"):
        generated = json.loads((prefix / "share" / "veg_area_msgs" / "msg" / f"{name}.json").read_text())
        expected = next(h["hash_string"] for h in generated["type_hashes"]
                        if h["type_name"] == f"veg_area_msgs/msg/{name}")
        assert typestore().hash_rihs01(f"veg_area_msgs/msg/{name}") == expected, name


def test_the_frame_counts_travel_in_the_result_and_an_unknown_one_as_minus_one(prefix):
    """The area node's frame counts are fields of ProjectedArea (the console reads them there, not from the
    JSON); a count the node cannot know (skipped frames without a camera_info per frame) is -1 in the message
    and unknown (None) again on the console's page."""
    from builtin_interfaces.msg import Time

    from veg_area_ros.area import AreaMeasurer
    from veg_area_ros.classify import Classifier
    from veg_area_ros.ros.console_node import result_summary
    from veg_area_ros.ros.messages import projected_area
    from veg_area_ros.sim.synthetic import ENDOSCOPE, cube_scene, render_scene, scene_targets

    result = AreaMeasurer(ENDOSCOPE, scene_targets(), Classifier(threshold=120.0)).measure(
        render_scene(ENDOSCOPE, cube_scene(), 0.5))
    counts = {"frames_received": 12, "frames_skipped": None, "frames_lost": 0, "frames_measured": 11}
    msg = projected_area(result, Time(sec=3), "camera", "camera_info", counts)
    assert (msg.frames_received, msg.frames_skipped, msg.frames_lost, msg.frames_measured) == (12, -1, 0, 11)
    assert projected_area(result, Time(sec=3), "camera", "camera_info").frames_measured == -1  # none given
    summary = result_summary(msg)
    assert (summary["frames_received"], summary["frames_skipped"], summary["frames_lost"],
            summary["frames_measured"]) == (12, None, 0, 11)
    assert summary["warnings"] == result.warnings and summary["pixel_count"] == result.pixel_count


def test_a_bag_recorded_before_a_field_was_added_reads_with_its_own_definition(tmp_path):
    """A bag whose ProjectedArea was recorded with a definition one field shorter than today's (as a recording
    from before a field is added will be; here without `calibration_std_m2`) is read with the definition it was
    written with, which its connection carries: Af and the rest come back as written, where today's definition
    would read its bytes out of step."""
    from rosbags.rosbag2 import Reader, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from veg_area_ros.bags import our_message_files, typestore

    name = "veg_area_msgs/msg/ProjectedArea"
    today = next(p for p in our_message_files() if p.stem == "ProjectedArea").read_text()
    before = "\n".join(line for line in today.splitlines() if not line.startswith("float64 calibration_std_m2"))
    assert before != today
    old = get_typestore(Stores.ROS2_KILTED)
    old.register(get_types_from_msg(before, name))
    fields = {field: 0.0 for field in ("area_m2", "area_std_m2", "scale_std_m2", "threshold_std_m2",
                                       "discretisation_std_m2", "levels_std_m2", "plane_offset_std_m2",
                                       "exposure_std_m2", "glare_std_m2", "edge_trend_std_m2", "edge_trend_m2",
                                       "count_area_m2", "threshold")}
    fields.update(area_m2=0.0105, area_std_m2=1.5e-5, edge_trend_m2=2e-6, pixel_count=4321,
                  area_mode="subpixel", subpixel_applied=True, tone_curve="linear", calibrated=True,
                  calibration_source="camera_info", warnings=["exposure: clipped"], frames_received=9,
                  frames_skipped=-1, frames_lost=0, frames_measured=8)
    header = old.types["std_msgs/msg/Header"](stamp=old.types["builtin_interfaces/msg/Time"](sec=3, nanosec=0),
                                              frame_id="camera")
    message = old.types[name](header=header, **fields)
    with Writer(tmp_path / "old", version=Writer.VERSION_LATEST) as writer:
        connection = writer.add_connection("/projected_area", name, typestore=old)
        writer.write(connection, 3 * 10**9, old.serialize_cdr(message, name))
    with Reader(tmp_path / "old") as reader:
        (connection, _, data), = list(reader.messages())
        read = typestore(reader).deserialize_cdr(data, name)
        assert (read.area_m2, read.area_std_m2, read.edge_trend_m2, read.pixel_count, list(read.warnings)) == (
            0.0105, 1.5e-5, 2e-6, 4321, ["exposure: clipped"])
    try:  # today's definition reads these bytes out of step
        misread = typestore().deserialize_cdr(data, name)
        alike = (misread.pixel_count, list(misread.warnings)) == (4321, ["exposure: clipped"])
    except Exception:  # rosbags raises whatever the misplaced bytes make of it
        alike = False
    assert not alike


def test_calibration_progress_carries_what_the_node_says_and_gives_it_back(prefix):
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message

    from veg_area_msgs.msg import CalibrationProgress
    from veg_area_ros.bags import typestore
    from veg_area_ros.ros.messages import progress_as_dict, progress_message

    state = {"message": "view 7 kept (54 points, coverage 41 %)", "views_kept": 7, "frames_seen": 40,
             "frames_looked": 31, "frames_skipped": 9, "feedback_published": 0, "coverage": 0.41,
             "coverage_cells": 14, "fitted": False, "rms_px": None, "still_needed": "tilt the board left-right",
             "bars": {"x": 0.8, "y": 0.5, "size": 0.2, "tilt_h": 0.0, "tilt_v": 0.4, "roll": 0.1, "coverage": 0.41},
             "rejected": {"too similar to a kept view": 5, "blurred": 2}, "warnings": []}
    msg = progress_message(state, Time(sec=3), "camera")
    back = progress_as_dict(deserialize_message(serialize_message(msg), CalibrationProgress))
    assert back == state
    fitted = progress_as_dict(progress_message({**state, "fitted": True, "rms_px": 0.061,
                                                "warnings": ["k3 large"]}, Time(), "camera"))
    assert (fitted["fitted"], fitted["rms_px"], fitted["warnings"]) == (True, 0.061, ["k3 large"])
    decoded = typestore().deserialize_cdr(serialize_message(msg), "veg_area_msgs/msg/CalibrationProgress")
    assert decoded.still_needed == state["still_needed"] and list(decoded.rejected_counts) == [5, 2]
    assert (prefix / "share" / "veg_area_msgs" / "msg" / "CalibrationProgress.msg").is_file()


def test_colcon_finds_both_packages_in_a_workspace_and_builds_the_messages_first(tmp_path):
    """As on a ROS 2 install: the repository cloned into a workspace's src/, `colcon build` as usual."""
    colcon = Path(sys.executable).parent / "colcon"
    if not colcon.exists():
        pytest.skip("colcon is installed by `make install`")
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "veg_area").symlink_to(REPO)
    done = subprocess.run([str(colcon), "list", "--topological-order", "--names-only", "--base-paths", "src"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["veg_area_msgs", "veg_area_ros"], done.stdout
