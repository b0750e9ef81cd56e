"""The one-command simulation + SLAM demo: headless run of every node, metrics, figures, rosbag2 recording.

Modules: ``cli`` (command line), ``run`` (the run), ``driver`` (figure-eight route node),
``matched_noise`` (SLAM's wheel and LiDAR noise matched to the simulated ones), ``launch_nodes`` (what the
launch file computes). The recorder, monitor and Foxglove relay are nuturtle_tools', the metrics and
figures nuturtle_eval's. See docs/demo.md.
"""
