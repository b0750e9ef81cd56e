"""Noise calibration from a recording with ground truth: maximum likelihood of the motion and measurement
errors (MRCLAM: Vicon poses and landmarks).

Measurement noise
-----------------
Each landmark observation ``z`` is compared with ``h(q_true(t), m_true)`` (the Vicon pose interpolated at
its stamp; :mod:`turtlelib.range_bearing`); the ML standard deviations of zero-mean Gaussian residuals are
``range_std = sqrt(mean(nu_r^2))`` and ``bearing_std = sqrt(mean(nu_b^2))``.

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

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from turtlelib import HeldInputs, Transform2D, TwistNoise, UnicycleMotion, normalize_angles
from turtlelib.range_bearing import predict_observations, residual

from .mrclam import MrclamRecording
from .setups import interpolate_poses

NOISE_FIELDS = tuple(f.name for f in dataclasses.fields(TwistNoise))
TRUTH_VARIANCE = np.diag([1e-6, 1e-6, 1e-6])
LOG_BOUNDS = (-30.0, 3.0)


@dataclass(frozen=True)
class Calibration:
    """The fitted noise (``noise``, ``range_std``, ``bearing_std``) and what it was fitted on."""

    noise: TwistNoise
    range_std: float
    bearing_std: float
    windows: int
    window_s: float
    observations: int
    negative_log_likelihood: float

    def params_dict(self) -> dict:
        """The ``noise:`` / ``slam:`` sections of a params YAML (``--params``)."""
        return {
            "noise": dataclasses.asdict(self.noise),
            "slam": {"range_std": self.range_std, "bearing_std": self.bearing_std},
        }

    def report(self) -> str:
        lines = [
            f"fitted on {self.windows} windows of {self.window_s} s and {self.observations} observations "
            f"(motion: sum of ln det S + e^T S^-1 e = {self.negative_log_likelihood:.1f}):"
        ]
        lines += [f"  {name:22s} {getattr(self.noise, name):.4g}" for name in NOISE_FIELDS]
        lines += [
            f"  {'range_std':22s} {self.range_std:.4g} m",
            f"  {'bearing_std':22s} {self.bearing_std:.4g} rad",
        ]
        return "\n".join(lines)


def measurement_residuals(recording: MrclamRecording) -> NDArray[np.float64]:
    """``nu = z - h(q_true, m_true)`` (K, 2) of the observations within the ground truth's time span."""
    t = recording.measurement_t_ns
    inside = (t >= recording.truth_t_ns[0]) & (t <= recording.truth_t_ns[-1])
    poses = interpolate_poses(recording.truth_t_ns, recording.truth_poses, t[inside])
    position = {int(s): xy for s, xy in zip(recording.landmark_subjects, recording.landmark_xy, strict=True)}
    landmarks = np.array([position[int(s)] for s in recording.measurement_subject[inside]]).reshape(-1, 2)
    z = np.column_stack([recording.measurement_range_m[inside], recording.measurement_bearing_rad[inside]])
    nu = np.empty_like(z)
    for k in range(len(z)):
        z_hat, _, _ = predict_observations(poses[k], landmarks[k : k + 1], Transform2D())
        nu[k] = residual(z[k], z_hat[0])
    return nu


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
    window_s: float = 2.0,
    progress: Callable[[int], None] | None = None,
) -> Calibration:
    """Fit the motion noise and the measurement noise of ``recording`` to its Vicon truth."""
    if not window_s > 0.0:
        raise ValueError(f"window must be > 0 s, got {window_s!r}")
    nu = measurement_residuals(recording)
    errors, bases = motion_windows(recording, window_s, progress)
    if len(errors) < len(NOISE_FIELDS):
        raise ValueError(
            f"only {len(errors)} windows of {window_s} s: too few to fit {len(NOISE_FIELDS)} parameters"
        )
    noise, nll = fit_motion_noise(errors, bases)
    return Calibration(
        noise=noise,
        range_std=float(np.sqrt(np.mean(nu[:, 0] ** 2))),
        bearing_std=float(np.sqrt(np.mean(nu[:, 1] ** 2))),
        windows=len(errors),
        window_s=window_s,
        observations=len(nu),
        negative_log_likelihood=nll,
    )
