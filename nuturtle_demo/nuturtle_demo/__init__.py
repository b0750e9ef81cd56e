"""The one-command simulation + SLAM demo: headless run of every node, metrics, figures, rosbag2 recording.

Modules: ``cli`` (command line), ``run`` (the run), ``driver`` (figure-eight route node), ``monitor``
(pose streams), ``metrics`` (pure accuracy/consistency metrics), ``recorder`` (rosbag2 bag, MCAP storage),
``plots`` (figures, matplotlib imported lazily), ``params`` (parameter files), ``datasets`` (readers of
the real MRCLAM and Victoria Park datasets, no ROS), ``foxglove_layout`` (the committed Foxglove layout).
See docs/demo.md.
"""
