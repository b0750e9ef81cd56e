"""nuturtle_description ROS 2 package."""
