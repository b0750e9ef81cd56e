"""A decimated trail of poses for a nav_msgs/Path display.

Poses arrive at the wheel-encoder rate (hundreds per second) but a path only needs a new point once
the robot has moved: a pose is kept when it is at least ``min_step_m`` (m) from the last kept one or
has turned by at least ``min_turn_rad`` (rad); beyond ``max_poses`` the oldest is dropped, so memory
and message size stay bounded however long the robot drives. A display needs the whole path again only
now and then: :meth:`PathTrail.publish_due` says when, at most once per ``path_period`` (s) of the poses'
own time and only when a pose was kept since, so a path of ``n`` poses costs ``n / path_period`` poses per
second on the wire instead of ``n`` at every new pose.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from functools import partial
from typing import Generic, TypeVar

from ..util.validation import integer, non_negative, store
from .se2 import Transform2D, normalize_angle

Item = TypeVar("Item")


@dataclass(frozen=True)
class PathTrailConfig:
    """Decimation of a path: ``path_min_step_m`` (m) and ``path_min_turn_rad`` (rad) finite and >= 0,
    ``path_max_poses`` an integer >= 1; ``path_period`` (s, finite, >= 0): the least time between two
    publications of the path (0: at every kept pose). ValueError otherwise."""

    path_min_step_m: float = 0.05
    path_min_turn_rad: float = 0.2
    path_max_poses: int = 500
    path_period: float = 1.0

    def __post_init__(self) -> None:
        store(self, ("path_min_step_m", "path_min_turn_rad", "path_period"), non_negative)
        store(self, ("path_max_poses",), partial(integer, minimum=1))


class PathTrail(Generic[Item]):
    """The kept items (e.g. PoseStamped messages), oldest first; `offer` decides on each new pose."""

    def __init__(self, config: PathTrailConfig) -> None:
        self.config = config
        self.items: deque[Item] = deque(maxlen=config.path_max_poses)
        self._T_last_kept: Transform2D | None = None
        self._period_ns = round(config.path_period * 1e9)
        self._published_ns: int | None = None
        self._unpublished = False

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
        self._unpublished = True
        return True

    def publish_due(self, stamp_ns: int) -> bool:
        """Whether to publish the trail at time ``stamp_ns`` (int ns, the poses' clock), and if so it counts
        as published then: a pose was kept since the last publication and ``path_period`` has passed since
        it (or there was none, or the time went back)."""
        last = self._published_ns
        if not self._unpublished or (last is not None and 0 <= stamp_ns - last < self._period_ns):
            return False
        self._published_ns = stamp_ns
        self._unpublished = False
        return True

    def clear(self) -> None:
        self.items.clear()
        self._T_last_kept = None
        self._published_ns = None
        self._unpublished = False
