"""Benchmark: EkfSlam's scan rate (unknown association, eight landmarks in view) before and after a flood
of observations whose tentative landmarks all expire (docs/reliability.md).

The flood: 1,000 distinct points (a 15 cm grid around the robot, away from the real landmarks) in ten
arrays of ``max_observations`` (100), all at one instant; each starts a tentative landmark, and every one
of them expires ``tentative_timeout`` (2 s) later, leaving the eight real ones. Reports the scans per
second of CPU time before the flood and after, and the storage's capacity (landmark slots).

Usage: python -P bench/slam_flood.py [--scans 400]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS

import argparse
import time

import numpy as np

from turtlelib import DiffDrive
from turtlelib.estimation.ekf_slam import EkfSlam, SlamConfig
from turtlelib.motion.motion_models import DiffDriveMotion

S = 10**9
SCAN_NS = S // 5
LANDMARKS = np.array(
    [[1.0, 0.5], [1.5, -0.8], [-1.2, 1.1], [0.3, 1.7], [-0.9, -1.3], [2.0, 0.2], [-1.8, 0.0], [0.5, -1.9]]
)


def range_bearing(points: np.ndarray) -> np.ndarray:
    return np.column_stack([np.hypot(points[:, 0], points[:, 1]), np.arctan2(points[:, 1], points[:, 0])])


class Run:
    """A standing robot (no sensor offset) that sees ``LANDMARKS`` with 1 cm / 0.01 rad noise every scan."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.slam = EkfSlam(SlamConfig(), DiffDriveMotion(DiffDrive(0.033, 0.16), 0.05))
        self.t_ns = 0

    def scan(self) -> None:
        self.t_ns += SCAN_NS
        self.slam.predict((0.0, 0.0))
        z = range_bearing(LANDMARKS) + self.rng.normal(0.0, 0.01, LANDMARKS.shape)
        self.slam.update_unknown(z, stamp_ns=self.t_ns)

    def rate(self, scans: int) -> float:
        start = time.process_time()
        for _ in range(scans):
            self.scan()
        return scans / (time.process_time() - start)

    @property
    def capacity(self) -> int:
        """The filter's storage in landmark slots (what every full update spans); read from its state."""
        return self.slam._state.capacity_landmarks

    def flood(self) -> None:
        gx, gy = np.meshgrid(np.arange(-2.5, 2.5, 0.15), np.arange(-2.5, 2.5, 0.15))
        grid = np.column_stack([gx.ravel(), gy.ravel()])
        apart = np.min(np.linalg.norm(grid[:, None, :] - LANDMARKS[None], axis=2), axis=1) > 0.3
        grid = grid[apart & (np.hypot(grid[:, 0], grid[:, 1]) > 0.3)][:1000]
        for k in range(0, len(grid), 100):
            self.t_ns += 1
            self.slam.update_unknown(range_bearing(grid[k : k + 100]), stamp_ns=self.t_ns)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=400, help="scans timed before and after the flood")
    args = parser.parse_args()
    run = Run()
    for _ in range(50):  # every real landmark confirmed
        run.scan()
    print(f"before the flood: {run.rate(args.scans):.0f} scans/s, capacity {run.capacity} landmarks")
    run.flood()
    peak = len(run.slam.tentative_ids)
    print(f"flood: {peak} tentative landmarks, capacity {run.capacity}")
    for _ in range(20):  # 4 s: past tentative_timeout
        run.scan()
    left = f"{len(run.slam.tentative_ids)} tentative, {len(run.slam.landmark_ids)} confirmed"
    rate = run.rate(args.scans)
    print(f"after the flood ({left}): {rate:.0f} scans/s, capacity {run.capacity}")


if __name__ == "__main__":
    main()
