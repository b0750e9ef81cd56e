"""Closed-loop slip and bump scenarios in nusim's simulation, without ROS: the world, the LiDAR, the
landmark detector and EKF SLAM on its timeline, as the nodes chain them.

The robot (a TurtleBot3 model, the Burger by default, in nusim's default world) drives a circle of
``radius_m`` about (0, radius_m), mapping (or localizing in the true map) for ``event_s`` seconds.
Then one event:

* ``"phantom_turn"``: the floor loses its grip (``Simulation.traction`` 0) while the robot is commanded to
  turn in place until its wheels report ``turn_rad`` of turn; the body does not move;
* ``"wheel_slip"``: while the circle goes on, the left wheel spins on a slick patch (its traction 0) until
  the wheels have reported ``turn_rad`` more turn than the body made;
* ``"bump"``: the robot turns to face the nearest cylinder, drives into it and keeps pushing, wheels
  spinning, for ``push_s`` seconds, then drives back and turns back onto its circle;

or ``"none"``; and the circle resumes for ``after_s`` seconds. Joint states at 20 Hz, scans at 5 Hz,
physics at 100 Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from nusim.simulation import NoiseConfig, Simulation, SimulationConfig, default_lidar
from nuturtle_description.robot_params import model_params
from turtlelib import EkfSlam, LandmarkDetector, SlamConfig, SlamTimeline, Twist2D
from turtlelib.estimation.range_bearing import observations_from_points
from turtlelib.estimation.slip_recovery import SlipRecovery, SlipRecoveryConfig, lost_wheel_turn_per_m
from turtlelib.mapping.landmark_map import LandmarkMap
from turtlelib.motion.motion_models import DiffDriveMotion
from turtlelib.motion.motion_signals import WheelAngles
from turtlelib.sensing.detection import DetectorConfig

PHYSICS_DT_S = 0.01
JOINT_EVERY = 5  # physics steps per joint_states (20 Hz)
SCAN_EVERY = 20  # physics steps per scan (5 Hz)
SPEED_M_S = 0.12
TURN_RAD_S = 1.0


@dataclass
class ScenarioResult:
    """Errors of the filter against the truth: ``final_error_m`` / ``final_heading_rad`` at the end,
    ``event_end_s`` when the event ended, ``errors`` (t_s, position error m) after every scan, the
    landmarks mapped and the ``spurious`` ones (no cylinder within 0.15 m), the recovery's scans ``held``,
    relocalizations (``relocalized``) and ``stalls`` (scans), and its status ``levels`` and ``messages`` seen
    (in order, each without repeats)."""

    final_error_m: float
    final_heading_rad: float
    event_end_s: float
    landmarks: int
    spurious: int
    held: int
    relocalized: int
    stalls: int
    errors: list[tuple[float, float]] = field(default_factory=list)
    levels: list[str] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)


class _Loop:
    def __init__(self, mode: str, recovery: SlipRecoveryConfig, seed: int, model: str) -> None:
        sim_config = SimulationConfig(
            robot=model_params(model), noise=NoiseConfig(seed=seed), lidar=default_lidar()
        )
        self.sim = Simulation(sim_config)
        robot = sim_config.robot
        T_body_scan = robot.T_body_scan
        self.config = SlamConfig(
            mode=mode, sensor_x=T_body_scan.x, sensor_y=T_body_scan.y, sensor_theta=T_body_scan.theta
        )
        self.drive = robot.diff_drive()
        self.slam = EkfSlam(self.config, DiffDriveMotion(self.drive, 0.05), self.sim.T_world_body)
        if mode == "localization":
            circles = self.sim.circles
            true_map = LandmarkMap(
                "map", 0, np.arange(len(circles)), circles[:, :2], 1e-6 * np.eye(2 * len(circles))
            )
            self.slam.load_map(true_map, self.sim.T_world_body)
        turn_per_m = lost_wheel_turn_per_m(robot.track_width)
        self.recovery = SlipRecovery(replace(recovery, slip_turn_per_m=turn_per_m))
        self.timeline = SlamTimeline(self.slam, WheelAngles(), step=self.recovery)
        self.detector = LandmarkDetector(DetectorConfig())
        self.lidar = sim_config.lidar
        self.steps = 0
        self.t_ns = 0
        self.result_errors: list[tuple[float, float]] = []
        self.levels: list[str] = []
        self.messages: list[str] = []
        self.timeline.add_motion(0, tuple(self.sim.wheel_angles_rad))

    def command(self, v: float, w: float) -> None:
        self.sim.command_wheels(*self.drive.wheel_speeds(Twist2D(w, v, 0.0)))

    def step(self) -> None:
        self.sim.step(PHYSICS_DT_S)
        self.steps += 1
        self.t_ns = round(self.steps * PHYSICS_DT_S * 1e9)
        if self.steps % JOINT_EVERY == 0:
            self.timeline.add_motion(self.t_ns, tuple(self.sim.wheel_angles_rad))
        if self.steps % SCAN_EVERY == 0:
            detections = self.detector.detect(self.lidar.range_scan(self.sim.scan().range_m))
            z, _ = observations_from_points(detections.p_sensor, np.zeros((len(detections), 2, 2)))
            self.timeline.add_observations(self.t_ns, z)
            self.result_errors.append((self.t_ns * 1e-9, self.error()[0]))
            status = self.recovery.status
            if not self.levels or self.levels[-1] != status.level:
                self.levels.append(status.level)
            if not self.messages or self.messages[-1] != status.message:
                self.messages.append(status.message)

    def error(self) -> tuple[float, float]:
        T_est, _ = self.timeline.latest_pose()
        truth = self.sim.T_world_body
        return (
            float(np.hypot(T_est.x - truth.x, T_est.y - truth.y)),
            abs(math.remainder(T_est.theta - truth.theta, math.tau)),
        )

    def run_for(self, seconds: float, v: float, w: float) -> None:
        self.command(v, w)
        for _ in range(round(seconds / PHYSICS_DT_S)):
            self.step()

    def follow_circle(self, seconds: float, radius_m: float) -> None:
        """Drive counter-clockwise along the circle of ``radius_m`` about (0, radius_m), steering on the true
        pose every joint_states period (the test's driver: back onto the circle after an event)."""
        for k in range(round(seconds / PHYSICS_DT_S)):
            if k % JOINT_EVERY == 0:
                truth = self.sim.T_world_body
                # heading of the circle's tangent, turned inwards by the radial error e: psi_t + atan(2 e)
                phi = math.atan2(truth.y - radius_m, truth.x)
                error_m = math.hypot(truth.x, truth.y - radius_m) - radius_m
                heading = phi + 0.5 * math.pi + math.atan(2.0 * error_m)
                turn = math.remainder(heading - truth.theta, math.tau)
                self.command(SPEED_M_S, SPEED_M_S / radius_m + max(-TURN_RAD_S, min(TURN_RAD_S, 2.0 * turn)))
            self.step()


def run_scenario(
    event: str,
    mode: str = "mapping",
    *,
    recovery: SlipRecoveryConfig | None = None,
    seed: int = 0,
    model: str = "burger",
    radius_m: float = 0.75,
    event_s: float = 25.0,
    turn_rad: float = 0.75,
    push_s: float = 4.0,
    after_s: float = 20.0,
) -> ScenarioResult:
    """One scenario (module docstring) for the TurtleBot3 ``model``; ``recovery`` None: the default
    :class:`SlipRecoveryConfig`."""
    loop = _Loop(mode, SlipRecoveryConfig() if recovery is None else recovery, seed, model)
    w_circle = SPEED_M_S / radius_m
    loop.follow_circle(event_s, radius_m)
    if event == "phantom_turn":
        loop.sim.traction = np.zeros(2)
        loop.run_for(turn_rad / TURN_RAD_S, 0.0, TURN_RAD_S)
        loop.sim.traction = np.ones(2)
    elif event == "wheel_slip":
        # the left wheel spins on a slick patch: the wheels report turn_rad more turn than the body makes
        w_left, _ = loop.drive.wheel_speeds(Twist2D(w_circle, SPEED_M_S, 0.0))
        loop.sim.traction = np.array([0.0, 1.0])
        loop.run_for(
            turn_rad * loop.drive.track_width / (loop.drive.wheel_radius * w_left), SPEED_M_S, w_circle
        )
        loop.sim.traction = np.ones(2)
    elif event == "bump":
        _drive_into_nearest_cylinder(loop, push_s)
    elif event != "none":
        raise ValueError(f"unknown event {event!r}")
    event_end_s = loop.t_ns * 1e-9
    loop.follow_circle(after_s, radius_m)
    final_m, final_rad = loop.error()
    landmarks = loop.slam.landmarks
    circles = loop.sim.circles[:, :2]
    nearest = np.min(np.linalg.norm(landmarks[:, None, :] - circles[None, :, :], axis=2), axis=1)
    return ScenarioResult(
        final_m,
        final_rad,
        event_end_s,
        len(landmarks),
        int((nearest > 0.15).sum()),
        loop.recovery.status.held,
        loop.recovery.status.relocalized,
        loop.recovery.status.stalls,
        loop.result_errors,
        loop.levels,
        loop.messages,
    )


def _drive_into_nearest_cylinder(loop: _Loop, push_s: float) -> None:
    """Face the nearest cylinder (the test's driver knows the true pose), drive into it and push for
    ``push_s`` s, wheels spinning, then drive back and turn back onto the circle."""
    truth = loop.sim.T_world_body
    circles = loop.sim.circles
    target = circles[np.argmin(np.linalg.norm(circles[:, :2] - truth.translation, axis=1))]
    bearing = math.atan2(target[1] - truth.y, target[0] - truth.x)
    turn = math.remainder(bearing - truth.theta, math.tau)
    loop.run_for(abs(turn) / TURN_RAD_S, 0.0, math.copysign(TURN_RAD_S, turn))
    start = loop.sim.T_world_body.translation
    gap = float(np.linalg.norm(target[:2] - start)) - target[2] - loop.sim.config.robot.collision_radius
    loop.run_for(max(gap, 0.0) / SPEED_M_S + push_s, SPEED_M_S, 0.0)
    back = float(np.linalg.norm(loop.sim.T_world_body.translation - start))
    loop.run_for(back / SPEED_M_S, -SPEED_M_S, 0.0)
    loop.run_for(abs(turn) / TURN_RAD_S, 0.0, -math.copysign(TURN_RAD_S, turn))
