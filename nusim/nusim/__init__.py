"""nusim ROS 2 package."""
