"""The simulated TurtleBot3 Burger in an arena of cylinders, or in rooms: pure Python/numpy, no ROS.

World (frame ``world``, m, rad)
-------------------------------
An arena closed by walls: the polygon with corners ``(walls.x[k], walls.y[k])`` in order (any simple
polygon, e.g. the hexagon of ROBOTIS' turtlebot3_world), or without them the rectangle
``|x| <= arena_x_length / 2``, ``|y| <= arena_y_length / 2`` (the inner faces of its walls); cylinders ``j``
at ``c_j = (obstacles.x[j], obstacles.y[j])`` of radius ``obstacles.r[j]``; and the robot, a disc of
``collision_radius`` ``R`` centred on ``base_footprint`` with true pose ``T_world_body`` (starting at
``(x0, y0, theta0)``). The robot's centre ``p`` is *free* when it is inside the polygon, ``|p - c_j| >=
R + r_j`` for every cylinder and ``dist(p, wall_k) >= R`` for every wall segment (each wall is a capsule
of radius ``R`` around its segment for the centre; :mod:`nusim.free_space`).

Rooms (:mod:`nusim.house`): interior walls (segments), boxes (solid rectangles: furniture the LiDAR sees
whole) and furniture on legs (four small cylinders each, placed at random in given areas from the
``seed``) are walls and cylinders too: the LiDAR sees them and the robot cannot pass them. The landmarks
are the cylinders alone (``obstacles``): legs are never reported by the fake sensor.

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

Randomness: one ``numpy.random.SeedSequence(seed)`` spawns five independent streams (wheel noise, slip,
LiDAR, landmark sensor, placement of the furniture on legs), so the same seed and the same commands
reproduce the same run in the same rooms, and changing how often one sensor is read does not change
another's noise.

Several robots (:class:`Robots`, :class:`MultiRobotSimulation`)
----------------------------------------------------------------
One world can hold ``n`` robots of one model, robot ``k`` named ``robots.names[k]`` (its ROS namespace)
and starting at ``(robots.x0[k], robots.y0[k], robots.theta0[k])``; without names it is the one robot at
``(x0, y0, theta0)`` above, exactly as before. Each robot is a :class:`Simulation` of its own (motors,
encoders, slip, sensors) with its own four noise streams (:func:`robot_streams`: robot 0 has the ones
above, robot ``k >= 1`` the four children of the seed's child ``4 + k``; the placement stream is the
world's). To the others a robot is a cylinder of its ``collision_radius`` at its true position: each
robot's LiDAR sees the others as discs, and robots collide with each other as with a cylinder (the move
cut at the first contact ``|p_a - p_b| = R_a + R_b``, the heading still turning). One physics step moves
every robot in turn, in the order ``robots.names`` lists them, each against the others where they are at
that moment (the robots before it already moved), so no two ever overlap. The starts must be free and
pairwise at least ``2 R`` apart, and the furniture on legs is placed clear of every start.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from numpy.typing import NDArray

from nuturtle_description.robot_params import RobotParams
from turtlelib import DiffDrive, Transform2D
from turtlelib.sensing.scan_model import LidarConfig, arena_walls, polygon_walls, simulate_scan
from turtlelib.util.validation import finite_real, in_range, integer, non_negative, one_of, positive, store

from .free_space import FreeBall, contact_fraction, first_collision
from .house import Boxes, InteriorWalls, Legs, WorldGeometry, store_lists, store_table

# The default world: eight cylinders of the course's radius, 0.75 to 1.85 m from the centre. On any circle
# of radius 0.5 to 1.0 m through the origin (centre (0, +-radius)) the robot's disc (0.11 m) clears every
# cylinder by at least 0.1 m, and sees some of them within the fake sensor's 2 m.
DEFAULT_OBSTACLE_R_M = 0.038
DEFAULT_OBSTACLES_X = (1.4, -1.4, 1.3, -1.3, 0.0, 0.0, 1.2, -1.2)
DEFAULT_OBSTACLES_Y = (0.3, -0.3, -1.2, 1.2, 0.75, -0.75, 1.4, -1.4)
# A robot's name: one token of a ROS namespace (tb3_0, tb3_1, ...)
ROBOT_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
# No other robot: rows [x, y, r] (m) of the other robots' discs
NO_OTHERS = np.zeros((0, 3))
NO_WALLS = np.zeros((0, 4))


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
        store_lists(self, "walls.", (("x", finite_real), ("y", finite_real)))
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
        store_lists(self, "obstacles.", (("x", finite_real), ("y", finite_real), ("r", positive)))
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
    ``max_range`` (m, > 0): its range; ``seed`` (int >= 0) seeds every noise stream and the placement of
    the furniture on legs.
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


def seed_streams(seed: int) -> list[np.random.SeedSequence]:
    """The five independent streams of ``seed`` (module docstring): wheel noise, slip, LiDAR, landmark
    sensor, placement (spawned children: each one's draws do not depend on how many the others make)."""
    return np.random.SeedSequence(seed).spawn(5)


def robot_streams(seed: int, index: int) -> list[np.random.SeedSequence]:
    """Robot ``index``'s four streams (wheel noise, slip, LiDAR, landmark sensor): robot 0's are the first
    four of :func:`seed_streams` (one robot as before), robot ``k >= 1``'s the children of the seed's child
    ``4 + k`` (``SeedSequence(seed, spawn_key=(4 + k,))``, the child ``spawn`` would give): every robot's
    independent of the others' and of the placement."""
    if index == 0:
        return seed_streams(seed)[:4]
    return np.random.SeedSequence(seed, spawn_key=(4 + index,)).spawn(4)


@dataclass(frozen=True)
class Robots:
    """Several robots in one world (module docstring): ``names`` their names (each a ROS namespace token:
    a letter then letters, digits or ``_``; distinct), and their start poses ``x0[k]``, ``y0[k]`` (m,
    finite) and ``theta0[k]`` (rad, finite), one per name. No names (the default): the one robot at the
    arena's ``(x0, y0, theta0)``. ROS parameters ``robots.names``, ``robots.x0``, ``robots.y0``,
    ``robots.theta0``; any sequences become tuples.
    """

    names: tuple[str, ...] = ()
    x0: tuple[float, ...] = ()
    y0: tuple[float, ...] = ()
    theta0: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.names, (str, bytes)) or not isinstance(self.names, Sequence):
            raise ValueError(f"robots.names must be a list of names, got {self.names!r}")
        object.__setattr__(self, "names", tuple(self.names))
        for k, name in enumerate(self.names):
            if not isinstance(name, str) or ROBOT_NAME.fullmatch(name) is None:
                raise ValueError(
                    f"robots.names[{k}] must be a namespace token (a letter, then letters, digits or _), "
                    f"got {name!r}"
                )
        if len(set(self.names)) != len(self.names):
            raise ValueError(f"robots.names must be distinct, got {list(self.names)}")
        store_table(self, "robots.", (("x0", finite_real), ("y0", finite_real), ("theta0", finite_real)))
        if len(self.x0) != len(self.names):
            raise ValueError(
                f"robots.x0, robots.y0 and robots.theta0 need one value per name ({len(self.names)}), "
                f"got {len(self.x0)}"
            )

    def starts(self, arena: ArenaConfig) -> tuple[Transform2D, ...]:
        """Each robot's start pose ``T_world_start``; without names the arena's one."""
        if not self.names:
            return (arena.T_world_start,)
        return tuple(Transform2D(*pose) for pose in zip(self.x0, self.y0, self.theta0, strict=True))


@dataclass(frozen=True)
class SimulationConfig:
    """The whole simulated world; the defaults are the default world (config/basic_world.yaml).

    Besides each part's own checks, every cylinder must lie inside the arena, outside every box and clear
    of the interior walls, and each robot's collision disc must start free (inside the walls, clear of
    every cylinder, box and interior wall, and of the other robots' start discs); the furniture on legs
    is then placed (``world``, from the seed's placement stream, clear of every start); ValueError
    otherwise. ``robots``: several robots (module docstring), none by default (one robot).
    """

    arena: ArenaConfig = field(default_factory=ArenaConfig)
    obstacles: Obstacles = field(default_factory=Obstacles)
    robot: RobotParams = field(default_factory=RobotParams)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    lidar: LidarConfig = field(default_factory=default_lidar)
    walls: Walls = field(default_factory=Walls)
    interior_walls: InteriorWalls = field(default_factory=InteriorWalls)
    boxes: Boxes = field(default_factory=Boxes)
    legs: Legs = field(default_factory=Legs)
    robots: Robots = field(default_factory=Robots)
    # everything solid, the legs placed: set by __post_init__
    world: WorldGeometry = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        segments = self.wall_segments
        no_circles = np.zeros((0, 3))
        bare = WorldGeometry(segments, self.interior_walls.segments(), self.boxes.corners())
        for j, (x, y, r) in enumerate(self.obstacles.circles()):
            if first_collision(np.array([x, y]), no_circles, segments, r) is not None:
                raise ValueError(
                    f"obstacle {j} at ({x}, {y}) m with radius {r} m does not fit inside "
                    f"{self.walls.describe(self.arena)}"
                )
            reason = bare.first_collision(np.array([x, y]), r)
            if reason is not None:
                raise ValueError(f"obstacle {j} at ({x}, {y}) m with radius {r} m {reason}")
        world = WorldGeometry(bare.outer, bare.interior, bare.boxes, self.obstacles.circles())
        radius_m = self.robot.collision_radius
        starts_xy = np.array([T.translation for T in self.starts])
        for k, p_world in enumerate(starts_xy):
            collision = world.first_collision(p_world, radius_m)
            if collision is None and k > 0:
                # |p_k - p_j| >= 2 R for the robots before it
                gaps_m = np.hypot(*(starts_xy[:k] - p_world).T)
                j = int(np.argmin(gaps_m))
                if gaps_m[j] < 2.0 * radius_m:
                    collision = f"overlaps robot {self.robots.names[j]}'s start ({gaps_m[j]:.3f} m apart)"
            if collision is not None:
                whose = (
                    f"the robot's start (x0, y0) = ({self.arena.x0}, {self.arena.y0}) m"
                    if not self.robots.names
                    else f"robot {self.robots.names[k]}'s start ({p_world[0]}, {p_world[1]}) m"
                )
                raise ValueError(f"{whose} with collision_radius {radius_m} m {collision}")
        placement = np.random.default_rng(seed_streams(self.noise.seed)[4])
        world = world.with_legs(self.legs, placement, starts_xy, radius_m)
        object.__setattr__(self, "world", world)

    @property
    def starts(self) -> tuple[Transform2D, ...]:
        """Each robot's start pose ``T_world_start`` (one without ``robots``: the arena's)."""
        return self.robots.starts(self.arena)

    @property
    def wall_segments(self) -> NDArray[np.float64]:
        """The arena's walls (K, 4), rows ``[x0, y0, x1, y1]`` (m), a closed polygon (:class:`Walls`)."""
        return self.walls.segments(self.arena)


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
    """The true state of one simulated robot and its sensors (see the module docstring for the models):
    robot ``index`` of ``config.robots`` (0: the one robot), starting at ``T_world_start``.

    State: ``T_world_body`` (true pose), the motor commands ``motor_cmd`` (left, right; mcu), the encoder
    angles (rad, continuous, before quantisation) and the last step's wheel speeds and body twist.
    ``others`` (M, 3) of :meth:`step`, :meth:`scan` and :meth:`teleport`: the other robots' discs
    ``[x, y, r]`` (m) in the world (:class:`MultiRobotSimulation`), none by default.
    """

    def __init__(self, config: SimulationConfig, index: int = 0) -> None:
        self.config = config
        self.index = index
        self.T_world_start = config.starts[index]
        self.drive: DiffDrive = config.robot.diff_drive()
        # the landmarks and the arena's polygon of walls; world: everything solid (rooms included)
        self.circles = config.obstacles.circles()
        self.walls = config.wall_segments
        self.world = config.world
        self._free_ball = FreeBall(self.world.circles, self.world.segments, config.robot.collision_radius)
        wheel_seq, slip_seq, lidar_seq, landmark_seq = robot_streams(config.noise.seed, index)
        self._wheel_rng = np.random.default_rng(wheel_seq)
        self._slip_rng = np.random.default_rng(slip_seq)
        self._lidar_rng = np.random.default_rng(lidar_seq)
        self._landmark_rng = np.random.default_rng(landmark_seq)
        self.T_world_body = self.T_world_start
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

    def step(self, dt_s: float, others: NDArray[np.float64] = NO_OTHERS) -> None:
        """Advance the robot by ``dt_s`` s (> 0): wheel noise, encoders, slip, arc motion, collisions (with
        the world and the ``others``' discs)."""
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
        if others.shape[0]:
            # the other robots as cylinders: contact at |p - c| = R + r
            s = min(
                s, contact_fraction(T_start.translation, d_world, others, NO_WALLS, self.collision_radius_m)
            )
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

    @property
    def collision_radius_m(self) -> float:
        """The robot's collision radius (m): its disc to the world and to the other robots."""
        return self.config.robot.collision_radius

    @property
    def disc(self) -> NDArray[np.float64]:
        """The robot as the others meet and see it: ``[x, y, collision_radius]`` (m), shape (3,)."""
        return np.array([self.T_world_body.x, self.T_world_body.y, self.collision_radius_m])

    def teleport(self, T_world_body: Transform2D, others: NDArray[np.float64] = NO_OTHERS) -> None:
        """Put the robot at ``T_world_body`` (the encoders keep their count); ValueError if not free (in the
        world, or overlapping one of the ``others``' discs)."""
        p_world = T_world_body.translation
        collision = self.world.first_collision(p_world, self.collision_radius_m)
        # |p - c| < R + r
        overlapping = np.hypot(*(p_world - others[:, :2]).T) < self.collision_radius_m + others[:, 2]
        if collision is None and np.any(overlapping):
            j = int(np.argmax(overlapping))
            collision = f"overlaps another robot at ({others[j, 0]:.3f}, {others[j, 1]:.3f}) m"
        if collision is not None:
            raise ValueError(
                f"cannot teleport to ({T_world_body.x}, {T_world_body.y}) m: the robot {collision}"
            )
        self.T_world_body = T_world_body
        self.V_body = np.zeros(3)

    def reset(self) -> None:
        """Back to the start pose, at rest (motor commands zero); the encoders keep their count."""
        self.teleport(self.T_world_start)
        self.motor_cmd = np.zeros(2, dtype=np.int64)
        self.wheel_speed_rad_s = np.zeros(2)

    # --- sensors -----------------------------------------------------------------------------------------

    def scan(self, others: NDArray[np.float64] = NO_OTHERS) -> SimulatedScan:
        """A LiDAR scan from the true pose against every wall and cylinder (rooms included) and the
        ``others``' discs: this turn's layout, then the ranges (m; ``no_return`` where nothing is
        measured)."""
        T_world_scan = self.T_world_body @ self.config.robot.T_body_scan
        layout = self.config.lidar.scan_layout(self._lidar_rng)
        circles = self.world.circles if not others.shape[0] else np.vstack([self.world.circles, others])
        return SimulatedScan(
            layout, simulate_scan(T_world_scan, circles, self.world.segments, layout, self._lidar_rng)
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


class MultiRobotSimulation:
    """Every robot of ``config`` in its one world (module docstring, "Several robots"): ``robots[k]`` the
    :class:`Simulation` of robot ``k`` (one without ``config.robots``), ``names`` their names (``("",)``
    for the one robot). Each robot's other robots are cylinders of their collision radius at their true
    positions."""

    def __init__(self, config: SimulationConfig) -> None:
        self.config = config
        self.names = config.robots.names or ("",)
        self.robots = [Simulation(config, k) for k in range(len(self.names))]

    def others(self, index: int) -> NDArray[np.float64]:
        """The discs ``[x, y, r]`` (m) of every robot but ``index``, shape (n - 1, 3)."""
        if len(self.robots) == 1:
            return NO_OTHERS
        return np.array([robot.disc for robot in self.robots if robot.index != index])

    def step(self, dt_s: float) -> None:
        """One physics step of ``dt_s`` s: each robot in turn, against the others where they are now."""
        for robot in self.robots:
            robot.step(dt_s, self.others(robot.index))

    def scan(self, index: int) -> SimulatedScan:
        """Robot ``index``'s LiDAR scan, the other robots seen as discs."""
        return self.robots[index].scan(self.others(index))

    def teleport(self, index: int, T_world_body: Transform2D) -> None:
        """Put robot ``index`` at ``T_world_body``; ValueError if that is not free of the world and of the
        other robots."""
        self.robots[index].teleport(T_world_body, self.others(index))

    def reset(self) -> None:
        """Every robot back to its start pose, at rest (the starts are free and apart: SimulationConfig)."""
        for robot in self.robots:
            robot.reset()
