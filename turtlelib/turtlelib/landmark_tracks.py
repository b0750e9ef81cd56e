"""Bookkeeping of EKF SLAM landmark slots: id, sightings, scan of creation, confirmed or tentative.

The slots mirror :class:`turtlelib.slam_state.SlamState`'s: :meth:`LandmarkTracks.append` adds the last
slot, :meth:`LandmarkTracks.remove` swap-removes exactly as ``SlamState.remove`` does. Arrays grow with
spare capacity; every query is vectorised (O(n) numpy, no per-landmark Python loop).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


class LandmarkTracks:
    """Per-slot ``ids``, ``seen`` (sightings), ``born`` (scan of creation) and ``confirmed`` flags."""

    def __init__(self, capacity: int = 16) -> None:
        self._ids = np.zeros(capacity, dtype=np.int64)
        self._seen = np.zeros(capacity, dtype=np.int64)
        self._born = np.zeros(capacity, dtype=np.int64)
        self._confirmed = np.zeros(capacity, dtype=bool)
        self._n = 0
        self._slot_of: dict[int, int] = {}

    @property
    def ids(self) -> NDArray[np.int64]:
        """Landmark id of every slot (n,), a view."""
        return self._ids[: self._n]

    @property
    def confirmed(self) -> NDArray[np.bool_]:
        """Confirmed flag of every slot (n,), a view."""
        return self._confirmed[: self._n]

    def slot(self, landmark_id: int) -> int | None:
        """The slot of ``landmark_id``, or None."""
        return self._slot_of.get(landmark_id)

    def append(self, landmark_id: int, scan: int, confirmed: bool) -> int:
        """A new last slot for ``landmark_id`` first seen in ``scan``; returns the slot."""
        if self._n == len(self._ids):
            for name in ("_ids", "_seen", "_born", "_confirmed"):
                old = getattr(self, name)
                grown = np.zeros(2 * len(old), dtype=old.dtype)
                grown[: self._n] = old
                setattr(self, name, grown)
        slot = self._n
        self._ids[slot], self._seen[slot], self._born[slot] = landmark_id, 1, scan
        self._confirmed[slot] = confirmed
        self._slot_of[landmark_id] = slot
        self._n += 1
        return slot

    def remove(self, slot: int) -> None:
        """Forget ``slot``; the last slot moves into it (as in ``SlamState.remove``)."""
        del self._slot_of[int(self._ids[slot])]
        last = self._n - 1
        if slot != last:
            for array in (self._ids, self._seen, self._born, self._confirmed):
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

    def expired(self, scan: int, timeout: int) -> NDArray[np.int64]:
        """Slots of tentative landmarks created ``timeout`` or more scans before ``scan``, highest first."""
        n = self._n
        old = ~self._confirmed[:n] & (scan - self._born[:n] >= timeout)
        return old.nonzero()[0][::-1]

    def slots_by_id(self, confirmed: bool) -> NDArray[np.int64]:
        """The confirmed (or the tentative) slots in ascending id order."""
        slots = (self._confirmed[: self._n] == confirmed).nonzero()[0]
        return slots[np.argsort(self._ids[slots], kind="stable")]
