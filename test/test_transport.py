"""The transport rule: which Fast DDS profile a process loads, found the same from an unsourced .venv, a
sourced ROS 2 install and a colcon install. No ROS here."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from helpers import REPO

from veg_area_ros.transport import buffer_warning, choose_transport, config_locations, find_config


def colcon_prefix(root: Path) -> Path:
    """An install prefix as colcon leaves it: the ament index marker and the package's config/."""
    (root / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (root / "share" / "ament_index" / "resource_index" / "packages" / "veg_area_ros").write_text("")
    (root / "share" / "veg_area_ros" / "config").mkdir(parents=True)
    for name in ("fastdds.xml", "fastdds_local.xml"):
        (root / "share" / "veg_area_ros" / "config" / name).write_text("<profiles/>")
    return root


def test_no_ament_environment_is_a_normal_state_not_an_error():
    transport = choose_transport({})
    assert transport.name == "auto" and Path(transport.profile).is_file()
    how = find_config("fastdds.xml", {})[1]
    assert how in ("this interpreter's prefix", "the source tree")
    assert f"(found via {how})" in transport.description


def test_a_sourced_ros_install_without_the_package_falls_back_to_the_interpreter_or_the_tree(tmp_path):
    ros = tmp_path / "opt" / "ros" / "kilted"
    (ros / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    environ = {"AMENT_PREFIX_PATH": str(ros)}
    path, how = find_config("fastdds.xml", environ)
    assert how != "ament index" and Path(path).is_file()


def test_a_colcon_install_on_the_ament_path_wins(tmp_path):
    install = colcon_prefix(tmp_path / "ws" / "install")
    environ = {"AMENT_PREFIX_PATH": f"/opt/ros/kilted:{install}"}
    transport = choose_transport(environ)
    assert transport.profile == str(install / "share" / "veg_area_ros" / "config" / "fastdds.xml")
    assert transport.description.endswith("(found via ament index)")
    local = choose_transport(environ | {"VEG_AREA_TRANSPORT": "local"})
    assert local.profile.endswith("install/share/veg_area_ros/config/fastdds_local.xml")


def test_the_lookup_order_is_ament_index_interpreter_prefix_source_tree(tmp_path):
    install = colcon_prefix(tmp_path / "install")
    places = config_locations("fastdds.xml", {"AMENT_PREFIX_PATH": str(install)})
    assert [how for _, how in places] == ["ament index", "this interpreter's prefix", "the source tree"]
    assert places[1][0] == Path(sys.prefix) / "share" / "veg_area_ros" / "config" / "fastdds.xml"
    assert places[2][0] == REPO / "veg_area_ros" / "config" / "fastdds.xml"


def test_found_nowhere_says_where_it_looked(monkeypatch, tmp_path):
    import veg_area_ros.transport as transport_module

    monkeypatch.setattr(transport_module, "config_locations",
                        lambda name, environ=None: [(tmp_path / "none" / name, "nowhere")])
    transport = transport_module.choose_transport({})
    assert transport.name == "default" and transport.profile is None
    assert str(tmp_path / "none" / "fastdds.xml") in transport.description


def test_a_users_profile_and_another_rmw_are_left_alone_and_a_typo_refused():
    assert choose_transport({"FASTDDS_DEFAULT_PROFILES_FILE": "/etc/mine.xml"}).name == "user profile"
    assert choose_transport({"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}).name == "another rmw"
    with pytest.raises(ValueError, match="must be one of"):
        choose_transport({"VEG_AREA_TRANSPORT": "fast"})


def test_low_socket_buffers_warn_only_for_the_profile_that_reaches_other_pcs(tmp_path):
    for key in ("rmem_max", "wmem_max"):
        (tmp_path / key).write_text("212992\n")
    assert "212992" in buffer_warning(choose_transport({}), tmp_path)
    assert buffer_warning(choose_transport({"VEG_AREA_TRANSPORT": "local"}), tmp_path) is None
