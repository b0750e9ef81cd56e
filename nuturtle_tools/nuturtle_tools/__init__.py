"""Robot-side tools, without the simulator: record topics into rosbag2 bags, replay a bag into the landmarks
and slam nodes, and watch any of it live in Foxglove.

Modules: ``recorder`` (rosbag2 bag writer, MCAP storage, and the node that taps every topic), ``bag_source``
(reads MCAP and sqlite3 bags), ``player`` (the bag player node and the executor steps it paces),
``replay`` / ``replay_run`` (``python -m nuturtle_tools.replay``: a bag into landmarks and slam, then metrics
and figures), ``monitor`` (pose streams of a run), ``params`` (parameter files of in-process nodes),
``foxglove_relay`` / ``relay_config`` (topics on a Foxglove WebSocket, the ``foxglove_relay`` node),
``foxglove_layout`` (the committed Foxglove layout), ``staged_run`` (a demo or replay run into its output
folder), ``bag_recovery`` (an unfinished MCAP recording made readable). See docs/replay.md and docs/live.md.
"""
