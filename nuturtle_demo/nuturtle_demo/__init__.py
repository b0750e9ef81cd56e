"""The one-command simulation + SLAM demo: headless run of every node, metrics, figures, MCAP recording.

Modules: ``cli`` (command line), ``run`` (the run), ``driver`` (figure-eight route node), ``monitor``
(pose streams), ``metrics`` (pure accuracy/consistency metrics), ``recorder`` (rosbag2-layout MCAP),
``plots`` (figures, matplotlib imported lazily), ``params`` (parameter files). See docs/demo.md.
"""
