"""nuturtle_ros_common: the rclpy glue the suite's nodes share (conversions, markers, parameters, entry point, TF)."""
