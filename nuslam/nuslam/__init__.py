"""nuslam ROS 2 package."""
