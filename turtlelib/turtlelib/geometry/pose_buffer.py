"""A bounded buffer of stamped poses, read at any time between its samples.

Between consecutive samples ``(t0, T0)``, ``(t1, T1)`` (integer ns) the body is taken to move along one
constant twist, so the pose at ``t`` in ``[t0, t1]`` is::

    T(t) = T0 exp(s log(T0^-1 T1)),   s = (t - t0) / (t1 - t0)

Outside the buffered span there is no pose (``None``): a transform is never extrapolated.
"""

from __future__ import annotations

import bisect

from ..util.validation import integer
from .se2 import Transform2D, integrate_twist


class PoseBuffer:
    """The newest ``max_samples`` (>= 2) poses by increasing stamp."""

    def __init__(self, max_samples: int) -> None:
        self._max = integer("max_samples", max_samples, minimum=2)
        self._times: list[int] = []
        self._poses: list[Transform2D] = []

    def __len__(self) -> int:
        return len(self._times)

    @property
    def latest_time_ns(self) -> int | None:
        return self._times[-1] if self._times else None

    def add(self, t_ns: int, T: Transform2D) -> None:
        """Append a pose; ValueError for a stamp not after the newest (``clear`` first after a time jump)."""
        t_ns = integer("pose stamp (ns)", t_ns)
        if self._times and t_ns <= self._times[-1]:
            raise ValueError(f"pose stamp {t_ns} ns is not after the newest, {self._times[-1]} ns")
        self._times.append(t_ns)
        self._poses.append(T)
        if len(self._times) > self._max:
            del self._times[0], self._poses[0]

    def clear(self) -> None:
        self._times.clear()
        self._poses.clear()

    def at(self, t_ns: int) -> Transform2D | None:
        """The pose at ``t_ns`` (module docstring), or None outside the buffered span."""
        k = bisect.bisect_left(self._times, t_ns)
        if k == len(self._times):
            return None
        if self._times[k] == t_ns:
            return self._poses[k]
        if k == 0:
            return None
        t0, t1 = self._times[k - 1], self._times[k]
        T0 = self._poses[k - 1]
        # T(t) = T0 exp(s log(T0^-1 T1))
        return T0 @ integrate_twist((T0.inverse() @ self._poses[k]).log() * ((t_ns - t0) / (t1 - t0)))
