"""The two datasets as experiments: which motion model, sensor mount, start pose and noise each one takes.

* **MRCLAM** (iRobot Create, commanded velocities): :class:`turtlelib.UnicycleMotion` on the held
  ``(v, omega)`` commands, taken as the robot's motion through a :class:`CommandCalibration` (the robots
  move about 0.2 s after their commands, 9 % slower and turning 6 % less); the camera is aligned with the
  body frame (sensor mount at the origin); the filter starts at the Vicon pose at the first (calibrated)
  odometry time. Known association uses the landmark subject numbers as ids.
* **Victoria Park** (utility truck): :class:`turtlelib.AckermannMotion` on the held ``(speed, steering)``
  samples, the body at the rear-axle centre, the laser (and GPS antenna) at ``(LASER_X_M, LASER_Y_M)`` in
  the body frame; unknown association. The start pose comes from the GPS only: the filter's track over the
  first ``START_WINDOW_S``, run from the identity, is rigidly aligned (least squares) to the GPS fixes of
  that time, and the residual sets the start uncertainty (protocol ``aligned``). The ``published``
  protocol starts instead from the pose the literature starts from (``PUBLISHED_T_MAP_LASER0``).

The noise (:class:`turtlelib.TwistNoise`) and the filter's options come from :class:`DatasetParams`; the
defaults (:func:`mrclam_params`, :data:`VICTORIA_PARAMS`) are explained in docs/real_data.md, and a YAML
file (``noise:`` and ``slam:`` mappings, and ``commands:`` for MRCLAM, e.g. written by the calibrate command)
replaces any of them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Self, TypeVar

import numpy as np
from numpy.typing import NDArray

from turtlelib import AckermannMotion, HeldInputs, SlamConfig, Transform2D, TwistNoise, UnicycleMotion
from turtlelib.util.timebase import NS_PER_S
from turtlelib.util.validation import finite_real, in_range, one_of, positive, store

from ..metrics import align_se2
from .experiment import ASSOCIATIONS, Experiment, Scans, run_experiment
from .mrclam import MrclamRecording
from .victoria import VictoriaRecording, gps_outliers

# Victoria Park's truck (info.txt, car.png; Guivant & Nebot 2001): wheelbase, lateral offset of the
# rear-left encoder wheel, laser position from the rear-axle centre (x forward, y left)
WHEELBASE_M = 2.83
ENCODER_Y_M = 0.76
LASER_X_M = 3.78
LASER_Y_M = 0.50
START_WINDOW_S = 60.0
# floor of the start position uncertainty (m): the GPS fixes are metre-level
GPS_MIN_STD_M = 0.5
# how the run starts and is scored (docs/real_data.md): ``aligned`` starts from the filter's first minute
# aligned to the GPS (gps_start); ``published`` starts from the literature's fixed start pose
PROTOCOLS = ("aligned", "published")
# The published start (the EKF/FastSLAM/PHD-SLAM codes on this dataset start at x0 = [-67.6493; -41.7142;
# 35.5 pi/180], some with P0 = 0): that x0 is the first GPS fix (Lo_m[0], La_m[0]) = (-67.64927, -41.71422) m,
# i.e. a pose in the GPS frame [East, North] (our map frame) with the heading CCW from East, of the point
# those codes' vehicle model tracks: the laser at (a + L, b) = (3.78, 0.50) m from the rear-axle centre,
# which is also the GPS antenna (the dataset's README, car.png). The fix is stamped 0 s, the first odometry
# sample 0.973 s, and the car stands still (speed 0) until 3.25 s, so it is also the pose at the first sample.
PUBLISHED_T_MAP_LASER0 = (-67.6493, -41.7142, math.radians(35.5))
# its heading σ: 35.5 deg lies 0.23 deg from the heading of the aligned start (35.27 deg), and the whole
# published run's best rigid alignment to the GPS turns it by 0.13 deg (docs/real_data.md); 1 deg covers
# both. Its position σ is one fix's, GPS_MIN_STD_M.
PUBLISHED_THETA_STD_RAD = math.radians(1.0)


@dataclass(frozen=True)
class CommandCalibration:
    """How a robot's commanded velocities become its motion: the command ``(v_cmd, omega_cmd)`` stamped
    ``t`` moves the robot from ``t + delay_s`` on at::

        v = speed_scale v_cmd,   omega = yaw_rate_scale omega_cmd + yaw_rate_bias

    ``delay_s`` (s) in [0, 2], the scales (> 0) and the bias (rad/s, finite); the identity by default.
    Fitted by least squares to a recording's ground truth (:func:`calibration.fit_commands`).
    """

    delay_s: float = 0.0
    speed_scale: float = 1.0
    yaw_rate_scale: float = 1.0
    yaw_rate_bias: float = 0.0

    def __post_init__(self) -> None:
        store(self, ("delay_s",), partial(in_range, low=0.0, high=2.0))
        store(self, ("speed_scale", "yaw_rate_scale"), positive)
        store(self, ("yaw_rate_bias",), finite_real)

    def apply(self, recording: MrclamRecording) -> MrclamRecording:
        """``recording`` with its commands restamped and scaled into the motion they make."""
        return dataclasses.replace(
            recording,
            odometry_t_ns=recording.odometry_t_ns + round(self.delay_s * NS_PER_S),
            odometry_v_mps=self.speed_scale * recording.odometry_v_mps,
            odometry_omega_rad_s=self.yaw_rate_scale * recording.odometry_omega_rad_s + self.yaw_rate_bias,
        )


@dataclass(frozen=True)
class DatasetParams:
    """The motion noise and the filter's configuration of one dataset."""

    noise: TwistNoise
    slam: SlamConfig

    def replaced(self, values: dict) -> Self:
        """A copy with ``values[section]`` (mappings of field names) replacing fields of its sections
        (``noise``, ``slam`` and, for MRCLAM, ``commands``); ValueError for an unknown section or field (and
        for invalid values)."""
        names = [f.name for f in dataclasses.fields(self)]
        unknown = set(values) - set(names)
        if unknown:
            raise ValueError(f"unknown parameter sections {sorted(unknown)} (expected {', '.join(names)})")
        sections = {}
        for name in names:
            current = getattr(self, name)
            section = values.get(name) or {}
            if not isinstance(section, dict):
                raise ValueError(f"{name}: expected a mapping of parameters, got {section!r}")
            fields = {f.name for f in dataclasses.fields(current)}
            extra = set(section) - fields
            if extra:
                raise ValueError(f"{name}: unknown parameters {sorted(extra)}")
            sections[name] = dataclasses.replace(current, **section)
        return dataclasses.replace(self, **sections)

    def as_dict(self) -> dict:
        return {f.name: dataclasses.asdict(getattr(self, f.name)) for f in dataclasses.fields(self)}


@dataclass(frozen=True)
class MrclamParams(DatasetParams):
    """:class:`DatasetParams` and the robot's :class:`CommandCalibration`."""

    commands: CommandCalibration = CommandCalibration()


Params = TypeVar("Params", bound=DatasetParams)


def load_params(defaults: Params, path: str | Path | None) -> Params:
    """``defaults`` with the values of the YAML file at ``path`` (none: the defaults)."""
    if path is None:
        return defaults
    import yaml

    try:
        with open(path, encoding="utf-8") as stream:
            values = yaml.safe_load(stream) or {}
    except (OSError, yaml.YAMLError) as error:
        raise ValueError(f"{path}: not a readable params file: {error}") from error
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected a mapping of parameter sections (noise:, slam:, ...)")
    try:
        return defaults.replaced(values)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{path}: {error}") from error


# MRCLAM robot 1 (Dataset 7), from `calibrate mrclam --robot 1` (docs/real_data.md): the only tuning.
# The right-invariant EKF: an honest heading with Jacobians at the newest estimates
MRCLAM_PARAMS = MrclamParams(
    commands=CommandCalibration(
        delay_s=0.19, speed_scale=0.9238, yaw_rate_scale=0.9341, yaw_rate_bias=-3.82e-3
    ),
    noise=TwistNoise(
        forward_m2_per_m=6.99e-3,
        forward_m2_per_s=0.0,
        lateral_m2_per_m=1.47e-4,
        heading_rad2_per_m=2.37e-3,
        heading_rad2_per_rad=1.07e-2,
        heading_rad2_per_s=0.0,
    ),
    slam=SlamConfig(
        range_std=0.0238,
        range_std_per_m=0.0293,
        bearing_std=0.0275,
        noise_correlation=0.906,
        noise_correlation_length=0.323,
        max_range=10.0,
        initial_xy_std=0.001,
        initial_theta_std=0.001,
        linearization="invariant",
        gate_known=0.9999,
        gate_associate=0.99,
        gate_new=0.9999,
        confirm_count=3,
        tentative_timeout=30.0,
    ),
)
# unknown association pairs observations by joint compatibility (JCBB): the tubes stand in pairs 0.18 m apart,
# and it takes the errors as independent: with the honest (wider) covariance of the correlated model the
# gates admit both tubes of a pair, and fewer are mapped once (docs/real_data.md)
MRCLAM_UNKNOWN_PARAMS = MRCLAM_PARAMS.replaced(
    {"slam": {"matcher": "jcbb", "noise_correlation": 0.0, "noise_correlation_length": 0.0}}
)


def mrclam_params(association: str) -> MrclamParams:
    """The MRCLAM defaults for ``association`` (``known`` or ``unknown``)."""
    one_of("association", association, ASSOCIATIONS)
    return MRCLAM_PARAMS if association == "known" else MRCLAM_UNKNOWN_PARAMS


# Victoria Park: the measurement noise and range limit of the published EKF setups, the motion noise from
# MRCLAM's fitted structure scaled to a car (docs/real_data.md); nothing here is fitted to Victoria Park
VICTORIA_PARAMS = DatasetParams(
    noise=TwistNoise(
        forward_m2_per_m=0.01,
        forward_m2_per_s=0.0,
        lateral_m2_per_m=0.001,
        heading_rad2_per_m=2e-4,
        heading_rad2_per_rad=0.01,
        heading_rad2_per_s=1e-5,
    ),
    slam=SlamConfig(
        range_std=0.5,
        bearing_std=math.radians(1.5),
        sensor_x=LASER_X_M,
        sensor_y=LASER_Y_M,
        max_range=30.0,
        linearization="invariant",
        matcher="jcbb",
        gate_associate=0.99,
        gate_new=0.9999,
        confirm_count=3,
        tentative_timeout=3.0,
    ),
)


def mrclam_experiment(recording: MrclamRecording, params: MrclamParams, association: str) -> Experiment:
    """MRCLAM robot ``recording.robot`` (module docstring), its commands through ``params.commands``;
    ``association`` is ``known`` or ``unknown``."""
    one_of("association", association, ASSOCIATIONS)
    recording = params.commands.apply(recording)
    t0 = recording.odometry_t_ns[0]
    truth = recording.truth_t_ns
    if not truth[0] <= t0 <= truth[-1]:
        raise ValueError("the ground truth does not cover the first odometry time")
    start = interpolate_poses(truth, recording.truth_poses, np.array([t0]))[0]
    z = np.column_stack([recording.measurement_range_m, recording.measurement_bearing_rad])
    ids = recording.measurement_subject if association == "known" else None
    return Experiment(
        name=f"MRCLAM robot {recording.robot} ({association} association)",
        motion=UnicycleMotion(params.noise),
        signal=HeldInputs(),
        motion_t_ns=recording.odometry_t_ns,
        motion_samples=np.column_stack([recording.odometry_v_mps, recording.odometry_omega_rad_s]),
        scans=Scans.from_rows(recording.measurement_t_ns, z, ids),
        T_map_body0=Transform2D(*start),
        config=params.slam,
    )


def victoria_experiment(
    recording: VictoriaRecording, params: DatasetParams, protocol: str = "aligned"
) -> Experiment:
    """The Victoria Park run (module docstring), unknown association, started from the GPS: by
    :func:`gps_start` (``protocol`` ``aligned``) or at :func:`published_start` (``published``) with the
    position σ of one GPS fix, ``GPS_MIN_STD_M``, and the heading σ ``PUBLISHED_THETA_STD_RAD``."""
    one_of("protocol", protocol, PROTOCOLS)
    motion = AckermannMotion(WHEELBASE_M, ENCODER_Y_M, params.noise)
    samples = np.column_stack([recording.speed_mps, recording.steering_rad])
    z = np.column_stack([recording.detection_range_m, recording.detection_bearing_rad])
    config = dataclasses.replace(params.slam, sensor_x=LASER_X_M, sensor_y=LASER_Y_M, sensor_theta=0.0)
    run = Experiment(
        name="Victoria Park (unknown association)",
        motion=motion,
        signal=HeldInputs(),
        motion_t_ns=recording.odometry_t_ns,
        motion_samples=samples,
        scans=Scans.from_rows(recording.detection_t_ns, z),
        T_map_body0=Transform2D(),
        config=dataclasses.replace(config, initial_xy_std=0.0, initial_theta_std=0.0),
    )
    if protocol == "published":
        T_map_body0, xy_std, theta_std = published_start(), GPS_MIN_STD_M, PUBLISHED_THETA_STD_RAD
        run = dataclasses.replace(run, name="Victoria Park (unknown association, published protocol)")
    else:
        T_map_body0, xy_std, theta_std = gps_start(run, recording)
    return dataclasses.replace(
        run,
        T_map_body0=T_map_body0,
        config=dataclasses.replace(config, initial_xy_std=xy_std, initial_theta_std=theta_std),
    )


def gps_start(run: Experiment, recording: VictoriaRecording) -> tuple[Transform2D, float, float]:
    """``(T_map_body0, xy_std, theta_std)`` from the GPS: ``run`` (which starts at the identity) filtered
    over its first ``START_WINDOW_S``, its laser track aligned rigidly to the (outlier-free) GPS fixes of
    that time.

    The filter's track rather than dead reckoning: the trees hold its heading, while the steering-angle
    odometry drifts by degrees within a minute, and that drift would rotate the whole map frame.
    ``xy_std`` is the RMS residual (at least ``GPS_MIN_STD_M``), ``theta_std`` that residual over the RMS
    spread of the track (the rotation a residual of that size leaves undetermined). ValueError if fewer
    than 3 fixes fall in the window."""
    t_ns = run.motion_t_ns
    end_ns = t_ns[0] + round(START_WINDOW_S * NS_PER_S)
    k_end = int(np.searchsorted(t_ns, end_ns, side="right"))
    window = dataclasses.replace(
        run,
        motion_t_ns=t_ns[:k_end],
        motion_samples=run.motion_samples[:k_end],
        scans=run.scans.until(end_ns),
    )
    result = run_experiment(window)
    track, _ = laser_points(result.track)
    # the fixes the track spans (it ends at the window's last scan)
    inside = (recording.gps_t_ns >= result.track_t_ns[0]) & (recording.gps_t_ns <= result.track_t_ns[-1])
    fixes = inside & ~gps_outliers(recording.gps_t_ns, recording.gps_xy)
    if fixes.sum() < 3:
        raise ValueError(f"fewer than 3 GPS fixes in the first {START_WINDOW_S} s: cannot place the start")
    at_fixes = np.column_stack(
        [np.interp(recording.gps_t_ns[fixes], result.track_t_ns, track[:, i]) for i in range(2)]
    )
    T_map_odo = align_se2(at_fixes, recording.gps_xy[fixes])
    residual = np.linalg.norm(T_map_odo @ at_fixes - recording.gps_xy[fixes], axis=1)
    rms = float(np.sqrt(np.mean(residual**2)))
    spread = float(np.sqrt(np.mean(np.sum((at_fixes - at_fixes.mean(axis=0)) ** 2, axis=1))))
    return T_map_odo @ run.T_map_body0, max(rms, GPS_MIN_STD_M), rms / max(spread, 1.0)


def published_start() -> Transform2D:
    """``T_map_body0`` of the published start: the laser pose ``T_map_laser0`` (``PUBLISHED_T_MAP_LASER0``)
    moved to the rear-axle centre, ``T_map_body0 = T_map_laser0 T_body_laser^-1`` with
    ``T_body_laser = (LASER_X_M, LASER_Y_M, 0)``: the same heading, and the position
    ``p_laser - R(theta) [a, b]``."""
    return Transform2D(*PUBLISHED_T_MAP_LASER0) @ Transform2D(LASER_X_M, LASER_Y_M, 0.0).inverse()


def laser_points(
    poses: NDArray[np.float64], covariances: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """The laser's position (S, 2) for body poses (S, 3) and, given their covariances (S, 3, 3), its
    covariance (S, 2, 2) ``J P J^T`` (else None)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    # r = R(theta) [a, b]
    r = np.column_stack([c * LASER_X_M - s * LASER_Y_M, s * LASER_X_M + c * LASER_Y_M])
    if covariances is None:
        return poses[:, :2] + r, None
    J = np.zeros((len(poses), 2, 3))
    J[:, 0, 0] = J[:, 1, 1] = 1.0
    J[:, 0, 2], J[:, 1, 2] = -r[:, 1], r[:, 0]
    return poses[:, :2] + r, J @ covariances @ J.transpose(0, 2, 1)


def interpolate_poses(
    t_ns: NDArray[np.int64], poses: NDArray[np.float64], query_ns: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Poses (Q, 3) at ``query_ns`` within ``t_ns``: x, y linear, heading linear when unwrapped."""
    t0 = t_ns[0]
    t, query = (t_ns - t0) * 1e-9, (np.asarray(query_ns) - t0) * 1e-9
    theta = np.interp(query, t, np.unwrap(poses[:, 2]))
    return np.column_stack([np.interp(query, t, poses[:, 0]), np.interp(query, t, poses[:, 1]), theta])
