"""Filter consistency: NEES, NIS and the chi2 bounds to judge them (Bar-Shalom, Li & Kirubarajan, 5.4).

* NEES ``eps = e^T P^-1 e`` of the estimation error ``e = x_true - x_hat`` (d,) against the filter's
  covariance ``P``: chi2 with ``d`` dof when the filter is consistent.
* NIS ``eps_nu = nu^T S^-1 nu`` of an innovation ``nu`` against its predicted covariance ``S``.
* Over ``n_runs`` independent Monte Carlo runs, ``n_runs * mean(eps)`` is chi2 with ``n_runs d`` dof, so
  the average lies in ``chi2_bounds(d, n_runs, prob)`` with probability ``prob``.

Angle components of ``e`` and ``nu`` must be wrapped by the caller. A singular covariance (positive
semi-definite but not definite, e.g. the exactly known start pose of a filter before it moves) has no NEES:
it is skipped as NaN, so averages over a run use ``np.nanmean``. An indefinite one is an error.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtri

from ..util.validation import covariance as checked_covariance

# P with smallest / largest eigenvalue at or below this is singular: no NEES (not an error)
SINGULAR_EIGENVALUE_RTOL = 1e-12


def nees(error: ArrayLike, covariance: ArrayLike, atol: float = 0.0) -> float | NDArray[np.float64]:
    """``e^T P^-1 e`` for ``error`` (..., d) and ``covariance`` (..., d, d) (stacks broadcast).

    Solved through a Cholesky factor, never inverted. NaN where ``P`` is singular: its smallest eigenvalue
    at most ``SINGULAR_EIGENVALUE_RTOL`` times its largest, or at most ``atol`` (in the units of ``P``: a
    floor below which a variance counts as zero). ValueError unless the shapes agree, ``e`` is finite and
    every ``P`` a covariance (finite, symmetric, positive semi-definite:
    :func:`turtlelib.util.validation.covariance`).
    """
    e = np.asarray(error, dtype=np.float64)
    P = np.asarray(covariance, dtype=np.float64)
    if e.ndim < 1 or P.shape[-2:] != (e.shape[-1], e.shape[-1]):
        raise ValueError(f"error (..., d) and covariance (..., d, d) disagree: {e.shape}, {P.shape}")
    if not np.all(np.isfinite(e)):
        raise ValueError("error must be finite")
    P = checked_covariance("covariance", P, P.shape, definite=False)
    e, P = np.broadcast_arrays(e[..., None], P)
    e = e[..., 0]
    eigenvalues = np.linalg.eigvalsh(P)
    scale = np.maximum(np.abs(eigenvalues).max(axis=-1), np.finfo(float).tiny)
    definite = eigenvalues[..., 0] > np.maximum(SINGULAR_EIGENVALUE_RTOL * scale, atol)
    result = np.full(definite.shape, np.nan)
    if np.any(definite):
        L = np.linalg.cholesky(P[definite])
        # w = L^-1 e,  eps = |w|^2
        w = np.linalg.solve(L, e[definite][..., None])[..., 0]
        result[definite] = np.einsum("...i,...i->...", w, w)
    return float(result) if result.ndim == 0 else result


def nis(innovation: ArrayLike, S: ArrayLike) -> float | NDArray[np.float64]:
    """``nu^T S^-1 nu`` for ``innovation`` (..., d) and its covariance ``S`` (..., d, d); see :func:`nees`."""
    return nees(innovation, S)


def chi2_bounds(dof: int, n_runs: int, prob: float = 0.95) -> tuple[float, float]:
    """Two-sided ``prob`` interval ``(low, high)`` of the average over ``n_runs`` of a chi2_dof statistic.

    ``n_runs * average ~ chi2(n_runs dof)``: ``low = q((1 - prob)/2) / n_runs``,
    ``high = q((1 + prob)/2) / n_runs`` with ``q`` its quantile function.
    """
    if isinstance(dof, bool) or not (isinstance(dof, (int, np.integer)) and dof >= 1):
        raise ValueError(f"dof must be an integer >= 1, got {dof!r}")
    if isinstance(n_runs, bool) or not (isinstance(n_runs, (int, np.integer)) and n_runs >= 1):
        raise ValueError(f"n_runs must be an integer >= 1, got {n_runs!r}")
    if not 0.0 < prob < 1.0:
        raise ValueError(f"prob must lie in (0, 1), got {prob!r}")
    total_dof = dof * n_runs
    tail = 0.5 * (1.0 - prob)
    # P(chi2 <= low) = tail,  P(chi2 > high) = tail
    low = float(chdtri(total_dof, 1.0 - tail)) / n_runs
    high = float(chdtri(total_dof, tail)) / n_runs
    return low, high
