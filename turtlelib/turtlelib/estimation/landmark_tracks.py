"""The records of EKF SLAM landmark slots: id, sightings (at most one per stamp), time of creation and of the
last counted sighting, where the sensor last viewed it,
confirmed or tentative, and the columns a strategy adds (first estimates:
:mod:`turtlelib.estimation.linearization`).

:class:`turtlelib.estimation.slam_state.SlamState` owns one and is its only writer of rows: it appends rows
with its landmark slots and swap-removes a row with its slot, so records and state never disagree. Arrays grow
with spare capacity; every query is vectorised (O(n) numpy, no per-landmark Python loop).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


class LandmarkTracks:
    """Per-slot ``ids``, ``seen`` (sightings), ``born`` (stamp of the first sighting, ns), ``last_view_xy``
    (the sensor's map position at its last fused observation, m; inf before any), ``confirmed`` flags and
    the float columns added by :meth:`add_column`; ``next_id`` is one more than the largest id ever held
    (0 at first)."""

    def __init__(self, capacity: int = 16) -> None:
        self._ids = np.zeros(capacity, dtype=np.int64)
        self._seen = np.zeros(capacity, dtype=np.int64)
        self._born = np.zeros(capacity, dtype=np.int64)
        self._sighted_ns = np.zeros(capacity, dtype=np.int64)
        self._last_view_xy = np.full((capacity, 2), np.inf)
        self._confirmed = np.zeros(capacity, dtype=bool)
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

    def append(self, landmark_ids: NDArray[np.int64], stamp_ns: int, confirmed: bool) -> NDArray[np.int64]:
        """New last rows for the distinct ``landmark_ids`` (k,) (none held already), first seen at
        ``stamp_ns``; returns their slots (k,). O(k), one reallocation at most."""
        k = len(landmark_ids)
        self._reserve(self._n + k)
        new = slice(self._n, self._n + k)
        self._ids[new], self._seen[new], self._born[new] = landmark_ids, 1, stamp_ns
        self._sighted_ns[new] = stamp_ns
        self._last_view_xy[new] = np.inf
        self._confirmed[new] = confirmed
        self._tentative += 0 if confirmed else k
        for column in self._columns.values():
            column[new] = 0.0
        self._slot_of.update(zip(np.asarray(landmark_ids).tolist(), range(self._n, self._n + k), strict=True))
        self._n += k
        if k:
            self.next_id = max(self.next_id, int(np.max(landmark_ids)) + 1)
        return np.arange(new.start, new.stop)

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

    def sighted(self, slots: NDArray[np.int64], confirm_count: int, stamp_ns: int) -> NDArray[np.int64]:
        """Count one sighting at ``stamp_ns`` of each of the distinct tentative ``slots`` not yet sighted at
        that stamp or later (copies of one scan count once); returns the ids this confirms."""
        # the usual scan: only confirmed landmarks sighted
        if self._tentative == 0 or self._confirmed[slots].all():
            return np.zeros(0, dtype=np.int64)
        tentative = slots[~self._confirmed[slots] & (self._sighted_ns[slots] < stamp_ns)]
        self._seen[tentative] += 1
        self._sighted_ns[tentative] = stamp_ns
        newly = tentative[self._seen[tentative] >= confirm_count]
        self._confirmed[newly] = True
        self._tentative -= len(newly)
        return np.sort(self._ids[newly])

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

    def _arrays(self) -> list[NDArray]:
        """Every per-slot array, full capacity."""
        return [
            self._ids,
            self._seen,
            self._born,
            self._sighted_ns,
            self._last_view_xy,
            self._confirmed,
            *self._columns.values(),
        ]

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
        self._ids, self._seen, self._born, self._sighted_ns, self._last_view_xy, self._confirmed = grown[:6]
        self._columns = dict(zip(self._columns, grown[6:], strict=True))
