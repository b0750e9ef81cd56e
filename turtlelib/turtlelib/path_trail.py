"""A decimated trail of poses for a nav_msgs/Path display.

Poses arrive at the wheel-encoder rate (hundreds per second) but a path only needs a new point once
the robot has moved: a pose is kept when it is at least ``min_step_m`` (m) from the last kept one or
has turned by at least ``min_turn_rad`` (rad); beyond ``max_poses`` the oldest is dropped, so memory
and message size stay bounded however long the robot drives.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from functools import partial
from typing import Generic, TypeVar

from .geometry import Transform2D, normalize_angle
from .validation import integer, non_negative, store

Item = TypeVar("Item")


@dataclass(frozen=True)
class PathTrailConfig:
    """Decimation of a path: ``path_min_step_m`` (m) and ``path_min_turn_rad`` (rad) finite and >= 0,
    ``path_max_poses`` an integer >= 1 (ValueError otherwise)."""

    path_min_step_m: float = 0.02
    path_min_turn_rad: float = 0.1
    path_max_poses: int = 3000

    def __post_init__(self) -> None:
        store(self, ("path_min_step_m", "path_min_turn_rad"), non_negative)
        store(self, ("path_max_poses",), partial(integer, minimum=1))


class PathTrail(Generic[Item]):
    """The kept items (e.g. PoseStamped messages), oldest first; `offer` decides on each new pose."""

    def __init__(self, config: PathTrailConfig) -> None:
        self.config = config
        self.items: deque[Item] = deque(maxlen=config.path_max_poses)
        self._T_last_kept: Transform2D | None = None

    def offer(self, T_frame_body: Transform2D, item: Item) -> bool:
        """Keep ``item`` (the pose as displayed) if ``T_frame_body`` moved enough; True if kept.

        Kept when the trail is empty, or ``|p - p_last| >= path_min_step_m`` or
        ``|wrap(theta - theta_last)| >= path_min_turn_rad``.
        """
        T_last = self._T_last_kept
        if T_last is not None:
            step_m = math.hypot(T_frame_body.x - T_last.x, T_frame_body.y - T_last.y)
            turn_rad = abs(normalize_angle(T_frame_body.theta - T_last.theta))
            if step_m < self.config.path_min_step_m and turn_rad < self.config.path_min_turn_rad:
                return False
        self.items.append(item)
        self._T_last_kept = T_frame_body
        return True

    def clear(self) -> None:
        self.items.clear()
        self._T_last_kept = None
