"""nuturtle_control ROS 2 package."""
