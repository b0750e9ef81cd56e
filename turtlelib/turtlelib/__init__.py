"""turtlelib: pure numpy SE(2) geometry, diff-drive kinematics, LiDAR landmark detection and EKF SLAM.

No ROS import, ever: the ROS nodes in nusim, nuturtle_control and nuslam are thin wrappers over this.
"""
