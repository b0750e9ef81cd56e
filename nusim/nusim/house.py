"""Rooms for nusim: interior walls, furniture, and furniture on legs placed at random per seed. No ROS.

Beside the arena's walls and its cylinders (the landmarks, :mod:`nusim.simulation`), a world may hold
(frame ``nusim/world``, m, rad):

* interior walls: segments ``(interior_walls.x0[k], interior_walls.y0[k]) -> (interior_walls.x1[k],
  interior_walls.y1[k])`` without thickness (the LiDAR sees both faces, the robot keeps its collision
  radius from either); a doorway is the gap between two of them;
* boxes: solid rectangles (a sofa, shelves, a cabinet): centre ``(boxes.x[b], boxes.y[b])``, side
  ``boxes.length[b]`` along the heading ``boxes.yaw[b]`` and ``boxes.width[b]`` across it; the LiDAR sees
  its four sides and the robot cannot enter it;
* furniture on legs (a chair, a table: the LiDAR, 0.17 m above the floor, sees the legs under the top):
  piece ``k`` stands on four legs of radius ``legs.r[k]`` at ``(+-length/2, +-width/2)`` in its own frame
  (``legs.length[k]``, ``legs.width[k]``: between the legs' centres). Its centre is drawn uniformly in
  ``[legs.x_min[k], legs.x_max[k]] x [legs.y_min[k], legs.y_max[k]]`` and its heading in
  ``[legs.yaw_min[k], legs.yaw_max[k]]``, again until its four legs are clear of the walls, the boxes, the
  cylinders, the legs placed before and the robot's start disc (at most ``PLACEMENT_DRAWS`` draws; a range
  of zero width fixes that coordinate). The pieces are placed in order from one seeded generator, so a
  seed gives one placement and another seed, most likely, another.

Legs are not landmarks: the fake landmark sensor reports the cylinders alone.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from turtlelib.sensing.scan_model import polygon_walls
from turtlelib.util.validation import finite_real, positive

from .free_space import first_collision, inside_polygon, wall_distances

# Draws of one piece of furniture on legs before its placement is given up
PLACEMENT_DRAWS = 200


def store_lists(
    config: object, prefix: str, fields: Sequence[tuple[str, Callable[[str, object], float]]]
) -> None:
    """Each of ``config``'s list ``fields`` (name, check) as a tuple of checked floats; ValueError naming
    the parameter ``<prefix><name>`` (and the entry) otherwise."""
    for name, check in fields:
        values = getattr(config, name)
        if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
            raise ValueError(f"{prefix}{name} must be a list of numbers, got {values!r}")
        object.__setattr__(
            config, name, tuple(check(f"{prefix}{name}[{k}]", v) for k, v in enumerate(values))
        )


def store_table(
    config: object, prefix: str, fields: Sequence[tuple[str, Callable[[str, object], float]]]
) -> None:
    """:func:`store_lists`, the lists being the columns of one table: ValueError unless they have one
    length."""
    store_lists(config, prefix, fields)
    lengths = [len(getattr(config, name)) for name, _ in fields]
    if len(set(lengths)) > 1:
        names = ", ".join(f"{prefix}{name}" for name, _ in fields)
        raise ValueError(f"{names} must have the same length, got {', '.join(map(str, lengths))}")


@dataclass(frozen=True)
class InteriorWalls:
    """Interior wall ``k`` from ``(x0[k], y0[k])`` to ``(x1[k], y1[k])`` (m, finite, of non-zero length).

    ROS parameters ``interior_walls.x0``, ``interior_walls.y0``, ``interior_walls.x1``,
    ``interior_walls.y1``; empty (the default): none.
    """

    x0: tuple[float, ...] = ()
    y0: tuple[float, ...] = ()
    x1: tuple[float, ...] = ()
    y1: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        store_table(self, "interior_walls.", [(name, finite_real) for name in ("x0", "y0", "x1", "y1")])
        for k, (x0, y0, x1, y1) in enumerate(self.segments()):
            if x0 == x1 and y0 == y1:
                raise ValueError(f"interior wall {k} at ({x0}, {y0}) m has zero length")

    def segments(self) -> NDArray[np.float64]:
        """Rows ``[x0, y0, x1, y1]`` (m), shape (K, 4)."""
        return np.array([self.x0, self.y0, self.x1, self.y1], dtype=np.float64).T.reshape(-1, 4)


@dataclass(frozen=True)
class Boxes:
    """Box ``b``: centre ``(x[b], y[b])`` (m, finite), ``length[b]`` along its heading ``yaw[b]`` (rad,
    finite) and ``width[b]`` across it (m, > 0).

    ROS parameters ``boxes.x``, ``boxes.y``, ``boxes.length``, ``boxes.width``, ``boxes.yaw``; empty (the
    default): none.
    """

    x: tuple[float, ...] = ()
    y: tuple[float, ...] = ()
    length: tuple[float, ...] = ()
    width: tuple[float, ...] = ()
    yaw: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        store_table(
            self,
            "boxes.",
            (("x", finite_real), ("y", finite_real), ("length", positive), ("width", positive),
             ("yaw", finite_real)),
        )  # fmt: skip

    def corners(self) -> NDArray[np.float64]:
        """Each box's corners counter-clockwise, shape (B, 4, 2) (m): ``c + Rot(yaw) (+-length/2,
        +-width/2)``."""
        return _rectangles(
            np.column_stack([self.x, self.y]).reshape(-1, 2),
            np.asarray(self.length),
            np.asarray(self.width),
            np.asarray(self.yaw),
        )


def _rectangles(
    centres: NDArray[np.float64], length: NDArray[np.float64], width: NDArray[np.float64], yaw: NDArray
) -> NDArray[np.float64]:
    """The corners (N, 4, 2) of rectangles centred at ``centres`` (N, 2), counter-clockwise from
    ``(-length/2, -width/2)`` in each one's frame turned by ``yaw`` (N,)."""
    unit = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    local = unit[None, :, :] * np.stack([length, width], axis=-1)[:, None, :]
    c, s = np.cos(yaw), np.sin(yaw)
    # p = c + Rot(yaw) q
    x = c[:, None] * local[..., 0] - s[:, None] * local[..., 1]
    y = s[:, None] * local[..., 0] + c[:, None] * local[..., 1]
    return np.stack([x, y], axis=-1) + centres[:, None, :]


@dataclass(frozen=True)
class Legs:
    """Piece ``k`` of furniture on legs (module docstring): the area of its centre ``[x_min[k],
    x_max[k]] x [y_min[k], y_max[k]]`` (m, finite, min <= max), the range of its heading ``[yaw_min[k],
    yaw_max[k]]`` (rad, finite, min <= max), its legs' spacing ``length[k]`` along its heading and
    ``width[k]`` across (m, centre to centre, more than ``2 r[k]``) and their radius ``r[k]`` (m, > 0).

    ROS parameters ``legs.x_min``, ``legs.x_max``, ``legs.y_min``, ``legs.y_max``, ``legs.yaw_min``,
    ``legs.yaw_max``, ``legs.length``, ``legs.width``, ``legs.r``; empty (the default): none.
    """

    x_min: tuple[float, ...] = ()
    x_max: tuple[float, ...] = ()
    y_min: tuple[float, ...] = ()
    y_max: tuple[float, ...] = ()
    yaw_min: tuple[float, ...] = ()
    yaw_max: tuple[float, ...] = ()
    length: tuple[float, ...] = ()
    width: tuple[float, ...] = ()
    r: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        bounds = ("x_min", "x_max", "y_min", "y_max", "yaw_min", "yaw_max")
        store_table(self, "legs.", [(name, finite_real) for name in bounds] + [
            ("length", positive), ("width", positive), ("r", positive)
        ])  # fmt: skip
        for low, high in (("x_min", "x_max"), ("y_min", "y_max"), ("yaw_min", "yaw_max")):
            for k, (a, b) in enumerate(zip(getattr(self, low), getattr(self, high), strict=True)):
                if a > b:
                    raise ValueError(f"legs.{low}[{k}] ({a}) must not exceed legs.{high}[{k}] ({b})")
        for k, (length, width, r) in enumerate(zip(self.length, self.width, self.r, strict=True)):
            if min(length, width) <= 2.0 * r:
                raise ValueError(
                    f"the legs of piece {k} overlap: legs.length[{k}] ({length}) and legs.width[{k}] "
                    f"({width}) must exceed twice legs.r[{k}] ({r})"
                )

    @property
    def pieces(self) -> int:
        return len(self.r)

    def draw(self, k: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """Piece ``k``'s four legs at a pose drawn from ``rng`` (three uniform numbers: x, y, heading),
        rows ``[x, y, r]`` (m), shape (4, 3)."""
        centre = np.array(
            [[rng.uniform(self.x_min[k], self.x_max[k]), rng.uniform(self.y_min[k], self.y_max[k])]]
        )
        yaw = rng.uniform(self.yaw_min[k], self.yaw_max[k])
        corners = _rectangles(centre, np.array([self.length[k]]), np.array([self.width[k]]), np.array([yaw]))
        return np.column_stack([corners[0], np.full(4, self.r[k])])

    def describe(self, k: int) -> str:
        return (
            f"piece {k} on legs (centre in [{self.x_min[k]}, {self.x_max[k]}] x [{self.y_min[k]}, "
            f"{self.y_max[k]}] m)"
        )


@dataclass(frozen=True)
class WorldGeometry:
    """Everything solid in the world (nusim/world, m): ``outer`` (N, 4) the arena's closed polygon of walls,
    ``interior`` (K, 4) the interior wall segments, ``boxes`` (B, 4, 2) the boxes' corners
    (counter-clockwise), ``landmarks`` (M, 3) the cylinders ``[x, y, r]`` (the landmarks, index = id) and
    ``legs`` (L, 3) the placed legs ``[x, y, r]``."""

    outer: NDArray[np.float64]
    interior: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 4)))
    boxes: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 4, 2)))
    landmarks: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    legs: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def box_walls(self) -> NDArray[np.float64]:
        """The boxes' sides (4 B, 4), rows ``[x0, y0, x1, y1]``, four per box in order."""
        return np.concatenate([self.boxes, np.roll(self.boxes, -1, axis=1)], axis=2).reshape(-1, 4)

    @property
    def segments(self) -> NDArray[np.float64]:
        """Every wall the LiDAR sees and the robot meets (K, 4): the arena's, the interior ones, the boxes'
        sides."""
        return np.vstack([self.outer, self.interior, self.box_walls])

    @property
    def circles(self) -> NDArray[np.float64]:
        """Every cylinder the LiDAR sees and the robot meets (M + L, 3): the landmarks, then the legs."""
        return np.vstack([self.landmarks, self.legs])

    def first_collision(self, p_world: NDArray[np.float64], radius_m: float) -> str | None:
        """Why a disc of ``radius_m`` centred at ``p_world`` is not free in this world, or None: outside
        the arena or touching its walls or a landmark (:func:`nusim.free_space.first_collision`), inside a
        box, nearer than ``radius_m`` to an interior wall or a box's side, overlapping a leg."""
        reason = first_collision(p_world, self.landmarks, self.outer, radius_m)
        if reason is not None:
            return reason
        for b, corners in enumerate(self.boxes):
            if inside_polygon(p_world, polygon_walls(corners)):
                return f"is inside box {b} at {_point(corners.mean(axis=0))} m"
        for name, walls in (("interior wall", self.interior), ("a side of box", self.box_walls)):
            if walls.shape[0]:
                distances = wall_distances(p_world, walls)
                k = int(np.argmin(distances))
                if distances[k] < radius_m:
                    index = k if name == "interior wall" else k // 4
                    return (
                        f"is {distances[k]:.3f} m from {name} {index} ({walls[k, 0]}, {walls[k, 1]}) -> "
                        f"({walls[k, 2]}, {walls[k, 3]})"
                    )
        # |p - c_l| < R + r_l
        overlapping = np.hypot(*(p_world - self.legs[:, :2]).T) < radius_m + self.legs[:, 2]
        if np.any(overlapping):
            leg = int(np.argmax(overlapping))
            return f"overlaps leg {leg} at {_point(self.legs[leg, :2])} m"
        return None

    def with_legs(
        self, legs: Legs, rng: np.random.Generator, starts_xy: NDArray[np.float64], robot_radius_m: float
    ) -> WorldGeometry:
        """This world with ``legs``' pieces placed in order, each drawn from ``rng`` until its four legs are
        free here (among the legs placed before) and clear of every robot's start disc (``starts_xy``
        (n, 2), ``robot_radius_m``); ValueError naming the piece when PLACEMENT_DRAWS draws leave none
        free."""
        world = self
        starts_xy = np.asarray(starts_xy, dtype=np.float64).reshape(-1, 2)
        for k in range(legs.pieces):
            for _ in range(PLACEMENT_DRAWS):
                candidate = legs.draw(k, rng)
                # |leg - start| >= R + r for every start, and each leg a free disc
                gaps_m = np.linalg.norm(candidate[:, None, :2] - starts_xy[None], axis=-1)
                clear_of_robot = gaps_m >= robot_radius_m + candidate[:, 2:3]
                if np.all(clear_of_robot) and all(
                    world.first_collision(leg[:2], leg[2]) is None for leg in candidate
                ):
                    break
            else:
                raise ValueError(
                    f"{legs.describe(k)}: no placement of its legs in {PLACEMENT_DRAWS} draws is clear of "
                    "the walls, boxes, cylinders, other legs and the robots' starts"
                )
            world = replace(world, legs=np.vstack([world.legs, candidate]))
        return world


def _point(p: NDArray[np.float64]) -> str:
    return f"({p[0]:.3f}, {p[1]:.3f})"
