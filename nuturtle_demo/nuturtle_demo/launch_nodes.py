"""What nusim_slam.launch.py computes (a plain function: tests call it, launch cannot run in CI).

slam's `map` starts where the robot starts (slam's x0, y0, theta0 = 0), and nusim puts the robot at its
world file's start pose, so ``T_world_map = T_world_start``: one static transform ties the simulator's
ground truth tree (`nusim/world`) to the estimators' (`map`, or a namespaced robot's map frame such as
`tb3_0/map`), and RViz shows both in one frame.
"""

from __future__ import annotations

from pathlib import Path

from nuturtle_ros_common.ros_files import load_ros_parameters

WORLD_FRAME = "nusim/world"
MAP_FRAME = "map"


def world_to_map_arguments(world_file: str | Path, map_frame: str = MAP_FRAME) -> list[str]:
    """tf2_ros static_transform_publisher's arguments for ``nusim/world -> map_frame`` = the world file's
    start pose (x0, y0 in m, theta0 in rad; 0 where the file leaves them out)."""
    values = load_ros_parameters(Path(world_file))
    x, y, yaw = (float(values.get(name, 0.0)) for name in ("x0", "y0", "theta0"))
    return [
        *("--x", repr(x), "--y", repr(y), "--yaw", repr(yaw)),
        *("--frame-id", WORLD_FRAME, "--child-frame-id", map_frame),
    ]
