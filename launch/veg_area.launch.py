"""Camera, calibration and area nodes together on a real ROS 2 install (needs launch_ros):

    ros2 launch veg_area_ros veg_area.launch.py
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import SetEnvironmentVariable
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description():
    share = get_package_share_directory("veg_area_ros")
    config = os.path.join(share, "config")
    return LaunchDescription([
        # camera-sized images between processes: shared memory with large segments (see README)
        SetEnvironmentVariable("FASTDDS_DEFAULT_PROFILES_FILE", os.path.join(config, "fastdds_shm.xml")),
        Node(package="veg_area_ros", executable="camera_node", name="camera_node",
             parameters=[os.path.join(config, "camera_node.yaml")]),
        Node(package="veg_area_ros", executable="calibration_node", name="calibration_node",
             parameters=[os.path.join(config, "calibration_node.yaml")]),
        Node(package="veg_area_ros", executable="area_node", name="area_node",
             parameters=[os.path.join(config, "area_node.yaml")]),
    ])
