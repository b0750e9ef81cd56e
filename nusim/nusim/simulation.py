"""The simulated TurtleBot3 Burger in an arena of cylinders: pure Python/numpy, no ROS.

World (frame ``world``, m, rad)
-------------------------------
An arena closed by walls: the polygon with corners ``(walls.x[k], walls.y[k])`` in order (any simple
polygon, e.g. the hexagon of ROBOTIS' turtlebot3_world), or without them the rectangle
``|x| <= arena_x_length / 2``, ``|y| <= arena_y_length / 2`` (the inner faces of its walls); cylinders ``j``
at ``c_j = (obstacles.x[j], obstacles.y[j])`` of radius ``obstacles.r[j]``; and the robot, a disc of
``collision_radius`` ``R`` centred on ``base_footprint`` with true pose ``T_world_body`` (starting at
``(x0, y0, theta0)``). The robot's centre ``p`` is *free* when it is inside the polygon, ``|p - c_j| >=
R + r_j`` for every cylinder and ``dist(p, wall_k) >= R`` for every wall segment (each wall is a capsule
of radius ``R`` around its segment for the centre).

Motors (per wheel ``i`` in (left, right), per physics step of ``dt`` s)
---------------------------------------------------------------------
* command: ``u_i = clip(round(w_i * motor_cmd_per_rad_sec), -motor_cmd_max, motor_cmd_max)`` motor
  units (mcu), the wheel speed the motor holds is ``w_i' = u_i / motor_cmd_per_rad_sec`` (rad/s);
* wheel-speed noise (only on a turning wheel: a stopped motor holds still):
  ``w_i'' = w_i' + n_i``, ``n_i ~ N(0, input_noise^2)`` drawn each step;
* the encoder counts the noisy commanded rotation ``phi_i += w_i'' dt`` and reads
  ``ticks_i = round(phi_i * encoder_ticks_per_rad)``;
* slip: the wheel's contact with the floor moves ``dphi_i = traction_i w_i'' dt (1 + s_i)``,
  ``s_i ~ U(-slip_fraction, slip_fraction)``, and the body follows the exact diff-drive arc
  ``T' = T @ exp([F dphi])`` (``turtlelib.DiffDrive.step``). ``traction_i`` is 1 on a normal floor; a slip
  event (a wheel spinning on a slick patch, or lifted) is ``traction_i`` 0 for a while: the encoders count
  motion the body does not make.

Collisions (stop at contact)
----------------------------
The body's translation over a step runs along the chord from ``p`` to the arc's end ``p'``
(the arc's sagitta over one step is below a micrometre at the Burger's speeds). It is cut at the first
contact, the smallest ``s`` in [0, 1] with ``p + s (p' - p)`` on the boundary of the free space
(:func:`contact_fraction`: the inflated cylinders, the walls' lines offset by ``R``, their corners as discs
of radius ``R``); the heading still turns. So a robot pushing against a cylinder or a wall stays touching
it while its wheels keep turning (and its encoders keep counting, as on the real robot), and it never
passes through anything. Most steps are far from everything: a ball of free space (:class:`FreeBall`)
around the last point where the clearance was measured answers those without a contact test.

Sensors
-------
* LiDAR: ``turtlelib.sensing.scan_model.simulate_scan`` from ``T_world_scan = T_world_body @ T_body_scan``
  (``T_body_scan``: the robot's ``lidar_x``, ``lidar_y``, ``lidar_yaw``) against the cylinders and the walls,
  on the scan's beam layout (``LidarConfig.scan_layout``: fixed, or drawn per turn for the LDS-02). The
  TurtleBot3 LiDARs are in ``LIDAR_MODELS`` (``lidar_model``: ``lds01``, ``lds02``, ``gazebo``).
* Fake landmark sensor: every cylinder with ``|p_body_j| <= max_range``, where
  ``p_body_j = T_world_body^-1 @ c_j``, reads ``p_body_j + e``, ``e ~ N(0, basic_sensor_variance I_2)``.

Randomness: one ``numpy.random.SeedSequence(seed)`` spawns four independent streams (wheel noise, slip,
LiDAR, landmark sensor), so the same seed and the same commands reproduce the same run, and changing
how often one sensor is read does not change another's noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from numpy.typing import NDArray

from nuturtle_description.robot_params import RobotParams
from turtlelib import DiffDrive, Transform2D
from turtlelib.sensing.scan_model import LidarConfig, arena_walls, polygon_walls, simulate_scan
from turtlelib.util.validation import finite_real, in_range, integer, non_negative, one_of, positive, store

# How much less than the measured clearance the free ball's radius is (m): far above the rounding of a
# contact test, far below any distance that matters
FREE_BALL_MARGIN_M = 1e-6
# The default world: eight cylinders of the course's radius, 0.75 to 1.85 m from the centre. On any circle
# of radius 0.5 to 1.0 m through the origin (centre (0, +-radius)) the robot's disc (0.11 m) clears every
# cylinder by at least 0.1 m, and sees some of them within the fake sensor's 2 m.
DEFAULT_OBSTACLE_R_M = 0.038
DEFAULT_OBSTACLES_X = (1.4, -1.4, 1.3, -1.3, 0.0, 0.0, 1.2, -1.2)
DEFAULT_OBSTACLES_Y = (0.3, -0.3, -1.2, 1.2, 0.75, -0.75, 1.4, -1.4)


@dataclass(frozen=True)
class ArenaConfig:
    """The arena's size ``arena_x_length``, ``arena_y_length`` (m, > 0) and the robot's start pose
    ``(x0, y0)`` (m), ``theta0`` (rad)."""

    x0: float = 0.0
    y0: float = 0.0
    theta0: float = 0.0
    arena_x_length: float = 5.0
    arena_y_length: float = 5.0

    def __post_init__(self) -> None:
        store(self, ("x0", "y0", "theta0"), finite_real)
        store(self, ("arena_x_length", "arena_y_length"), positive)

    @property
    def T_world_start(self) -> Transform2D:
        return Transform2D(self.x0, self.y0, self.theta0)


def _store_lists(
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


@dataclass(frozen=True)
class Walls:
    """The arena's walls as a polygon: corner ``k`` at ``(x[k], y[k])`` (m, finite), in order around it,
    the last joined to the first (``turtlelib.polygon_walls``: a simple polygon of at least 3 corners).
    Empty (the default): the rectangle of ``arena_x_length`` by ``arena_y_length``. ROS parameters
    ``walls.x``, ``walls.y``; any sequences become float tuples.
    """

    x: tuple[float, ...] = ()
    y: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        _store_lists(self, "walls.", (("x", finite_real), ("y", finite_real)))
        if len(self.x) != len(self.y):
            raise ValueError(
                f"walls.x and walls.y must have the same length, got {len(self.x)} and {len(self.y)}"
            )
        if self.x:
            polygon_walls(np.column_stack([self.x, self.y]))

    def segments(self, arena: ArenaConfig) -> NDArray[np.float64]:
        """The walls (K, 4), rows ``[x0, y0, x1, y1]`` (m): the polygon's edges, or the ``arena``'s
        rectangle without corners."""
        if not self.x:
            return arena_walls(arena.arena_x_length, arena.arena_y_length)
        return polygon_walls(np.column_stack([self.x, self.y]))

    def describe(self, arena: ArenaConfig) -> str:
        if not self.x:
            return f"the {arena.arena_x_length} m x {arena.arena_y_length} m arena"
        return f"the arena's {len(self.x)}-corner polygon of walls"


@dataclass(frozen=True)
class Obstacles:
    """Cylinders ``j``: centre ``(x[j], y[j])`` (m, finite), radius ``r[j]`` (m, > 0); equal lengths.

    ROS parameters ``obstacles.x``, ``obstacles.y``, ``obstacles.r``; any sequences become float tuples.
    """

    x: tuple[float, ...] = DEFAULT_OBSTACLES_X
    y: tuple[float, ...] = DEFAULT_OBSTACLES_Y
    r: tuple[float, ...] = (DEFAULT_OBSTACLE_R_M,) * len(DEFAULT_OBSTACLES_X)

    def __post_init__(self) -> None:
        _store_lists(self, "obstacles.", (("x", finite_real), ("y", finite_real), ("r", positive)))
        if not len(self.x) == len(self.y) == len(self.r):
            raise ValueError(
                "obstacles.x, obstacles.y and obstacles.r must have the same length, got "
                f"{len(self.x)}, {len(self.y)} and {len(self.r)}"
            )

    def circles(self) -> NDArray[np.float64]:
        """Rows ``[x, y, r]`` (m), shape (M, 3)."""
        return np.array([self.x, self.y, self.r], dtype=np.float64).T.reshape(-1, 3)


@dataclass(frozen=True)
class NoiseConfig:
    """Noise of the motors and the fake landmark sensor, its range, and the random seed.

    ``input_noise`` (rad/s, >= 0): sigma of the wheel-speed noise; ``slip_fraction`` in [0, 1): bound of
    the uniform slip; ``basic_sensor_variance`` (m^2, >= 0): per-axis variance of the landmark sensor;
    ``max_range`` (m, > 0): its range; ``seed`` (int >= 0) seeds every noise stream.
    """

    input_noise: float = 0.01
    slip_fraction: float = 0.01
    basic_sensor_variance: float = 1e-4
    max_range: float = 2.0
    seed: int = 0

    def __post_init__(self) -> None:
        store(self, ("input_noise", "basic_sensor_variance"), non_negative)
        # slip_fraction < 1: a wheel cannot slip backwards
        store(self, ("slip_fraction",), partial(in_range, low=0.0, high=1.0, open_high=True))
        store(self, ("max_range",), positive)
        store(self, ("seed",), partial(integer, minimum=0))


def default_lidar() -> LidarConfig:
    """The LDS-01 (360 beams of 1 deg, 0.12 to 3.5 m) with the course's noise and 1 cm resolution."""
    return LidarConfig(noise=0.01, resolution=0.01)


@dataclass(frozen=True)
class LidarModel:
    """A TurtleBot3 LiDAR as its driver publishes it (notes from ROBOTIS' drivers and turtlebot3_gazebo).

    ``sensor``: the defaults of the ``lidar.*`` parameters (layout, reach, noise, no-return value);
    ``reported_range_m``: the ``(range_min, range_max)`` the driver writes in each LaserScan (None: the
    sensor's own); ``angle_max_past_last_beam``: where the driver puts ``angle_max``, in increments past
    the last beam (0: at it, 1: one past, where the LDS-02's turn ends).
    """

    sensor: LidarConfig
    reported_range_m: tuple[float, float] | None = None
    angle_max_past_last_beam: int = 0


# lds01: nusim's LDS-01 (0.0 for no return, 1 cm noise and resolution). lds02 (ld08_driver): 2300 points
# per second, spin 6 Hz +- 2 % (383 beams of 0.94 deg, 374 to 391 per turn, the first at a random angle),
# NaN for no return, 1 mm resolution, a reach of 0.16 to 8 m but 0 to 100 m in the message. gazebo
# (turtlebot3_gazebo): 360 beams from 0 to 6.28 rad (the last repeats the first), inf for no return,
# 0.12 to 3.5 m, Gaussian noise of 0.01 m.
LIDAR_MODELS = {
    "lds01": LidarModel(default_lidar()),
    "lds02": LidarModel(
        LidarConfig(
            range_min=0.16,
            range_max=8.0,
            angle_increment=2.0 * math.pi * 6.0 / 2300.0,
            samples=383,
            noise=0.01,
            resolution=0.001,
            no_return=math.nan,
            spin_spread=0.02,
        ),
        reported_range_m=(0.0, 100.0),
        angle_max_past_last_beam=1,
    ),
    "gazebo": LidarModel(
        LidarConfig(angle_increment=6.28 / 359, samples=360, noise=0.01, no_return=math.inf)
    ),
}


@dataclass(frozen=True)
class LidarChoice:
    """``lidar_model``: the LiDAR simulated, one of ``LIDAR_MODELS`` (``lds01``, ``lds02``, ``gazebo``);
    it sets the defaults of the ``lidar.*`` parameters and what each scan message reports."""

    lidar_model: str = "lds01"

    def __post_init__(self) -> None:
        one_of("lidar_model", self.lidar_model, tuple(LIDAR_MODELS))

    @property
    def model(self) -> LidarModel:
        return LIDAR_MODELS[self.lidar_model]


@dataclass(frozen=True)
class SimulationConfig:
    """The whole simulated world; the defaults are the default world (config/basic_world.yaml).

    Besides each part's own checks, every cylinder must lie inside the arena and the robot's collision
    disc must start free (inside the walls, clear of every cylinder); ValueError otherwise.
    """

    arena: ArenaConfig = field(default_factory=ArenaConfig)
    obstacles: Obstacles = field(default_factory=Obstacles)
    robot: RobotParams = field(default_factory=RobotParams)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    lidar: LidarConfig = field(default_factory=default_lidar)
    walls: Walls = field(default_factory=Walls)

    def __post_init__(self) -> None:
        segments = self.wall_segments
        no_circles = np.zeros((0, 3))
        for j, (x, y, r) in enumerate(self.obstacles.circles()):
            if first_collision(np.array([x, y]), no_circles, segments, r) is not None:
                raise ValueError(
                    f"obstacle {j} at ({x}, {y}) m with radius {r} m does not fit inside "
                    f"{self.walls.describe(self.arena)}"
                )
        collision = first_collision(
            self.arena.T_world_start.translation,
            self.obstacles.circles(),
            segments,
            self.robot.collision_radius,
        )
        if collision is not None:
            raise ValueError(
                f"the robot's start (x0, y0) = ({self.arena.x0}, {self.arena.y0}) m with collision_radius "
                f"{self.robot.collision_radius} m {collision}"
            )

    @property
    def wall_segments(self) -> NDArray[np.float64]:
        """The arena's walls (K, 4), rows ``[x0, y0, x1, y1]`` (m), a closed polygon (:class:`Walls`)."""
        return self.walls.segments(self.arena)


def inside_polygon(p_world: NDArray[np.float64], walls: NDArray[np.float64]) -> bool:
    """Whether ``p_world`` lies inside the closed polygon whose edges are ``walls`` (K, 4): a ray from it
    towards +x crosses the edges an odd number of times (each edge counted on its half-open y span)."""
    x0, y0, x1, y1 = walls.T
    spans = (y0 > p_world[1]) != (y1 > p_world[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = x0 + (p_world[1] - y0) * (x1 - x0) / (y1 - y0)
    return bool(np.count_nonzero(spans & (x_cross > p_world[0])) % 2)


def wall_distances(p_world: NDArray[np.float64], walls: NDArray[np.float64]) -> NDArray[np.float64]:
    """The distance (K,) from ``p_world`` to each wall segment ``[x0, y0, x1, y1]``: to its nearest point
    ``a + s e``, ``e = b - a``, ``s = clip((p - a).e / e.e, 0, 1)``."""
    a, e = walls[:, :2], walls[:, 2:] - walls[:, :2]
    s = np.clip(np.einsum("kd,kd->k", p_world - a, e) / np.einsum("kd,kd->k", e, e), 0.0, 1.0)
    return np.hypot(*(p_world - a - s[:, None] * e).T)


def first_collision(
    p_world: NDArray[np.float64],
    circles: NDArray[np.float64],
    walls: NDArray[np.float64],
    radius_m: float,
) -> str | None:
    """Why a disc of ``radius_m`` centred at ``p_world`` is not free among ``circles`` (M, 3) inside the
    polygon of ``walls`` (K, 4) (see the module docstring), or None."""
    if not inside_polygon(p_world, walls):
        return "is not inside the arena (outside its walls)"
    distances = wall_distances(p_world, walls)
    if np.any(distances < radius_m):
        k = int(np.argmin(distances))
        return (
            f"is not inside the arena: {distances[k]:.3f} m from its wall ({walls[k, 0]}, {walls[k, 1]}) -> "
            f"({walls[k, 2]}, {walls[k, 3]})"
        )
    # |p - c_j| < R + r_j
    overlapping = np.hypot(*(p_world - circles[:, :2]).T) < radius_m + circles[:, 2]
    if np.any(overlapping):
        j = int(np.argmax(overlapping))
        return f"overlaps obstacle {j} at ({circles[j, 0]}, {circles[j, 1]}) m"
    return None


def contact_fraction(
    p_world: NDArray[np.float64],
    d_world: NDArray[np.float64],
    circles: NDArray[np.float64],
    walls: NDArray[np.float64],
    radius_m: float,
) -> float:
    """The fraction ``s`` in [0, 1] of the move ``p -> p + d`` a disc of ``radius_m`` makes before contact.

    Cylinder ``j`` (inflated to ``rho = radius_m + r_j``): with ``m = p - c_j``, contact where
    ``|m + s d|^2 = rho^2``, i.e. ``a s^2 + 2 b s + q = 0`` with ``a = d.d``, ``b = m.d``,
    ``q = |m|^2 - rho^2``; approaching (``b < 0``) and reaching it (``b^2 - a q >= 0``) the near root is
    ``s = q / (-b + sqrt(b^2 - a q))`` (no cancellation), and ``s = 0`` if already touching (``q <= 0``).
    Wall ``k`` from ``a_k`` along the unit ``t_k`` (length ``L_k``), normal ``n_k`` (``t_k`` turned by
    +90 deg): at signed distance ``h = n.(p - a)`` and approaching it (``h (n.d) < 0``) the centre reaches
    the line offset by ``radius_m`` at ``s = (|h| - radius_m) / |n.d|`` (0 if already nearer), a contact
    when its foot ``t.(p + s d - a)`` lies in ``[0, L]``; beyond the segment's ends its corners act as
    cylinders of radius 0. A start slightly inside (rounding at a previous contact) only blocks the motion
    that goes further in.
    """
    a = float(d_world @ d_world)
    if a == 0.0:
        return 1.0
    fraction = 1.0
    # the walls' corners: cylinders of radius 0
    circles = np.vstack([circles.reshape(-1, 3), np.column_stack([walls[:, :2], np.zeros(len(walls))])])
    if circles.shape[0]:
        m = p_world - circles[:, :2]
        rho = radius_m + circles[:, 2]
        b = m @ d_world
        q = np.einsum("ji,ji->j", m, m) - rho * rho
        disc = b * b - a * q
        reaches = (b < 0.0) & (disc >= 0.0)
        if np.any(reaches):
            # s = q / (-b + sqrt(b^2 - a q)), clamped at 0 when touching
            s = np.maximum(q[reaches], 0.0) / (-b[reaches] + np.sqrt(disc[reaches]))
            fraction = min(fraction, float(np.min(s)))
    return min(fraction, _wall_contact_fraction(p_world, d_world, walls, radius_m))


def _wall_contact_fraction(
    p_world: NDArray[np.float64], d_world: NDArray[np.float64], walls: NDArray[np.float64], radius_m: float
) -> float:
    """The first contact of the centre with a wall's line offset by ``radius_m`` within the segment's span
    (:func:`contact_fraction`), 1.0 without one."""
    if walls.shape[0] == 0:
        return 1.0
    a = walls[:, :2]
    e = walls[:, 2:] - a
    length = np.hypot(e[:, 0], e[:, 1])
    t = e / length[:, None]
    n = np.column_stack([-t[:, 1], t[:, 0]])
    h = np.einsum("kd,kd->k", p_world - a, n)
    hd = n @ d_world
    approaching = h * hd < 0.0
    if not np.any(approaching):
        return 1.0
    h, hd, a, t, length = h[approaching], hd[approaching], a[approaching], t[approaching], length[approaching]
    s = np.maximum((np.abs(h) - radius_m) / np.abs(hd), 0.0)
    foot = np.einsum("kd,kd->k", p_world + s[:, None] * d_world - a, t)
    hits = (foot >= 0.0) & (foot <= length) & (s <= 1.0)
    return float(np.min(s[hits])) if np.any(hits) else 1.0


def clearance_m(
    p_world: NDArray[np.float64], circles: NDArray[np.float64], walls: NDArray[np.float64], radius_m: float
) -> float:
    """How far the centre of a disc of ``radius_m`` at ``p_world`` can move in any direction before contact:
    ``min(min_j |p - c_j| - (radius_m + r_j), min_k dist(p, wall_k) - radius_m)`` (m; <= 0 at or past
    contact; inf in an empty world). Inside the arena, any move shorter than that is free."""
    nearest = math.inf
    if circles.shape[0]:
        nearest = float(np.min(np.hypot(*(p_world - circles[:, :2]).T) - circles[:, 2]))
    if walls.shape[0]:
        nearest = min(nearest, float(np.min(wall_distances(p_world, walls))))
    return nearest - radius_m


class FreeBall:
    """A ball of free space for the robot's centre, so a step far from everything needs no contact test.

    The ball is centred where the clearance (:func:`clearance_m`) was last measured, ``p0``, with radius
    ``clearance(p0) - FREE_BALL_MARGIN_M``. A move ``p -> p + d`` with ``|p - p0| + |d|`` below that radius
    stays inside it (triangle inequality), so no obstacle is within reach: its contact fraction is 1, as
    :func:`contact_fraction` gives. Otherwise the ball is measured again at ``p`` and, if the move still
    leaves it, :func:`contact_fraction` decides. Keyed on the position alone, so a teleport needs no
    reset. On the demo's figure eight in the default world (its disc about 0.45 m clear of every cylinder)
    the clearance is measured about once per 0.5 m of travel (15 times in 60 s) instead of a contact test
    per 10 ms step.
    """

    def __init__(self, circles: NDArray[np.float64], walls: NDArray[np.float64], radius_m: float) -> None:
        self.circles = circles
        self.walls = walls
        self.radius_m = radius_m
        self._centre = (math.nan, math.nan)
        self._free_m = -math.inf

    def contact_fraction(self, p_world: NDArray[np.float64], d_world: NDArray[np.float64]) -> float:
        """:func:`contact_fraction` of the move ``p -> p + d``."""
        reach_m = math.hypot(d_world[0], d_world[1])
        if self._reaches_within(p_world, reach_m):
            return 1.0
        self._centre = (float(p_world[0]), float(p_world[1]))
        self._free_m = clearance_m(p_world, self.circles, self.walls, self.radius_m) - FREE_BALL_MARGIN_M
        if self._reaches_within(p_world, reach_m):
            return 1.0
        return contact_fraction(p_world, d_world, self.circles, self.walls, self.radius_m)

    def _reaches_within(self, p_world: NDArray[np.float64], reach_m: float) -> bool:
        # |p - p0| + |d| < clearance(p0) - margin (False while the ball is unmeasured: NaN compares False)
        return math.hypot(p_world[0] - self._centre[0], p_world[1] - self._centre[1]) + reach_m < self._free_m


@dataclass(frozen=True)
class SimulatedScan:
    """One scan: its beam ``layout`` and the measured ``range_m`` (m), shape (layout.samples,)."""

    layout: LidarConfig
    range_m: NDArray[np.float64]


@dataclass(frozen=True)
class LandmarkReadings:
    """The fake sensor's output: ``ids`` (K,) indices of the cylinders within max_range, and ``p_body``
    (K, 2) their noisy centres (m) in base_footprint, row k for cylinder ``ids[k]``."""

    ids: NDArray[np.intp]
    p_body: NDArray[np.float64]


class Simulation:
    """The true state of the simulated Burger and its sensors (see the module docstring for the models).

    State: ``T_world_body`` (true pose), the motor commands ``motor_cmd`` (left, right; mcu), the encoder
    angles (rad, continuous, before quantisation) and the last step's wheel speeds and body twist.
    """

    def __init__(self, config: SimulationConfig) -> None:
        self.config = config
        self.drive: DiffDrive = config.robot.diff_drive()
        self.circles = config.obstacles.circles()
        self.walls = config.wall_segments
        self._free_ball = FreeBall(self.circles, self.walls, config.robot.collision_radius)
        wheel_seq, slip_seq, lidar_seq, landmark_seq = np.random.SeedSequence(config.noise.seed).spawn(4)
        self._wheel_rng = np.random.default_rng(wheel_seq)
        self._slip_rng = np.random.default_rng(slip_seq)
        self._lidar_rng = np.random.default_rng(lidar_seq)
        self._landmark_rng = np.random.default_rng(landmark_seq)
        self.T_world_body = config.arena.T_world_start
        self.motor_cmd = np.zeros(2, dtype=np.int64)
        self._encoder_rad = np.zeros(2)
        self.wheel_speed_rad_s = np.zeros(2)
        self.V_body = np.zeros(3)
        # the floor's grip under each wheel (left, right), in [0, 1]: 1 normally, 0 during a slip event
        # (module docstring)
        self.traction = np.ones(2)

    # --- motors ------------------------------------------------------------------------------------------

    def command_wheels(self, left_rad_s: float, right_rad_s: float) -> NDArray[np.int64]:
        """Set the wheel speeds (rad/s) as the motors take them; returns the motor commands (mcu).

        ``u = clip(round(w * motor_cmd_per_rad_sec), -motor_cmd_max, motor_cmd_max)`` (clipped before
        rounding, so huge finite speeds saturate). ValueError for non-finite speeds.
        """
        w = np.array([left_rad_s, right_rad_s], dtype=np.float64)
        if not np.all(np.isfinite(w)):
            raise ValueError(f"wheel speeds must be finite, got ({left_rad_s!r}, {right_rad_s!r})")
        robot = self.config.robot
        with np.errstate(over="ignore"):
            u = np.clip(w * robot.motor_cmd_per_rad_sec, -robot.motor_cmd_max, robot.motor_cmd_max)
        self.motor_cmd = np.round(u).astype(np.int64)
        return self.motor_cmd.copy()

    @property
    def commanded_speed_rad_s(self) -> NDArray[np.float64]:
        """``w' = u / motor_cmd_per_rad_sec`` (rad/s), shape (2,)."""
        return self.motor_cmd / self.config.robot.motor_cmd_per_rad_sec

    # --- physics -----------------------------------------------------------------------------------------

    def step(self, dt_s: float) -> None:
        """Advance the world by ``dt_s`` s (> 0): wheel noise, encoders, slip, arc motion, collisions."""
        dt_s = positive("dt_s", dt_s)
        noise = self.config.noise
        w = self.commanded_speed_rad_s
        # w'' = w' + n,  n ~ N(0, input_noise^2), on turning wheels only
        n = self._wheel_rng.normal(0.0, noise.input_noise, size=2)
        w_noisy = np.where(w != 0.0, w + n, 0.0)
        # phi += w'' dt  (what the encoders count)
        self._encoder_rad = self._encoder_rad + w_noisy * dt_s
        self.wheel_speed_rad_s = w_noisy
        # dphi_i = traction_i w_i'' dt (1 + s_i),  s_i ~ U(-slip, slip)
        slip = self._slip_rng.uniform(-noise.slip_fraction, noise.slip_fraction, size=2)
        dphi = self.traction * w_noisy * dt_s * (1.0 + slip)
        T_start = self.T_world_body
        # T' = T @ exp([F dphi])
        T_end = self.drive.step(T_start, dphi[0], dphi[1])
        d_world = T_end.translation - T_start.translation
        s = self._free_ball.contact_fraction(T_start.translation, d_world)
        if s < 1.0:
            p_world = T_start.translation + s * d_world
            T_end = Transform2D(p_world[0], p_world[1], T_end.theta)
        self.T_world_body = T_end
        # V_b = log(T^-1 T') / dt
        self.V_body = (T_start.inverse() @ T_end).log().as_array() / dt_s

    @property
    def encoder_ticks(self) -> NDArray[np.int64]:
        """``ticks = round(phi * encoder_ticks_per_rad)``, (left, right), shape (2,)."""
        return np.round(self._encoder_rad * self.config.robot.encoder_ticks_per_rad).astype(np.int64)

    @property
    def wheel_angles_rad(self) -> NDArray[np.float64]:
        """The encoder reading as a wheel angle: ``ticks / encoder_ticks_per_rad`` (rad), shape (2,)."""
        return self.encoder_ticks / self.config.robot.encoder_ticks_per_rad

    def teleport(self, T_world_body: Transform2D) -> None:
        """Put the robot at ``T_world_body`` (the encoders keep their count); ValueError if not free."""
        collision = first_collision(
            T_world_body.translation, self.circles, self.walls, self.config.robot.collision_radius
        )
        if collision is not None:
            raise ValueError(
                f"cannot teleport to ({T_world_body.x}, {T_world_body.y}) m: the robot {collision}"
            )
        self.T_world_body = T_world_body
        self.V_body = np.zeros(3)

    def reset(self) -> None:
        """Back to the start pose, at rest (motor commands zero); the encoders keep their count."""
        self.teleport(self.config.arena.T_world_start)
        self.motor_cmd = np.zeros(2, dtype=np.int64)
        self.wheel_speed_rad_s = np.zeros(2)

    # --- sensors -----------------------------------------------------------------------------------------

    def scan(self) -> SimulatedScan:
        """A LiDAR scan from the true pose: this turn's layout, then the ranges (m; ``no_return`` where
        nothing is measured)."""
        T_world_scan = self.T_world_body @ self.config.robot.T_body_scan
        layout = self.config.lidar.scan_layout(self._lidar_rng)
        return SimulatedScan(
            layout, simulate_scan(T_world_scan, self.circles, self.walls, layout, self._lidar_rng)
        )

    def sense_landmarks(self) -> LandmarkReadings:
        """The cylinders within max_range of base_footprint and their noisy body-frame centres."""
        # p_body_j = T_world_body^-1 @ c_j
        p_body = self.T_world_body.inverse() @ self.circles[:, :2]
        sigma_m = math.sqrt(self.config.noise.basic_sensor_variance)
        # one draw per cylinder every time, so the stream does not depend on what is in range
        e = self._landmark_rng.normal(0.0, sigma_m, size=p_body.shape)
        in_range = np.hypot(p_body[:, 0], p_body[:, 1]) <= self.config.noise.max_range
        return LandmarkReadings(np.flatnonzero(in_range), p_body[in_range] + e[in_range])
