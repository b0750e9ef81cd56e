"""nuturtle_ros_common: the rclpy glue the suite's nodes share.

Message conversions, markers, config dataclass <-> ROS parameters, the node entry point, optional TF,
wheel joints, throttled warnings, package share files, the DDS world of a run.
"""
