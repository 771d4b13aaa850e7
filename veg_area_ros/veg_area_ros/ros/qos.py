"""The QoS profiles of every topic the nodes publish or take, and why each is what it is."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from ..latest import REMEMBERED

# images: what camera drivers use (best effort, newest frame only); a slow consumer never queues frames
IMAGE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)
SENSOR_QOS = qos_profile_sensor_data
# camera_info from a calibration: latched, so a node that starts later still gets the calibration
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
RESULT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=50, reliability=ReliabilityPolicy.RELIABLE)
# camera_info as the area node takes it, on two subscriptions. Both deep: while a slow frame (the first builds the
# pixel weights) is measured, each frame's camera_info waits and is counted (depth 1 keeps the newest).
# Latched: gets a calibration published before the node started (calibration_node, camera_node); a volatile
# publisher cannot match it.
PER_FRAME_INFO_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=REMEMBERED,
                                reliability=LATCHED_QOS.reliability, durability=LATCHED_QOS.durability)
# Any publisher: best effort + volatile matches every offered QoS, so camera drivers that publish camera_info
# volatile with each frame (usb_cam, v4l2_camera, `ros2 bag play` of a bag without offered QoS) are heard too.
ANY_INFO_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=REMEMBERED, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)
