"""Bookkeeping of EKF SLAM landmark slots: id, sightings, time of creation, first estimate, where the sensor
last viewed it, confirmed or tentative.

The slots mirror :class:`turtlelib.slam_state.SlamState`'s: :meth:`LandmarkTracks.append` adds the last
slot, :meth:`LandmarkTracks.remove` swap-removes exactly as ``SlamState.remove`` does. Arrays grow with
spare capacity; every query is vectorised (O(n) numpy, no per-landmark Python loop).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


class LandmarkTracks:
    """Per-slot ``ids``, ``seen`` (sightings), ``born`` (stamp of the first sighting, ns), ``first_xy`` (the
    position the landmark was initialised at, m), ``last_view_xy`` (the sensor's map position at its last
    fused observation, m; inf before any) and ``confirmed`` flags."""

    _ARRAYS = ("_ids", "_seen", "_born", "_first_xy", "_last_view_xy", "_confirmed")

    def __init__(self, capacity: int = 16) -> None:
        self._ids = np.zeros(capacity, dtype=np.int64)
        self._seen = np.zeros(capacity, dtype=np.int64)
        self._born = np.zeros(capacity, dtype=np.int64)
        self._first_xy = np.zeros((capacity, 2))
        self._last_view_xy = np.full((capacity, 2), np.inf)
        self._confirmed = np.zeros(capacity, dtype=bool)
        self._n = 0
        self._slot_of: dict[int, int] = {}

    @property
    def ids(self) -> NDArray[np.int64]:
        """Landmark id of every slot (n,), a view."""
        return self._ids[: self._n]

    @property
    def first_xy(self) -> NDArray[np.float64]:
        """First estimate (n, 2) of every slot, a view."""
        return self._first_xy[: self._n]

    @property
    def last_view_xy(self) -> NDArray[np.float64]:
        """Sensor position (n, 2) at every slot's last fused observation (inf: none yet), a view."""
        return self._last_view_xy[: self._n]

    def viewed(self, slots: NDArray[np.int64], sensor_xy: NDArray[np.float64]) -> None:
        """Record ``sensor_xy`` (2,) as the last view of ``slots`` (k,)."""
        self._last_view_xy[slots] = sensor_xy

    def relinearize(self, slots: NDArray[np.int64], xy: NDArray[np.float64]) -> None:
        """Replace the first estimates of ``slots`` (k,) by ``xy`` (k, 2)."""
        self._first_xy[slots] = xy

    @property
    def confirmed(self) -> NDArray[np.bool_]:
        """Confirmed flag of every slot (n,), a view."""
        return self._confirmed[: self._n]

    def slot(self, landmark_id: int) -> int | None:
        """The slot of ``landmark_id``, or None."""
        return self._slot_of.get(landmark_id)

    def append(self, landmark_id: int, stamp_ns: int, confirmed: bool, first_xy: NDArray[np.float64]) -> int:
        """A new last slot for ``landmark_id`` first seen at ``stamp_ns`` at ``first_xy`` (2,); returns the
        slot."""
        self._reserve(self._n + 1)
        slot = self._n
        self._ids[slot], self._seen[slot], self._born[slot] = landmark_id, 1, stamp_ns
        self._first_xy[slot] = first_xy
        self._last_view_xy[slot] = np.inf
        self._confirmed[slot] = confirmed
        self._slot_of[landmark_id] = slot
        self._n += 1
        return slot

    def append_many(
        self, landmark_ids: NDArray[np.int64], stamp_ns: int, confirmed: bool, first_xy: NDArray[np.float64]
    ) -> NDArray[np.int64]:
        """New last slots for the distinct ``landmark_ids`` (k,) (none held already), first seen at
        ``stamp_ns`` at ``first_xy`` (k, 2); returns the slots (k,). O(k), one reallocation at most."""
        k = len(landmark_ids)
        self._reserve(self._n + k)
        new = slice(self._n, self._n + k)
        self._ids[new], self._seen[new], self._born[new] = landmark_ids, 1, stamp_ns
        self._first_xy[new] = first_xy
        self._last_view_xy[new] = np.inf
        self._confirmed[new] = confirmed
        self._slot_of.update(zip(np.asarray(landmark_ids).tolist(), range(self._n, self._n + k), strict=True))
        self._n += k
        return np.arange(new.start, new.stop)

    def _reserve(self, n: int) -> None:
        """Grow the arrays (at least doubling) so that ``n`` slots fit."""
        if n <= len(self._ids):
            return
        capacity = max(n, 2 * len(self._ids))
        for name in self._ARRAYS:
            old = getattr(self, name)
            grown = np.zeros((capacity, *old.shape[1:]), dtype=old.dtype)
            grown[: self._n] = old[: self._n]
            setattr(self, name, grown)

    def remove(self, slot: int) -> None:
        """Forget ``slot``; the last slot moves into it (as in ``SlamState.remove``)."""
        del self._slot_of[int(self._ids[slot])]
        last = self._n - 1
        if slot != last:
            for name in self._ARRAYS:
                array = getattr(self, name)
                array[slot] = array[last]
            self._slot_of[int(self._ids[slot])] = slot
        self._n = last

    def sighted(self, slots: NDArray[np.int64], confirm_count: int) -> NDArray[np.int64]:
        """Count one sighting of each of the distinct ``slots``; returns the ids this confirms."""
        tentative = slots[~self._confirmed[slots]]
        self._seen[tentative] += 1
        newly = tentative[self._seen[tentative] >= confirm_count]
        self._confirmed[newly] = True
        return np.sort(self._ids[newly])

    def expired(self, stamp_ns: int, timeout_ns: int) -> NDArray[np.int64]:
        """Slots of tentative landmarks first seen ``timeout_ns`` or more before ``stamp_ns``, highest
        first."""
        n = self._n
        old = ~self._confirmed[:n] & (stamp_ns - self._born[:n] >= timeout_ns)
        return old.nonzero()[0][::-1]

    def slots_by_id(self, confirmed: bool) -> NDArray[np.int64]:
        """The confirmed (or the tentative) slots in ascending id order."""
        slots = (self._confirmed[: self._n] == confirmed).nonzero()[0]
        return slots[np.argsort(self._ids[slots], kind="stable")]
