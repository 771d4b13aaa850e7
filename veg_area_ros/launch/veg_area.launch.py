"""Camera, calibration and area nodes together on a real ROS 2 install (needs launch_ros), and with
`console:=true` the operator's console (http://127.0.0.1:8080; `console_host:=0.0.0.0` opens it to the lab
network, controls only with the token it prints):

    ros2 launch veg_area_ros veg_area.launch.py console:=true
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, LogInfo, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from veg_area_ros.transport import choose_transport


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory("veg_area_ros")
    config = os.path.join(share, "config")
    # the nodes' own rule (VEG_AREA_TRANSPORT, a user's FASTDDS_DEFAULT_PROFILES_FILE kept), said once
    transport = choose_transport(dict(os.environ))
    chosen = [LogInfo(msg=f"veg_area_ros transport: {transport.description}")]
    if transport.profile and "FASTDDS_DEFAULT_PROFILES_FILE" not in os.environ:
        chosen.append(SetEnvironmentVariable("FASTDDS_DEFAULT_PROFILES_FILE", transport.profile))
    return LaunchDescription([
        DeclareLaunchArgument("console", default_value="false", description="Start the operator's web console."),
        DeclareLaunchArgument("console_host", default_value="127.0.0.1",
                              description="Address the console is served on (beyond loopback: token needed)."),
        DeclareLaunchArgument("console_port", default_value="8080", description="The console's TCP port."),
        *chosen,
        Node(package="veg_area_ros", executable="camera_node", name="camera_node",
             parameters=[os.path.join(config, "camera_node.yaml")]),
        Node(package="veg_area_ros", executable="calibration_node", name="calibration_node",
             parameters=[os.path.join(config, "calibration_node.yaml")]),
        Node(package="veg_area_ros", executable="area_node", name="area_node",
             parameters=[os.path.join(config, "area_node.yaml")]),
        Node(package="veg_area_ros", executable="console_node", name="console_node", output="screen",
             condition=IfCondition(LaunchConfiguration("console")),
             parameters=[{"host": ParameterValue(LaunchConfiguration("console_host"), value_type=str),
                          "port": ParameterValue(LaunchConfiguration("console_port"), value_type=int)}]),
    ])
