"""Central finite differences, the reference of every analytic Jacobian the tests check.

``J[:, i] = d(f(a + h e_i), f(a - h e_i)) / (2 h)``, with ``d`` the difference of two outputs: plain
subtraction, or :func:`wrapping` for outputs with angle entries, whose differences are taken in [-pi, pi]
(atan2 or a normalised heading may jump by 2 pi between the two evaluations). The truncation error is
``O(h^2)``, the rounding error ``O(eps |f| / h)``.
"""

import math
from collections.abc import Callable

import numpy as np

Difference = Callable[[np.ndarray, np.ndarray], np.ndarray]


def central_jacobian(
    f: Callable[[np.ndarray], np.ndarray],
    at: np.ndarray,
    difference: Difference = np.subtract,
    h: float = 1e-6,
) -> np.ndarray:
    """The (m, n) Jacobian of ``f``: R^n -> R^m at ``at`` (n,) by central differences of step ``h``."""
    at = np.asarray(at, dtype=float)
    columns = []
    for i in range(at.size):
        plus, minus = at.copy(), at.copy()
        plus[i] += h
        minus[i] -= h
        columns.append(difference(f(plus), f(minus)) / (2.0 * h))
    return np.column_stack(columns)


def wrapping(*angle_entries: int) -> Difference:
    """The difference ``a - b`` with entries ``angle_entries`` wrapped to [-pi, pi] (remainders of 2 pi)."""

    def difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        delta = np.subtract(a, b)
        for i in angle_entries:
            delta[i] = math.remainder(delta[i], math.tau)
        return delta

    return difference
