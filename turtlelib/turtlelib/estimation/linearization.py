"""Where EKF SLAM takes its Jacobians: the consistency strategies of
:class:`turtlelib.estimation.ekf_slam.EkfSlam`.

A strategy gives the filter the propagation Jacobian of a prediction and the observation Jacobians of an
update (:mod:`turtlelib.estimation.ekf_slam`'s module docstring has the maths):

* :class:`Standard`: both at the newest estimates.
* :class:`FirstEstimates` (``'fej'``): ``G`` at the motion from the last pose prior ``p = q_(k|k-1)``,
  ``G + J (p_(k|k) - p_(k|k-1))`` in its heading column, and ``H`` at ``p`` and the landmarks' first
  estimates.
* :class:`ObservabilityConstrained` (``'oc'``): the same ``G``; ``H`` at the newest estimates projected
  onto the closest Jacobian with ``H N = 0``.
* :class:`Invariant` (``'invariant'``): the right-invariant EKF; the state stores ``P`` in invariant
  coordinates and ``H`` becomes ``H T``.

FEJ and OC own their first estimates: a ``first_xy`` column of the slots' records
(:class:`turtlelib.estimation.landmark_tracks.LandmarkTracks`), set when a landmark is added and reset past
``relinearize_gate``, and the pose prior of the last prediction. :data:`LINEARIZATIONS` maps the
``linearization`` parameter to a strategy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from .matching import gate_2d, mahalanobis_2d
from .measurement_models import MeasurementModel
from .slam_state import HEADING, ROBOT_DIM, J, SlamState

Observations = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


class Linearization(Protocol):
    """What :class:`turtlelib.estimation.ekf_slam.EkfSlam` asks of a linearisation strategy."""

    #: whether the state keeps ``P`` in the right-invariant coordinates
    invariant: bool

    def start(self, state: SlamState) -> None:
        """A new or relocalised ``state``: the pose prior is its pose; the records get the strategy's
        columns."""
        ...

    def propagation_jacobian(self, state: SlamState, G: NDArray[np.float64]) -> NDArray[np.float64]:
        """The ``G`` (3, 3) a prediction from ``state`` applies, given the model's."""
        ...

    def predicted(self, pose_prior: NDArray[np.float64]) -> None:
        """A prediction reached ``pose_prior`` (3,), the prior ``q_(k|k-1)`` of the next updates."""
        ...

    def observe(self, state: SlamState, model: MeasurementModel, slots: NDArray[np.int64]) -> Observations:
        """``z_hat`` (k, 2) of landmark ``slots`` (k,) at the newest estimates and the update's Jacobians
        ``H_robot`` (k, 2, 3), ``H_landmark`` (k, 2, 2)."""
        ...

    def added(self, state: SlamState, slots: NDArray[np.int64]) -> None:
        """Landmark ``slots`` were just added to ``state``."""
        ...

    def fused(self, state: SlamState, slots: NDArray[np.int64]) -> None:
        """An update fused observations of ``slots``."""
        ...


class Standard:
    """Jacobians at the newest estimates."""

    invariant = False

    def start(self, state: SlamState) -> None:
        pass

    def propagation_jacobian(self, state: SlamState, G: NDArray[np.float64]) -> NDArray[np.float64]:
        return G

    def predicted(self, pose_prior: NDArray[np.float64]) -> None:
        pass

    def observe(self, state: SlamState, model: MeasurementModel, slots: NDArray[np.int64]) -> Observations:
        return model.predict(state.mean[:ROBOT_DIM], state.landmark_positions()[slots])

    def added(self, state: SlamState, slots: NDArray[np.int64]) -> None:
        pass

    def fused(self, state: SlamState, slots: NDArray[np.int64]) -> None:
        pass


class Invariant(Standard):
    """The right-invariant EKF: ``P`` in invariant coordinates, ``H_xi = H T``: the heading column gains
    ``H_p J p + H_m J m`` (zero for a measurement that turns with pose and landmark, to rounding)."""

    invariant = True

    def observe(self, state: SlamState, model: MeasurementModel, slots: NDArray[np.int64]) -> Observations:
        pose = state.mean[:ROBOT_DIM]
        landmarks = state.landmark_positions()[slots]
        z_hat, H_robot, H_landmark = model.predict(pose, landmarks)
        # H T: the heading column gains H_p J p + H_m J m
        H_robot[:, :, HEADING] += H_robot[:, :, :2] @ (J @ pose[:2]) + np.einsum(
            "kij,kj->ki", H_landmark, landmarks @ J.T
        )
        return z_hat, H_robot, H_landmark


class _FirstEstimateJacobians(Standard):
    """The pose prior, the first estimates and their relinearisation, shared by FEJ and OC.

    ``relinearize_gate`` in (0, 1]: a landmark's first estimate ``m_first`` becomes its current one ``m`` once
    ``(m - m_first)^T P_mm^-1 (m - m_first) > chi2_2^-1(relinearize_gate)`` after an update (1: never).
    """

    COLUMN = "first_xy"

    def __init__(self, relinearize_gate: float = 1.0) -> None:
        self._relinearize = gate_2d(relinearize_gate)
        self._pose_prior = np.zeros(ROBOT_DIM)

    def start(self, state: SlamState) -> None:
        state.tracks.add_column(self.COLUMN, 2)
        self._pose_prior = state.mean[:ROBOT_DIM].copy()

    def propagation_jacobian(self, state: SlamState, G: NDArray[np.float64]) -> NDArray[np.float64]:
        # G + J (p_(k|k) - p_(k|k-1)) in the heading column
        G = G.copy()
        G[0, 2] -= state.mean[1] - self._pose_prior[1]
        G[1, 2] += state.mean[0] - self._pose_prior[0]
        return G

    def predicted(self, pose_prior: NDArray[np.float64]) -> None:
        self._pose_prior = pose_prior.copy()

    def added(self, state: SlamState, slots: NDArray[np.int64]) -> None:
        state.tracks.column(self.COLUMN)[slots] = state.landmark_positions()[slots]

    def fused(self, state: SlamState, slots: NDArray[np.int64]) -> None:
        """Reset the first estimates of ``slots`` that lie beyond ``relinearize_gate`` of the current ones."""
        if self._relinearize == np.inf or len(slots) == 0:
            return
        current = state.landmark_positions()[slots]
        first = state.tracks.column(self.COLUMN)
        # D2 = (m - m_first)^T P_mm^-1 (m - m_first)
        d2, _ = mahalanobis_2d(current - first[slots], state.landmark_blocks(slots))
        far = d2 > self._relinearize
        first[slots[far]] = current[far]

    def _first_estimates(self, state: SlamState, slots: NDArray[np.int64]) -> NDArray[np.float64]:
        return state.tracks.column(self.COLUMN)[slots]


class FirstEstimates(_FirstEstimateJacobians):
    """FEJ-EKF: ``H`` at the pose prior and the landmarks' first estimates."""

    def observe(self, state: SlamState, model: MeasurementModel, slots: NDArray[np.int64]) -> Observations:
        z_hat, _, _ = model.predict(state.mean[:ROBOT_DIM], state.landmark_positions()[slots])
        _, H_robot, H_landmark = model.predict(self._pose_prior, self._first_estimates(state, slots))
        return z_hat, H_robot, H_landmark


class ObservabilityConstrained(_FirstEstimateJacobians):
    """OC-EKF: ``H`` at the newest estimates, projected per observation onto the closest Jacobian with
    ``H N = 0`` (:func:`observability_constrained`)."""

    def observe(self, state: SlamState, model: MeasurementModel, slots: NDArray[np.int64]) -> Observations:
        z_hat, H_robot, H_landmark = model.predict(state.mean[:ROBOT_DIM], state.landmark_positions()[slots])
        H_robot, H_landmark = observability_constrained(
            H_robot, H_landmark, self._pose_prior, self._first_estimates(state, slots)
        )
        return z_hat, H_robot, H_landmark


def observability_constrained(
    H_robot: NDArray[np.float64],
    H_landmark: NDArray[np.float64],
    pose: NDArray[np.float64],
    landmarks_xy: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The OC-EKF Jacobians (k, 2, 3), (k, 2, 2): ``H* = H (I - N (N^T N)^-1 N^T)`` per observation with
    ``N = [[I_2, J p], [0, 1], [I_2, J m]]`` (5, 3), ``p`` the pose's position and ``m`` (k, 2) the
    landmarks' (:mod:`turtlelib.estimation.ekf_slam`'s module docstring).

    The projector in closed form: ``N``'s columns orthogonalised are ``n_x = [1, 0, 0, 1, 0]``,
    ``n_y = [0, 1, 0, 0, 1]`` (``|n|^2 = 2``) and, with ``d = m - p``,
    ``n_theta = [d_y / 2, -d_x / 2, 1, -d_y / 2, d_x / 2]`` (``|n_theta|^2 = 1 + |d|^2 / 2``), so::

        H* = H - (H n_x) n_x^T / 2 - (H n_y) n_y^T / 2 - (H n_theta) n_theta^T / |n_theta|^2
    """
    H = np.concatenate([H_robot, H_landmark], axis=2)
    d = landmarks_xy - pose[:2]
    half = 0.5 * d
    n_theta = np.zeros((len(d), 5))
    n_theta[:, 0], n_theta[:, 1], n_theta[:, 2] = half[:, 1], -half[:, 0], 1.0
    n_theta[:, 3], n_theta[:, 4] = -half[:, 1], half[:, 0]
    # (H n_x) / 2 and (H n_y) / 2 (k, 2): the mean of the pose's and the landmark's x (y) columns
    mean_x = 0.5 * (H[:, :, 0] + H[:, :, 3])
    mean_y = 0.5 * (H[:, :, 1] + H[:, :, 4])
    H_theta = np.einsum("kij,kj->ki", H, n_theta) / (1.0 + 0.5 * np.einsum("ki,ki->k", d, d))[:, None]
    H = H - H_theta[:, :, None] * n_theta[:, None, :]
    H[:, :, 0] -= mean_x
    H[:, :, 3] -= mean_x
    H[:, :, 1] -= mean_y
    H[:, :, 4] -= mean_y
    return H[:, :, :ROBOT_DIM], H[:, :, ROBOT_DIM:]


#: the ``linearization`` parameter's choices: each builds its strategy from ``relinearize_gate``
LINEARIZATIONS: dict[str, Callable[[float], Linearization]] = {
    "standard": lambda relinearize_gate: Standard(),
    "fej": FirstEstimates,
    "oc": ObservabilityConstrained,
    "invariant": lambda relinearize_gate: Invariant(),
}
