"""The records of EKF SLAM landmark slots: id, sightings (at most one per stamp), time of creation and of the
last counted sighting, where the sensor last viewed it,
confirmed or tentative, the evidence of a tentative landmark's sightings, and the columns a strategy adds
(first estimates: :mod:`turtlelib.estimation.linearization`).

Confirmation: a post seen consistently from several viewpoints
--------------------------------------------------------------
Each sighting ``i`` of a tentative landmark brings :class:`Sightings` evidence: where the robot stood,
``v_i`` (m, map frame), and where the observation alone puts the landmark, ``m_i = g(q_i, z_i)`` (the
inverse observation model at the robot's pose when it was seen) with covariance ``Sigma_i = G_z R_i
G_z^T``. A tentative landmark is confirmed at its ``confirm_count``-th sighting or later (sightings at one
stamp count once) only when both tests pass, with ``p`` the association's gate probability:

* **one place**: the sightings agree on one position. With the information sums ``Lambda = sum_i
  Sigma_i^-1``, ``eta = sum_i Sigma_i^-1 m_i`` and ``c = sum_i m_i^T Sigma_i^-1 m_i`` the weighted mean is
  ``m_hat = Lambda^-1 eta`` and the scatter about it::

      T = sum_i (m_i - m_hat)^T Sigma_i^-1 (m_i - m_hat) = c - eta^T Lambda^-1 eta

  is ``chi2`` with ``2 (n - 1)`` degrees of freedom for a post that stays put; ``T <= chi2_(2(n-1))^-1(p)``
  is required. A chair leg pushed between sightings, a person's leg, or a "post" that is an artefact of
  the viewpoint (the end of a wall, a fragment between missing beams: its fitted centre slides as the robot
  moves) scatters far more than its noise and never confirms.
* **several viewpoints**: the robot moved between the sightings far enough that such an artefact would
  have shown itself: the baseline ``b = max_i |v_i - v_1|`` is at least ``sqrt(chi2_2^-1(p)) sigma``, with
  ``sigma^2`` the smallest eigenvalue of one sighting's mean covariance ``n Lambda^-1`` (a LiDAR's range
  noise): an artefact bound to the viewpoint moves about as far as the robot, so after ``b`` it has left
  the gate of its first sightings at least along their best-measured direction. (The largest eigenvalue,
  the bearing noise times the range, would ask a slow robot for more travel than a tentative landmark's
  lifetime allows at a few metres.) The robot's position, not the sensor's, is the viewpoint: turning on
  the spot is not a new one.

Evidence is kept as these sums (O(1) per slot and sighting, vectorised over the slots).

:class:`turtlelib.estimation.slam_state.SlamState` owns one and is its only writer of rows: it appends rows
with its landmark slots and swap-removes a row with its slot, so records and state never disagree. Arrays grow
with spare capacity; every query is vectorised (O(n) numpy, no per-landmark Python loop).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .matching import chi2_gate


class Sightings(NamedTuple):
    """The evidence of ``k`` sightings (map frame, m): ``view_xy`` (k, 2) where the robot stood, ``p_map``
    (k, 2) where each observation alone puts its landmark, ``covariance`` (k, 2, 2) that position's
    covariance from the observation noise (module docstring)."""

    view_xy: NDArray[np.float64]
    p_map: NDArray[np.float64]
    covariance: NDArray[np.float64]

    def take(self, rows: NDArray[np.int64]) -> Sightings:
        """The sightings ``rows`` (r,)."""
        return Sightings(self.view_xy[rows], self.p_map[rows], self.covariance[rows])


class LandmarkTracks:
    """Per-slot ``ids``, ``seen`` (sightings), ``born`` (stamp of the first sighting, ns), ``last_view_xy``
    (the sensor's map position at its last fused observation, m; inf before any), ``confirmed`` flags, the
    evidence of the sightings (module docstring: ``views`` counted, first view ``v_1`` (NaN before any),
    baseline ``b``, ``Lambda``, ``eta``, ``c``) and the float columns added by :meth:`add_column`; ``next_id``
    is one more than the largest id ever held (0 at first)."""

    def __init__(self, capacity: int = 16) -> None:
        self._ids = np.zeros(capacity, dtype=np.int64)
        self._seen = np.zeros(capacity, dtype=np.int64)
        self._born = np.zeros(capacity, dtype=np.int64)
        self._sighted_ns = np.zeros(capacity, dtype=np.int64)
        self._last_view_xy = np.full((capacity, 2), np.inf)
        self._confirmed = np.zeros(capacity, dtype=bool)
        # the evidence of the sightings (module docstring)
        self._views = np.zeros(capacity, dtype=np.int64)
        self._first_view_xy = np.full((capacity, 2), np.nan)
        self._baseline = np.zeros(capacity)
        self._information = np.zeros((capacity, 2, 2))
        self._information_mean = np.zeros((capacity, 2))
        self._information_square = np.zeros(capacity)
        self._tentative = 0  # how many rows are not confirmed
        # the columns strategies add, by name
        self._columns: dict[str, NDArray[np.float64]] = {}
        self._n = 0
        self.next_id = 0
        self._slot_of: dict[int, int] = {}

    @property
    def ids(self) -> NDArray[np.int64]:
        """Landmark id of every slot (n,), a view."""
        return self._ids[: self._n]

    @property
    def last_view_xy(self) -> NDArray[np.float64]:
        """Sensor position (n, 2) at every slot's last fused observation (inf: none yet), a view."""
        return self._last_view_xy[: self._n]

    @property
    def confirmed(self) -> NDArray[np.bool_]:
        """Confirmed flag of every slot (n,), a view."""
        return self._confirmed[: self._n]

    @property
    def all_confirmed(self) -> bool:
        """Whether every slot is confirmed (no tentative landmark), O(1)."""
        return self._tentative == 0

    def add_column(self, name: str, width: int) -> None:
        """A float column ``name`` (n, width), zero for the rows held (no-op if it exists); it grows and
        swap-removes with the rows, and new rows start at zero."""
        if name not in self._columns:
            self._columns[name] = np.zeros((len(self._ids), width))

    def column(self, name: str) -> NDArray[np.float64]:
        """Column ``name`` (n, width), a view its owner writes."""
        return self._columns[name][: self._n]

    def viewed(self, slots: NDArray[np.int64], sensor_xy: NDArray[np.float64]) -> None:
        """Record ``sensor_xy`` (2,) as the last view of ``slots`` (k,)."""
        self._last_view_xy[slots] = sensor_xy

    def slot(self, landmark_id: int) -> int | None:
        """The slot of ``landmark_id``, or None."""
        return self._slot_of.get(landmark_id)

    def append(
        self,
        landmark_ids: NDArray[np.int64],
        stamp_ns: int,
        confirmed: bool,
        sightings: Sightings | None = None,
    ) -> NDArray[np.int64]:
        """New last rows for the distinct ``landmark_ids`` (k,) (none held already), first seen at
        ``stamp_ns`` (with the evidence of that first sighting, if given); returns their slots (k,). O(k),
        one reallocation at most."""
        k = len(landmark_ids)
        self._reserve(self._n + k)
        new = slice(self._n, self._n + k)
        self._ids[new], self._seen[new], self._born[new] = landmark_ids, 1, stamp_ns
        self._sighted_ns[new] = stamp_ns
        self._last_view_xy[new] = np.inf
        self._confirmed[new] = confirmed
        self._views[new], self._first_view_xy[new], self._baseline[new] = 0, np.nan, 0.0
        self._information[new], self._information_mean[new], self._information_square[new] = 0.0, 0.0, 0.0
        slots = np.arange(new.start, new.stop)
        if sightings is not None:
            self._add_evidence(slots, sightings)
        self._tentative += 0 if confirmed else k
        for column in self._columns.values():
            column[new] = 0.0
        self._slot_of.update(zip(np.asarray(landmark_ids).tolist(), range(self._n, self._n + k), strict=True))
        self._n += k
        if k:
            self.next_id = max(self.next_id, int(np.max(landmark_ids)) + 1)
        return slots

    def remove(self, slot: int) -> None:
        """Forget ``slot``; the last row moves into it."""
        del self._slot_of[int(self._ids[slot])]
        self._tentative -= not self._confirmed[slot]
        last = self._n - 1
        if slot != last:
            for array in self._arrays():
                array[slot] = array[last]
            self._slot_of[int(self._ids[slot])] = slot
        self._n = last

    def sighted(
        self,
        slots: NDArray[np.int64],
        sightings: Sightings,
        confirm_count: int,
        gate_prob: float,
        stamp_ns: int,
    ) -> NDArray[np.int64]:
        """Count one sighting at ``stamp_ns`` of each of the distinct tentative ``slots`` (k,) not yet sighted
        at that stamp or later (copies of one scan count once), with its evidence ``sightings`` (k rows);
        returns the ids this confirms: seen ``confirm_count`` times or more, at one place from several
        viewpoints at gate probability ``gate_prob`` (module docstring)."""
        # the usual scan: only confirmed landmarks sighted
        if self._tentative == 0 or self._confirmed[slots].all():
            return np.zeros(0, dtype=np.int64)
        counted = (~self._confirmed[slots] & (self._sighted_ns[slots] < stamp_ns)).nonzero()[0]
        tentative = slots[counted]
        self._seen[tentative] += 1
        self._sighted_ns[tentative] = stamp_ns
        self._add_evidence(tentative, sightings.take(counted))
        due = tentative[self._seen[tentative] >= confirm_count]
        newly = due[self._consistent(due, gate_prob)]
        self._confirmed[newly] = True
        self._tentative -= len(newly)
        return np.sort(self._ids[newly])

    def _add_evidence(self, slots: NDArray[np.int64], sightings: Sightings) -> None:
        """Add the evidence of one sighting of each of the distinct ``slots`` (k,) to their sums."""
        if len(slots) == 0:
            return
        view_xy, p_map, covariance = sightings
        first = np.isnan(self._first_view_xy[slots, 0])
        self._first_view_xy[slots[first]] = view_xy[first]
        # b = max_i |v_i - v_1|
        moved = np.linalg.norm(view_xy - self._first_view_xy[slots], axis=1)
        self._baseline[slots] = np.maximum(self._baseline[slots], moved)
        # Lambda += Sigma_i^-1, eta += Sigma_i^-1 m_i, c += m_i^T Sigma_i^-1 m_i
        information = np.linalg.inv(covariance)
        weighted = np.einsum("kij,kj->ki", information, p_map)
        self._views[slots] += 1
        self._information[slots] += information
        self._information_mean[slots] += weighted
        self._information_square[slots] += np.einsum("ki,ki->k", p_map, weighted)

    def _consistent(self, slots: NDArray[np.int64], gate_prob: float) -> NDArray[np.bool_]:
        """(k,) whether the sightings of ``slots`` (k,) agree on one place seen from several viewpoints
        (module docstring)."""
        if len(slots) == 0:
            return np.zeros(0, dtype=bool)
        n = self._views[slots]
        covariance_of_mean = np.linalg.inv(self._information[slots])
        eta = self._information_mean[slots]
        # T = c - eta^T Lambda^-1 eta
        scatter = self._information_square[slots] - np.einsum("ki,kij,kj->k", eta, covariance_of_mean, eta)
        one_place = scatter <= chi2_gate(gate_prob, 2 * np.maximum(n - 1, 1))
        # sigma^2 = lambda_min(n Lambda^-1); b >= sqrt(chi2_2^-1(p)) sigma
        sigma2 = n * np.linalg.eigvalsh(covariance_of_mean)[:, 0]
        several_views = self._baseline[slots] ** 2 >= chi2_gate(gate_prob, 2) * sigma2
        return (n >= 2) & one_place & several_views

    def expired(self, stamp_ns: int, timeout_ns: int) -> NDArray[np.int64]:
        """Slots of tentative landmarks first seen ``timeout_ns`` or more before ``stamp_ns``, highest
        first."""
        if self._tentative == 0:
            return np.zeros(0, dtype=np.int64)
        n = self._n
        old = ~self._confirmed[:n] & (stamp_ns - self._born[:n] >= timeout_ns)
        return old.nonzero()[0][::-1]

    def slots_by_id(self, confirmed: bool) -> NDArray[np.int64]:
        """The confirmed (or the tentative) slots in ascending id order."""
        slots = (self._confirmed[: self._n] == confirmed).nonzero()[0]
        return slots[np.argsort(self._ids[slots], kind="stable")]

    # the per-slot arrays, besides the columns
    _SLOT_ARRAYS = (
        "_ids",
        "_seen",
        "_born",
        "_sighted_ns",
        "_last_view_xy",
        "_confirmed",
        "_views",
        "_first_view_xy",
        "_baseline",
        "_information",
        "_information_mean",
        "_information_square",
    )

    def _arrays(self) -> list[NDArray]:
        """Every per-slot array, full capacity: ``_SLOT_ARRAYS``, then the columns."""
        return [getattr(self, name) for name in self._SLOT_ARRAYS] + list(self._columns.values())

    def _reserve(self, n: int) -> None:
        """Grow the arrays (at least doubling) so that ``n`` slots fit."""
        if n <= len(self._ids):
            return
        capacity = max(n, 2 * len(self._ids))
        grown = []
        for old in self._arrays():
            array = np.zeros((capacity, *old.shape[1:]), dtype=old.dtype)
            array[: self._n] = old[: self._n]
            grown.append(array)
        for name, array in zip(self._SLOT_ARRAYS, grown, strict=False):
            setattr(self, name, array)
        self._columns = dict(zip(self._columns, grown[len(self._SLOT_ARRAYS) :], strict=True))
