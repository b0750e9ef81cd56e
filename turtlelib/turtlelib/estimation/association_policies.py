"""Data association of EKF SLAM as policy objects: which observation updates which landmark, which starts one.

:class:`turtlelib.estimation.ekf_slam.EkfSlam` asks its policy for a :class:`Plan` over one update's
observations, given a read-only :class:`SlamView` of the filter, fuses what the plan matches, then asks the
policy which of the plan's unexplained observations may start a landmark (:meth:`AssociationPolicy.admits`,
against the filter as it is after the fusion and the landmarks started before in the same update) and which
tentative landmarks it drops (:meth:`AssociationPolicy.expired`). The maths of gates, nearest neighbour and
JCBB is in :mod:`turtlelib.estimation.matching`.

* :class:`KnownIds` (known association): the observation's id names its landmark; an observation of a
  mapped landmark outside ``D2 < chi2_2^-1(gate_known)`` is rejected; an unseen id starts a confirmed
  landmark.
* :class:`GatedTracks` (unknown association): every observation is gated against every landmark (in large
  maps only against those that may come near it, :meth:`SlamView.gate_near`); compatible pairs
  (``D2 < chi2_2^-1(gate_associate)``) are matched by a :class:`Matcher` (:data:`MATCHERS`: nearest
  neighbour or JCBB), confirmed landmarks first; an observation beyond ``gate_new`` of every landmark starts
  a tentative one, confirmed after ``confirm_count`` sightings that agree on one place seen from several
  viewpoints (:mod:`turtlelib.estimation.landmark_tracks`, at the probability ``gate_associate``) or
  dropped ``tentative_timeout`` after its first.

A new matcher is one class with :meth:`Matcher.match` and one entry in :data:`MATCHERS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from .landmark_tracks import LandmarkTracks, Sightings
from .linearization import Linearization
from .matching import (
    gate_2d,
    joint_compatibility,
    mahalanobis_2d,
    mahalanobis_lower_bound,
    nearest_neighbour,
)
from .measurement_models import MeasurementModel
from .slam_state import ROBOT_DIM, SlamState

# what an update did with one observation (turtlelib.estimation.ekf_slam.ObservationStatus), as plain integers
MATCHED, NEW, REJECTED, UNMAPPED = 0, 1, 2, 3
# unknown association bounds D2 before gating (SlamView.gate_near) from this many landmarks on: the bound
# costs about 40 us per scan at 20 landmarks, where gating all of them is cheaper (bench/bench_ekf.py), and
# saves about 70 us at 300 spread over a park (Victoria Park, docs/real_data.md "Speed")
PREFILTER_MIN_LANDMARKS = 64


class Gating(NamedTuple):
    """``K`` observations against landmark ``slots`` (k,): innovations ``nu`` (K, k, 2), ``d2 = nu^T S^-1 nu``
    and ``log_det = ln det S`` (K, k) with ``S_kj = H_j P H_j^T + R_k``, and the Jacobians ``H_robot``
    (k, 2, 3), ``H_landmark`` (k, 2, 2) of the slots."""

    slots: NDArray[np.int64]
    nu: NDArray[np.float64]
    d2: NDArray[np.float64]
    log_det: NDArray[np.float64]
    H_robot: NDArray[np.float64]
    H_landmark: NDArray[np.float64]


class SlamView:
    """The filter as association sees it: read-only queries of its state, through its linearisation and the
    update's measurement model."""

    def __init__(
        self, state: SlamState, linearization: Linearization, model: MeasurementModel, max_landmarks: int
    ) -> None:
        self._state, self._linearization, self.model = state, linearization, model
        self._max_landmarks = max_landmarks

    @property
    def tracks(self) -> LandmarkTracks:
        """The slots' records (read them only)."""
        return self._state.tracks

    @property
    def n_landmarks(self) -> int:
        return self._state.n_landmarks

    @property
    def robot_pose(self) -> NDArray[np.float64]:
        """The robot's pose ``[x, y, theta]`` (3,) (m, rad), a copy."""
        return self._state.mean[:ROBOT_DIM].copy()

    @property
    def map_full(self) -> bool:
        """Whether the map holds ``max_landmarks`` (confirmed and tentative)."""
        return self._state.n_landmarks >= self._max_landmarks

    def observe(self, slots: NDArray[np.int64]) -> tuple[NDArray[np.float64], ...]:
        """``(z_hat (k, 2), H_robot (k, 2, 3), H_landmark (k, 2, 2))`` of landmark ``slots`` (k,)."""
        return self._linearization.observe(self._state, self.model, slots)

    def predicted(self, slots: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(z_hat (k, 2), H P H^T (k, 2, 2))`` of landmark ``slots`` (k,): their predicted observations and
        the covariance of those predictions."""
        z_hat, H_robot, H_landmark = self.observe(slots)
        return z_hat, self._predicted_covariances(H_robot, H_landmark, slots)

    def gate(self, z: NDArray[np.float64], R: NDArray[np.float64], slots: NDArray[np.int64]) -> Gating:
        """Every observation ``z`` (K, 2) against every landmark of ``slots`` (k,), O(K k)."""
        z_hat, H_robot, H_landmark = self.observe(slots)
        # nu_kj = z_k - z_hat_j
        nu = self.model.residual(z[:, None, :], z_hat[None, :, :])
        return self._gating(slots, nu, R, H_robot, H_landmark)

    def gate_near(self, z: NDArray[np.float64], R: NDArray[np.float64], gate: float) -> Gating:
        """:meth:`gate` against the landmark slots (ascending) that may come within ``D2 <= gate`` of an
        observation. The others are left out before their ``S`` is formed, by a lower bound of their ``D2``
        from the standard deviations of ``P``
        (:func:`~turtlelib.estimation.matching.mahalanobis_lower_bound`). O(K n), with ``S`` for the slots
        kept only."""
        z_hat, H_robot, H_landmark = self.observe(np.arange(self._state.n_landmarks))
        nu = self.model.residual(z[:, None, :], z_hat[None, :, :])
        std = self._state.stored_std()
        std_robot = np.broadcast_to(std[:ROBOT_DIM], (len(z_hat), ROBOT_DIM))
        std_pose_landmark = np.concatenate([std_robot, std[ROBOT_DIM:].reshape(-1, 2)], axis=1)
        bound = mahalanobis_lower_bound(
            nu, R, np.concatenate([H_robot, H_landmark], axis=2), std_pose_landmark
        )
        # margin: D2 and its bound are computed differently, to rounding
        near = (bound <= gate * (1.0 + 1e-6)).any(axis=0).nonzero()[0]
        return self._gating(near, nu[:, near], R, H_robot[near], H_landmark[near])

    def joint_covariance(self, gating: Gating, columns: NDArray[np.int64]) -> NDArray[np.float64]:
        """``H P H^T`` (2c, 2c) of the predicted observations of ``gating``'s ``columns`` (c,), jointly."""
        return self._state.observation_covariance(
            gating.slots[columns], gating.H_robot[columns], gating.H_landmark[columns]
        )

    def _gating(
        self,
        slots: NDArray[np.int64],
        nu: NDArray[np.float64],
        R: NDArray[np.float64],
        H_robot: NDArray[np.float64],
        H_landmark: NDArray[np.float64],
    ) -> Gating:
        Sigma = self._predicted_covariances(H_robot, H_landmark, slots)
        # S_kj = Sigma_j + R_k: R_k repeated for each landmark, so that the sum is one contiguous run
        count, k = len(R), len(slots)
        S = (np.repeat(R.reshape(count, 1, 4), k, axis=1) + Sigma.reshape(1, k, 4)).reshape(count, k, 2, 2)
        d2, log_det = mahalanobis_2d(nu, S)
        return Gating(slots, nu, d2, log_det, H_robot, H_landmark)

    def _predicted_covariances(
        self, H_robot: NDArray[np.float64], H_landmark: NDArray[np.float64], slots: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """``Sigma_j = H_j P H_j^T`` (k, 2, 2) for ``slots`` (k,), O(k): ``H_j`` is non-zero only on the pose
        and landmark j, so ``Sigma_j = J_j P_(q m_j) J_j^T`` with ``J_j = [H_robot_j, H_landmark_j]`` and
        ``P_(q m_j)`` the 5x5 joint covariance of the pose and landmark j."""
        J = np.concatenate([H_robot, H_landmark], axis=2)
        return J @ self._state.pose_landmark_blocks(slots) @ J.transpose(0, 2, 1)


class Plan(NamedTuple):
    """What to do with an update's ``K`` observations.

    ``status`` (K,) and ``landmark_ids`` (K,) so far (``MATCHED`` with the landmark's id, else
    ``REJECTED`` and -1); the fusion: observations ``rows`` (m,) of landmark ``slots`` (m,) with innovations
    ``nu`` (m, 2) and Jacobians ``H_robot`` (m, 2, 3), ``H_landmark`` (m, 2, 2); ``births`` (b,) the
    observations that no landmark explains, in order, with their ids ``birth_ids`` (b,) (None: the next
    free ids as they start) and ``birth_confirmed`` whether they start confirmed; ``gate``: the fusion
    rejects a matched observation whose own ``D2 = nu^T S^-1 nu`` is not below it (inf: none).
    """

    status: NDArray[np.int8]
    landmark_ids: NDArray[np.int64]
    rows: NDArray[np.int64]
    slots: NDArray[np.int64]
    nu: NDArray[np.float64]
    H_robot: NDArray[np.float64]
    H_landmark: NDArray[np.float64]
    births: NDArray[np.int64]
    birth_ids: NDArray[np.int64] | None
    birth_confirmed: bool
    gate: float = math.inf


class Matcher(Protocol):
    """Pairs observations with compatible landmarks of a :class:`Gating`."""

    def match(
        self, gating: Gating, compatible: NDArray[np.bool_], R: NDArray[np.float64], view: SlamView
    ) -> NDArray[np.int64]:
        """(K,) the column of ``gating`` each observation joins (-1: none), only ``compatible`` (K, k) pairs,
        each column at most once."""
        ...


class NearestNeighbour:
    """Greedy most likely pairs: the smallest ``-2 log N(nu; 0, S) = D2 + ln det S`` (+ const) first."""

    def match(
        self, gating: Gating, compatible: NDArray[np.bool_], R: NDArray[np.float64], view: SlamView
    ) -> NDArray[np.int64]:
        return nearest_neighbour(gating.d2 + gating.log_det, compatible)


class JointCompatibility:
    """JCBB (Neira & Tardos 2001) over the landmarks some observation is compatible with: the hypothesis with
    the most pairs whose joint innovation passes ``chi2_(2|H|)^-1(gate_prob)``, at most ``max_nodes`` pairs
    tried."""

    def __init__(self, gate_prob: float, max_nodes: int) -> None:
        self._gate_prob, self._max_nodes = gate_prob, max_nodes

    def match(
        self, gating: Gating, compatible: NDArray[np.bool_], R: NDArray[np.float64], view: SlamView
    ) -> NDArray[np.int64]:
        candidates = compatible.any(axis=0).nonzero()[0]
        if len(candidates) == 0:
            return np.full(len(gating.nu), -1, dtype=np.int64)
        match = joint_compatibility(
            gating.nu[:, candidates],
            compatible[:, candidates],
            view.joint_covariance(gating, candidates),
            R,
            self._gate_prob,
            self._max_nodes,
        )
        return np.where(match >= 0, candidates[match], -1)


#: the ``matcher`` parameter's choices: each builds its matcher from ``(gate_associate, jcbb_max_nodes)``
MATCHERS: dict[str, Callable[[float, int], Matcher]] = {
    "nn": lambda gate_associate, max_nodes: NearestNeighbour(),
    "jcbb": JointCompatibility,
}


class AssociationPolicy(Protocol):
    """How an update's observations meet the map (module docstring)."""

    #: whether the policy keeps tentative landmarks (their confirmations are reported)
    tentative: bool

    def plan(
        self, view: SlamView, z: NDArray[np.float64], R: NDArray[np.float64], ids: NDArray[np.int64] | None
    ) -> Plan:
        """The plan for observations ``z`` (K, 2) with noise ``R`` (K, 2, 2) (and their ``ids``, if known)."""
        ...

    def sighted(self, tracks: LandmarkTracks, slots: NDArray[np.int64], stamp_ns: int) -> NDArray[np.int64]:
        """Record a sighting at ``stamp_ns`` of the fused ``slots``; returns the ids this confirms."""
        ...

    def admits(
        self, view: SlamView, z: NDArray[np.float64], R: NDArray[np.float64], started: list[int]
    ) -> bool:
        """Whether observation ``z`` (2,) with noise ``R`` (2, 2) may start a landmark, given the slots
        ``started`` in this update before it."""
        ...

    def expired(self, view: SlamView, stamp_ns: int) -> NDArray[np.int64]:
        """The slots to drop after an update at ``stamp_ns``, highest first."""
        ...


_NO_ROWS = np.zeros(0, dtype=np.int64)  # an empty index, shared: read-only
_NO_ROWS.flags.writeable = False


def _empty_plan(count: int) -> tuple[NDArray[np.int8], NDArray[np.int64]]:
    status, landmark_ids = np.empty(count, dtype=np.int8), np.empty(count, dtype=np.int64)
    status.fill(REJECTED)
    landmark_ids.fill(-1)
    return status, landmark_ids


class KnownIds:
    """Known association with an innovation gate ``D2 < chi2_2^-1(gate_known)`` (``gate_known = 1``: none)."""

    tentative = False

    def __init__(self, gate_known: float) -> None:
        self._gate = gate_2d(gate_known)

    def plan(
        self, view: SlamView, z: NDArray[np.float64], R: NDArray[np.float64], ids: NDArray[np.int64] | None
    ) -> Plan:
        if ids is None:
            raise ValueError("known association needs the observations' landmark ids")
        usable = view.model.usable(z)
        slot_of = view.tracks.slot
        # the slot of each observation's landmark, None for an id not in the map
        found = [slot_of(i) for i in ids.tolist()]
        if None not in found and usable.all():  # the usual scan: every observation of a mapped landmark
            slots, rows, births = np.array(found, dtype=np.int64), np.arange(len(z)), _NO_ROWS
            status, landmark_ids = np.full(len(z), MATCHED, dtype=np.int8), ids.copy()
        else:
            slots = np.array([-1 if slot is None else slot for slot in found], dtype=np.int64)
            rows, births = (usable & (slots >= 0)).nonzero()[0], (usable & (slots < 0)).nonzero()[0]
            slots, z, R = slots[rows], z[rows], R[rows]
            status, landmark_ids = _empty_plan(len(ids))
            status[rows] = MATCHED
            landmark_ids[rows] = ids[rows]
        z_hat, H_robot, H_landmark = view.observe(slots)
        # the fusion refuses an observation whose D2 = nu^T S^-1 nu against its landmark is beyond the gate
        return Plan(
            status,
            landmark_ids,
            rows,
            slots,
            view.model.residual(z, z_hat),
            H_robot,
            H_landmark,
            births,
            ids[births],
            birth_confirmed=True,
            gate=self._gate,
        )

    def sighted(self, tracks: LandmarkTracks, slots: NDArray[np.int64], stamp_ns: int) -> NDArray[np.int64]:
        return np.zeros(0, dtype=np.int64)

    def admits(
        self, view: SlamView, z: NDArray[np.float64], R: NDArray[np.float64], started: list[int]
    ) -> bool:
        return True

    def expired(self, view: SlamView, stamp_ns: int) -> NDArray[np.int64]:
        return np.zeros(0, dtype=np.int64)


class GatedTracks:
    """Unknown association: gated matching (``gate_associate``), births beyond ``gate_new``, tentative tracks
    confirmed after ``confirm_count`` sightings at one place from several viewpoints or dropped
    ``timeout_ns`` after their first (module docstring).

    Its plan notes the evidence of the observations it pairs with tentative landmarks (where the robot
    stands, where each observation alone puts its landmark: :class:`Sightings`), and :meth:`sighted`
    counts those of them the update fused."""

    tentative = True

    def __init__(
        self, matcher: Matcher, gate_associate: float, gate_new: float, confirm_count: int, timeout_ns: int
    ) -> None:
        self._matcher = matcher
        self._gate_prob = gate_associate
        self._gate_associate = gate_2d(gate_associate)
        self._gate_new = gate_2d(gate_new)
        self._confirm_count, self._timeout_ns = confirm_count, timeout_ns
        # the slots of the last plan's pairs with tentative landmarks and their evidence
        self._evidence: tuple[NDArray[np.int64], Sightings] | None = None

    def plan(
        self, view: SlamView, z: NDArray[np.float64], R: NDArray[np.float64], ids: NDArray[np.int64] | None
    ) -> Plan:
        self._evidence = None
        usable = view.model.usable(z).nonzero()[0]
        z_usable, R_usable = (z, R) if len(usable) == len(z) else (z[usable], R[usable])
        n_landmarks = view.n_landmarks
        if n_landmarks and len(usable):
            if n_landmarks >= PREFILTER_MIN_LANDMARKS:
                gating = view.gate_near(z_usable, R_usable, self._gate_new)
            else:
                gating = view.gate(z_usable, R_usable, np.arange(n_landmarks))
            match = self._associate(gating, R_usable, view)
            rows = (match >= 0).nonzero()[0]
            columns = match[rows]
            slots = gating.slots[columns]
            if len(rows) == len(z):  # every observation matched (the usual scan)
                matched, status, landmark_ids = (
                    rows,
                    np.full(len(z), MATCHED, dtype=np.int8),
                    view.tracks.ids[slots],
                )
            else:
                matched = usable[rows]
                status, landmark_ids = _empty_plan(len(z))
                landmark_ids[matched] = view.tracks.ids[slots]
                status[matched] = MATCHED
            fused = (matched, slots, gating.nu[rows, columns], gating.H_robot[columns])
            self._note_evidence(view, slots, z_usable[rows], R_usable[rows])
            H_landmark = gating.H_landmark[columns]
            # births: the unmatched observations beyond gate_new of every landmark (none when all matched)
            unmatched = (match < 0).nonzero()[0]
            if len(unmatched):
                unmatched = unmatched[(gating.d2[unmatched] > self._gate_new).all(axis=1)]
            births = usable[unmatched]
        else:  # nothing to match: every usable observation may start a landmark
            status, landmark_ids = _empty_plan(len(z))
            empty = np.zeros(0, dtype=np.int64)
            fused = (empty, empty, np.zeros((0, 2)), np.zeros((0, 2, ROBOT_DIM)))
            H_landmark = np.zeros((0, 2, 2))
            births = usable
        return Plan(
            status, landmark_ids, *fused, H_landmark, births, None, birth_confirmed=self._confirm_count == 1
        )

    def _note_evidence(
        self, view: SlamView, slots: NDArray[np.int64], z: NDArray[np.float64], R: NDArray[np.float64]
    ) -> None:
        """Keep the evidence of the observations ``z`` (m, 2) with noise ``R`` (m, 2, 2) paired with
        ``slots`` (m,) that are tentative: the robot's position and ``m = g(q, z)`` with ``Sigma = G_z R
        G_z^T`` (the inverse model at the pose before the update)."""
        tentative = (~view.tracks.confirmed[slots]).nonzero()[0]
        if len(tentative) == 0:
            self._evidence = None
            return
        pose = view.robot_pose
        p_map, _, G_z = view.model.inverse(pose, z[tentative])
        covariance = G_z @ R[tentative] @ G_z.transpose(0, 2, 1)
        view_xy = np.broadcast_to(pose[:2], p_map.shape)
        self._evidence = (slots[tentative], Sightings(view_xy, p_map, covariance))

    def _associate(self, gating: Gating, R: NDArray[np.float64], view: SlamView) -> NDArray[np.int64]:
        """The column (or -1) for each observation: confirmed landmarks first; tentative landmarks only take
        observations that no confirmed landmark is compatible with."""
        compatible = gating.d2 < self._gate_associate
        tracks = view.tracks
        confirmed = None if tracks.all_confirmed else tracks.confirmed[gating.slots]
        if confirmed is None or confirmed.all():  # no tentative landmark among them (the usual scan)
            return self._matcher.match(gating, compatible, R, view)
        with_confirmed = compatible & confirmed
        match = self._matcher.match(gating, with_confirmed, R, view)
        unexplained = ~with_confirmed.any(axis=1)
        if unexplained.any():
            to_tentative = compatible & ~confirmed & unexplained[:, None]
            match = np.where(unexplained, self._matcher.match(gating, to_tentative, R, view), match)
        return match

    def sighted(self, tracks: LandmarkTracks, slots: NDArray[np.int64], stamp_ns: int) -> NDArray[np.int64]:
        """Count the sightings of the fused tentative ``slots`` with the evidence the plan noted."""
        evidence, self._evidence = self._evidence, None
        if evidence is None:
            return np.zeros(0, dtype=np.int64)
        noted, sightings = evidence
        fused = np.isin(noted, slots).nonzero()[0]
        return tracks.sighted(
            noted[fused], sightings.take(fused), self._confirm_count, self._gate_prob, stamp_ns
        )

    def admits(
        self, view: SlamView, z: NDArray[np.float64], R: NDArray[np.float64], started: list[int]
    ) -> bool:
        """Not within ``gate_new`` of a landmark this update started: one object gives one detection per
        scan."""
        if not started:
            return True
        gating = view.gate(z[None], R[None], np.array(started))
        return not np.any(gating.d2 <= self._gate_new)

    def expired(self, view: SlamView, stamp_ns: int) -> NDArray[np.int64]:
        return view.tracks.expired(stamp_ns, self._timeout_ns)
