"""The seeded numpy world the EKF SLAM tests drive through (test_ekf_world, test_ekf_localization).

A TurtleBot3 Burger drives loops of a circle of radius 0.5 m (0.2 m/s, 0.4 rad/s) among point landmarks.
Its wheels slip as the filter's model says (a random walk, simulated with independent slip on
``SLIP_SUBSTEPS`` sub-steps of every prediction step); the LDS-01 (x = -0.032 m on the body) reports range
and bearing of every landmark within range with Gaussian noise, at 5 Hz, in random order, with optional
uniform clutter.
"""

import math

import numpy as np

from turtlelib import DiffDrive, Transform2D, Twist2D
from turtlelib.estimation.ekf_slam import EkfSlam, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.motion.motion_models import DiffDriveMotion

PI = math.pi
BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
TWIST = Twist2D(0.4, 0.2, 0.0)
SCAN_PERIOD_S = 0.2
SCAN_PERIOD_NS = 200_000_000
PREDICTIONS_PER_SCAN = 4
SLIP_SUBSTEPS = 4
N_SCANS = int(round(2.0 * PI / TWIST.omega / SCAN_PERIOD_S))  # one loop
RANGE_STD, BEARING_STD = 0.02, 0.02
WHEEL_NOISE = 0.05
MOTION = DiffDriveMotion(BURGER, WHEEL_NOISE)
CONFIG = SlamConfig(sensor_x=-0.032, range_std=RANGE_STD, bearing_std=BEARING_STD, max_range=2.5)


class World:
    """The ground truth and the sensors among ``landmarks`` (M, 2), from ``T_world_body`` (default the
    origin), drawing noise from one generator seeded ``seed``; ``clutter_per_observation`` spurious
    detections per real one (on average)."""

    def __init__(
        self,
        seed: int,
        landmarks: np.ndarray,
        clutter_per_observation: float = 0.0,
        T_world_body: Transform2D | None = None,
    ) -> None:
        self.rng = np.random.default_rng(seed)
        self.landmarks = landmarks
        self.T_world_body = Transform2D() if T_world_body is None else T_world_body
        self.clutter = clutter_per_observation
        speeds = BURGER.wheel_speeds(TWIST)
        dt = SCAN_PERIOD_S / PREDICTIONS_PER_SCAN
        self.increments = (speeds[0] * dt, speeds[1] * dt)

    def drive(self) -> tuple[float, float]:
        """Move the truth by one prediction step; returns the encoder increments (what the filter gets)."""
        for _ in range(SLIP_SUBSTEPS):
            left, right = (dphi / SLIP_SUBSTEPS for dphi in self.increments)
            slip = self.rng.normal(0.0, WHEEL_NOISE * np.sqrt(np.abs([left, right])))
            self.T_world_body = BURGER.step(self.T_world_body, left + slip[0], right + slip[1])
        return self.increments

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        """``(source, z)``: the landmark index (-1 for clutter) and [range, bearing] of each detection, in
        random order. Clutter is uniform over the disc within max_range."""
        z, _, _ = predict_observations(self.T_world_body.as_array(), self.landmarks, CONFIG.T_body_sensor)
        source = np.flatnonzero(z[:, 0] <= CONFIG.max_range)
        z = z[source] + self.rng.normal(0.0, 1.0, (len(source), 2)) * [RANGE_STD, BEARING_STD]
        n_clutter = self.rng.binomial(len(source), self.clutter) if self.clutter else 0
        clutter = np.column_stack(
            [
                CONFIG.max_range * np.sqrt(self.rng.uniform(0.01, 1.0, n_clutter)),
                self.rng.uniform(-PI, PI, n_clutter),
            ]
        )
        source = np.concatenate([source, np.full(n_clutter, -1)])
        z = np.concatenate([z, clutter])
        z[:, 1] = np.remainder(z[:, 1] + PI, 2.0 * PI) - PI
        order = self.rng.permutation(len(z))
        return source[order], z[order]

    def step(self, slam: EkfSlam) -> None:
        """The ``PREDICTIONS_PER_SCAN`` predictions between two scans."""
        for _ in range(PREDICTIONS_PER_SCAN):
            slam.predict(self.drive())
