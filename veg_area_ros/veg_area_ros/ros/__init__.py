"""The ROS 2 side: thin nodes that wire parameters, topics and services to the ROS-free core."""
