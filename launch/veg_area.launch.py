"""Camera, calibration and area nodes together on a real ROS 2 install (needs launch_ros):

    ros2 launch veg_area_ros veg_area.launch.py
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import LogInfo, SetEnvironmentVariable
from launch_ros.actions import Node

from launch import LaunchDescription
from veg_area_ros.transport import choose_transport


def generate_launch_description():
    share = get_package_share_directory("veg_area_ros")
    config = os.path.join(share, "config")
    # the nodes' own rule (VEG_AREA_TRANSPORT, a user's FASTDDS_DEFAULT_PROFILES_FILE kept), said once
    transport = choose_transport(dict(os.environ))
    chosen = [LogInfo(msg=f"veg_area_ros transport: {transport.description}")]
    if transport.profile and "FASTDDS_DEFAULT_PROFILES_FILE" not in os.environ:
        chosen.append(SetEnvironmentVariable("FASTDDS_DEFAULT_PROFILES_FILE", transport.profile))
    return LaunchDescription([
        *chosen,
        Node(package="veg_area_ros", executable="camera_node", name="camera_node",
             parameters=[os.path.join(config, "camera_node.yaml")]),
        Node(package="veg_area_ros", executable="calibration_node", name="calibration_node",
             parameters=[os.path.join(config, "calibration_node.yaml")]),
        Node(package="veg_area_ros", executable="area_node", name="area_node",
             parameters=[os.path.join(config, "area_node.yaml")]),
    ])
