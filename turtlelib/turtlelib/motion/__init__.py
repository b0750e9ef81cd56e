"""Motion: differential-drive kinematics and odometry, the motion models the filter takes with their noise,
how stamped samples become model inputs, and the plausibility gate of a stream of samples."""
