"""Calibration from a recording with ground truth (MRCLAM: Vicon poses and landmarks): how the commands
move the robot (least squares), then the motion and measurement noise (maximum likelihood).

Commands
--------
With the held commands integrated, ``psi(t) = int omega_cmd`` (piecewise linear, exact at any time by
interpolation), a :class:`setups.CommandCalibration` is fitted in two steps:

* ``delay_s``: on a grid of ``DELAY_STEP_S`` up to ``MAX_DELAY_S``, the one whose commands, shifted by it,
  best explain the true heading increments over short windows of ``DELAY_WINDOW_S`` (least squares with a
  scale and an offset per grid point; the smallest residual wins);
* with that delay, over windows of ``window_s``: ``dtheta_true = yaw_rate_scale dpsi + yaw_rate_bias dt``
  and ``dp_true = speed_scale D`` (least squares), with ``D`` the commanded travel ``v_cmd dt`` of each
  command interval along the true heading at its middle, summed over the window (exact to O(dt^2)).

Measurement noise
-----------------
Each landmark observation ``z`` is compared with ``h(q_true(t), m_true)`` (the Vicon pose interpolated at
its stamp; :mod:`turtlelib.estimation.range_bearing`). The residuals are taken as zero-mean Gaussians; the
bearing's ML standard deviation is ``bearing_std = sqrt(mean(nu_b^2))``, and the range's grows with the
observed range ``r`` (``SlamConfig``: ``sigma_r = range_std + range_std_per_m r``, ``range_std_per_m >= 0``),
fitted by::

    argmin  sum_k ln sigma_r(r_k)^2 + nu_rk^2 / sigma_r(r_k)^2     (L-BFGS-B over the two parameters)

The errors of one landmark's successive observations are correlated through the viewpoint
(``SlamConfig.noise_correlation``): with the residuals whitened by the fitted standard deviations,
``w = [nu_r / sigma_r, nu_b / bearing_std]``, and ``d_k`` the distance the (true) sensor moved between two
successive sightings of a landmark, ``E[w_(k-1) w_k] = c exp(-d_k / l)`` (range and bearing pooled) gives
``noise_correlation = c`` and ``noise_correlation_length = l`` by least squares over every such pair
(``c <= MAX_CORRELATION``).

Motion noise
------------
The run is cut into windows of ``window_s``. In window ``w`` the motion model is run from the true pose at
its start over the window's inputs, giving the predicted end pose ``q_hat_w`` and, because every model's
``Q`` is linear in the :class:`turtlelib.TwistNoise` parameters ``theta_i``,
``P_w(theta) = sum_i theta_i B_wi`` (each ``B_wi`` propagated with ``P <- G P G^T + Q_i`` from the unit noise
of parameter ``i``). With the end error ``e_w = q_true - q_hat_w`` (heading wrapped) the parameters
maximise the likelihood of the windows::

    theta* = argmin_theta sum_w  ln det S_w + e_w^T S_w^-1 e_w,   S_w = P_w(theta) + Sigma_truth

(``Sigma_truth``: the Vicon's 1 mm / 1 mrad), over ``ln theta`` (so theta >= 0) by L-BFGS-B.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares, minimize

from turtlelib import HeldInputs, Transform2D, TwistNoise, UnicycleMotion, normalize_angles
from turtlelib.estimation.range_bearing import predict_observations, residual
from turtlelib.util.timebase import NS_PER_S

from .mrclam import MrclamRecording
from .setups import CommandCalibration, interpolate_poses

NOISE_FIELDS = tuple(f.name for f in dataclasses.fields(TwistNoise))
TRUTH_VARIANCE = np.diag([1e-6, 1e-6, 1e-6])
LOG_BOUNDS = (-30.0, 3.0)
DELAY_STEP_S = 0.01
MAX_DELAY_S = 0.5
DELAY_WINDOW_S = 0.5
# the largest error correlation the fit returns (SlamConfig.noise_correlation < 1)
MAX_CORRELATION = 0.99


@dataclass(frozen=True)
class Calibration:
    """The fitted commands and noise (``noise``, ``range_std``, ``range_std_per_m``, ``bearing_std``,
    ``noise_correlation``, ``noise_correlation_length``), and what they were fitted on."""

    commands: CommandCalibration
    noise: TwistNoise
    range_std: float
    range_std_per_m: float
    bearing_std: float
    noise_correlation: float
    noise_correlation_length: float
    windows: int
    window_s: float
    observations: int
    negative_log_likelihood: float

    def params_dict(self) -> dict:
        """The ``commands:`` / ``noise:`` / ``slam:`` sections of a params YAML (``--params``)."""
        return {
            "commands": dataclasses.asdict(self.commands),
            "noise": dataclasses.asdict(self.noise),
            "slam": {
                "range_std": self.range_std,
                "range_std_per_m": self.range_std_per_m,
                "bearing_std": self.bearing_std,
                "noise_correlation": self.noise_correlation,
                "noise_correlation_length": self.noise_correlation_length,
            },
        }

    def report(self) -> str:
        lines = [
            f"fitted on {self.windows} windows of {self.window_s} s and {self.observations} observations "
            f"(motion: sum of ln det S + e^T S^-1 e = {self.negative_log_likelihood:.1f}):"
        ]
        lines += [f"  {name:24s} {value:.4g}" for name, value in dataclasses.asdict(self.commands).items()]
        lines += [f"  {name:24s} {getattr(self.noise, name):.4g}" for name in NOISE_FIELDS]
        lines += [
            f"  {'range_std':24s} {self.range_std:.4g} m",
            f"  {'range_std_per_m':24s} {self.range_std_per_m:.4g} m/m",
            f"  {'bearing_std':24s} {self.bearing_std:.4g} rad",
            f"  {'noise_correlation':24s} {self.noise_correlation:.4g}",
            f"  {'noise_correlation_length':24s} {self.noise_correlation_length:.4g} m",
        ]
        return "\n".join(lines)


class Residuals(NamedTuple):
    """The observations within the ground truth's time span, in time order: the landmark ``subject`` (K,),
    the true sensor position ``sensor_xy`` (K, 2) (the camera sits at the body origin), the observed
    ``range_m`` (K,) and ``nu = z - h(q_true, m_true)`` (K, 2)."""

    subject: NDArray[np.int64]
    sensor_xy: NDArray[np.float64]
    range_m: NDArray[np.float64]
    nu: NDArray[np.float64]


def measurement_residuals(recording: MrclamRecording) -> Residuals:
    """The :class:`Residuals` of ``recording``'s landmark observations against its ground truth."""
    t = recording.measurement_t_ns
    inside = (t >= recording.truth_t_ns[0]) & (t <= recording.truth_t_ns[-1])
    poses = interpolate_poses(recording.truth_t_ns, recording.truth_poses, t[inside])
    position = {int(s): xy for s, xy in zip(recording.landmark_subjects, recording.landmark_xy, strict=True)}
    subject = recording.measurement_subject[inside]
    landmarks = np.array([position[int(s)] for s in subject]).reshape(-1, 2)
    z = np.column_stack([recording.measurement_range_m[inside], recording.measurement_bearing_rad[inside]])
    nu = np.empty_like(z)
    for k in range(len(z)):
        z_hat, _, _ = predict_observations(poses[k], landmarks[k : k + 1], Transform2D())
        nu[k] = residual(z[k], z_hat[0])
    return Residuals(subject, poses[:, :2], z[:, 0], nu)


def fit_range_noise(range_m: NDArray[np.float64], nu_range: NDArray[np.float64]) -> tuple[float, float]:
    """The ML ``(range_std, range_std_per_m)`` of range residuals ``nu_range`` (K,) at ranges ``range_m``
    (K,) (module docstring); ValueError for fewer than 2 observations."""
    if len(range_m) < 2:
        raise ValueError(f"{len(range_m)} observations: too few to fit the range noise")

    def cost(parameters: NDArray[np.float64]) -> float:
        variance = (parameters[0] + parameters[1] * range_m) ** 2
        return float(np.sum(np.log(variance) + nu_range**2 / variance))

    rms = float(np.sqrt(np.mean(nu_range**2)))
    floor = 1e-6 * max(rms, 1e-9)
    best = minimize(cost, [rms, 0.0], method="L-BFGS-B", bounds=[(floor, None), (0.0, None)])
    return float(best.x[0]), float(best.x[1])


def fit_noise_correlation(
    residuals: Residuals, range_std: float, range_std_per_m: float, bearing_std: float
) -> tuple[float, float]:
    """The least-squares ``(noise_correlation, noise_correlation_length)`` of the observation errors
    (module docstring); ValueError without two sightings of one landmark."""
    sigma = np.column_stack(
        [range_std + range_std_per_m * residuals.range_m, np.full(len(residuals.range_m), bearing_std)]
    )
    w = residuals.nu / sigma
    moved, products = [], []
    for subject in np.unique(residuals.subject):
        k = np.flatnonzero(residuals.subject == subject)
        moved.append(np.linalg.norm(np.diff(residuals.sensor_xy[k], axis=0), axis=1))
        products.append(w[k[:-1]] * w[k[1:]])
    if sum(len(m) for m in moved) == 0:
        raise ValueError("no landmark seen twice: the error correlation cannot be fitted")
    d = np.repeat(np.concatenate(moved), 2)
    p = np.concatenate(products).ravel()

    # E[w_(k-1) w_k] = c exp(-d / l)
    def misfit(parameters: NDArray[np.float64]) -> NDArray[np.float64]:
        c, length = parameters
        return c * np.exp(-d / length) - p

    start = [0.5, float(np.clip(np.median(d), 1e-3, 1e2))]
    fit = least_squares(misfit, start, bounds=([0.0, 1e-4], [MAX_CORRELATION, 1e3]))
    return float(fit.x[0]), float(fit.x[1])


def fit_commands(recording: MrclamRecording, window_s: float) -> CommandCalibration:
    """The :class:`setups.CommandCalibration` of ``recording`` by least squares (module docstring)."""
    t = recording.odometry_t_ns
    dt_s = np.diff(t) / NS_PER_S
    # psi at each command stamp: the held yaw-rate commands integrated (exact, piecewise linear in time)
    psi = np.r_[0.0, np.cumsum(recording.odometry_omega_rad_s[:-1] * dt_s)]
    first = max(int(t[0]) + round(MAX_DELAY_S * NS_PER_S), int(recording.truth_t_ns[0]))
    last = min(int(t[-1]), int(recording.truth_t_ns[-1]))

    def windows(length_s: float) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        edges = np.arange(first, last, round(length_s * NS_PER_S), dtype=np.int64)
        if len(edges) < 4:
            raise ValueError(f"the recording's ground truth spans too few {length_s} s windows")
        return edges, interpolate_poses(recording.truth_t_ns, recording.truth_poses, edges)

    edges, truth = windows(DELAY_WINDOW_S)
    dtheta = np.diff(np.unwrap(truth[:, 2]))
    best = (np.inf, 0.0)
    for delay_s in np.arange(0.0, MAX_DELAY_S + 0.5 * DELAY_STEP_S, DELAY_STEP_S):
        # the commands that act on [a, b] were stamped delay_s earlier
        dpsi = np.diff(np.interp(edges - round(delay_s * NS_PER_S), t, psi))
        A = np.column_stack([dpsi, np.ones_like(dpsi)])
        misfit = dtheta - A @ np.linalg.lstsq(A, dtheta, rcond=None)[0]
        best = min(best, (float(misfit @ misfit), float(delay_s)))
    delay_s = best[1]
    delay_ns = round(delay_s * NS_PER_S)

    edges, truth = windows(window_s)
    t_acting = t + delay_ns
    dtheta = np.diff(np.unwrap(truth[:, 2]))
    dpsi = np.diff(np.interp(edges, t_acting, psi))
    # dtheta = yaw_rate_scale dpsi + yaw_rate_bias dt
    (yaw_rate_scale, yaw_rate_bias), *_ = np.linalg.lstsq(
        np.column_stack([dpsi, np.diff(edges) / NS_PER_S]), dtheta, rcond=None
    )
    # dp = speed_scale D: D the commanded travel of each interval along the true heading at its middle
    middle = interpolate_poses(
        recording.truth_t_ns, recording.truth_poses, t_acting[:-1] + np.diff(t_acting) // 2
    )[:, 2]
    step = recording.odometry_v_mps[:-1] * dt_s
    D = np.zeros((len(t), 2))
    D[1:] = np.cumsum(step[:, None] * np.column_stack([np.cos(middle), np.sin(middle)]), axis=0)
    dD = np.diff(np.column_stack([np.interp(edges, t_acting, D[:, i]) for i in range(2)]), axis=0)
    dp = np.diff(truth[:, :2], axis=0)
    speed_scale = float(np.sum(dD * dp) / np.sum(dD * dD))
    return CommandCalibration(delay_s, speed_scale, float(yaw_rate_scale), float(yaw_rate_bias))


def motion_windows(
    recording: MrclamRecording, window_s: float, progress: Callable[[int], None] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(e (W, 3), B (W, p, 3, 3))``: the end error of each window and the covariance of each unit noise
    parameter (module docstring)."""
    t = recording.odometry_t_ns
    inside = (t >= recording.truth_t_ns[0]) & (t <= recording.truth_t_ns[-1])
    t = t[inside]
    samples = np.column_stack([recording.odometry_v_mps, recording.odometry_omega_rad_s])[inside]
    truth = interpolate_poses(recording.truth_t_ns, recording.truth_poses, t)
    mean_model = UnicycleMotion(TwistNoise())
    unit_models = [UnicycleMotion(TwistNoise(**{name: 1.0})) for name in NOISE_FIELDS]
    signal = HeldInputs()
    window_ns = round(window_s * 1e9)
    errors, bases = [], []
    k_start = 0
    while True:
        k_end = int(np.searchsorted(t, t[k_start] + window_ns, side="left"))
        if k_end >= len(t):
            break
        T = Transform2D(*truth[k_start])
        B = np.zeros((len(unit_models), 3, 3))
        for k in range(k_start, k_end):
            u = signal.input(tuple(samples[k]), tuple(samples[k + 1]), int(t[k + 1] - t[k]))
            if u is None:
                continue
            q, G, _ = mean_model.step(T, u)
            for i, model in enumerate(unit_models):
                # P_i <- G P_i G^T + Q_i
                B[i] = G @ B[i] @ G.T + model.step(T, u)[2]
            T = Transform2D(*q)
        error = truth[k_end] - T.as_array()
        error[2] = normalize_angles(error[2:3])[0]
        errors.append(error)
        bases.append(B)
        if progress is not None:
            progress(k_end - k_start)
        k_start = k_end
    return np.array(errors), np.array(bases)


def fit_motion_noise(errors: NDArray[np.float64], bases: NDArray[np.float64]) -> tuple[TwistNoise, float]:
    """The ML ``TwistNoise`` for window errors (W, 3) and unit covariances (W, p, 3, 3); returns it and the
    minimised ``sum_w ln det S_w + e_w^T S_w^-1 e_w``."""

    def cost(log_theta: NDArray[np.float64]) -> float:
        S = np.einsum("i,wijk->wjk", np.exp(log_theta), bases) + TRUTH_VARIANCE
        _, log_det = np.linalg.slogdet(S)
        mahalanobis = np.einsum("wi,wi->w", errors, np.linalg.solve(S, errors[..., None])[..., 0])
        return float(np.sum(log_det + mahalanobis))

    start = np.full(bases.shape[1], np.log(1e-3))
    best = minimize(cost, start, method="L-BFGS-B", bounds=[LOG_BOUNDS] * len(start))
    theta = np.exp(best.x)
    # parameters pinned at the lower bound are zero (that noise source is not in the data)
    theta[best.x <= LOG_BOUNDS[0] + 1e-6] = 0.0
    return TwistNoise(**dict(zip(NOISE_FIELDS, theta.tolist(), strict=True))), float(best.fun)


def calibrate_mrclam(
    recording: MrclamRecording,
    window_s: float,
    progress: Callable[[int], None] | None = None,
) -> Calibration:
    """Fit how the commands move the robot, then the motion noise of the calibrated commands and the
    measurement noise of ``recording`` to its Vicon truth."""
    if not window_s > 0.0:
        raise ValueError(f"window must be > 0 s, got {window_s!r}")
    residuals = measurement_residuals(recording)
    nu = residuals.nu
    range_std, range_std_per_m = fit_range_noise(residuals.range_m, nu[:, 0])
    bearing_std = float(np.sqrt(np.mean(nu[:, 1] ** 2)))
    correlation, correlation_length = fit_noise_correlation(
        residuals, range_std, range_std_per_m, bearing_std
    )
    commands = fit_commands(recording, window_s)
    errors, bases = motion_windows(commands.apply(recording), window_s, progress)
    if len(errors) < len(NOISE_FIELDS):
        raise ValueError(
            f"only {len(errors)} windows of {window_s} s: too few to fit {len(NOISE_FIELDS)} parameters"
        )
    noise, nll = fit_motion_noise(errors, bases)
    return Calibration(
        commands=commands,
        noise=noise,
        range_std=range_std,
        range_std_per_m=range_std_per_m,
        bearing_std=bearing_std,
        noise_correlation=correlation,
        noise_correlation_length=correlation_length,
        windows=len(errors),
        window_s=window_s,
        observations=len(nu),
        negative_log_likelihood=nll,
    )
