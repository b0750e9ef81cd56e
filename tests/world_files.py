"""nusim's world files read without ROS: the parameters of a world's params file as the simulator's
configuration (the parts the file sets; everything else the defaults, as nusim declares them)."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

from nusim.house import Boxes, InteriorWalls, Legs
from nusim.simulation import ArenaConfig, NoiseConfig, Obstacles, SimulationConfig, Walls
from nuturtle_ros_common.ros_files import load_ros_parameters

CONFIG = Path(__file__).resolve().parents[1] / "nusim" / "config"
ROOMS_WORLD = CONFIG / "rooms_world.yaml"
ROOMS_POSTS_WORLD = CONFIG / "rooms_posts_world.yaml"


def world_config(path: Path, seed: int = 0) -> SimulationConfig:
    """The world of the params file ``path`` with noise ``seed``."""
    values = load_ros_parameters(path)

    def part(cls, prefix=""):
        return cls(**{f.name: values[prefix + f.name] for f in fields(cls) if prefix + f.name in values})

    return SimulationConfig(
        arena=part(ArenaConfig),
        obstacles=part(Obstacles, "obstacles."),
        walls=part(Walls, "walls."),
        interior_walls=part(InteriorWalls, "interior_walls."),
        boxes=part(Boxes, "boxes."),
        legs=part(Legs, "legs."),
        noise=NoiseConfig(seed=seed),
    )
