"""The sparse nonlinear least-squares machinery the smoothers share: whitening, the relative-pose factor,
Levenberg-Marquardt over sparse Jacobians, and the factorisation of the information matrix.

Relative-pose factor
--------------------
Poses ``q = [x, y, theta]`` (``T_map_body``; m, m, rad). The residual of a measured relative pose ``delta``
(frame ``i``'s ``[x, y, theta]``) between poses ``i`` and ``j``::

    r = (q_i^-1 q_j) (-) delta = [R(theta_i)^T (p_j - p_i) - delta_xy,  theta_j - theta_i - delta_theta]

(heading wrapped), with ``dx, dy = p_j - p_i``, ``c, s = cos theta_i, sin theta_i``::

    dr/dq_i = [[-c, -s, -s dx + c dy], [s, -c, -c dx - s dy], [0, 0, -1]]
    dr/dq_j = blkdiag(R(theta_i)^T, 1)

Levenberg-Marquardt
-------------------
With whitened residuals ``e`` (M,) and their sparse Jacobian ``J`` (M, N) at ``x`` (a kernel, if any, already
folded in as iteratively reweighted least squares)::

    (J^T J + lambda D) dx = -J^T e,     D = diag(J^T J)

``J^T J`` is factorised by SuperLU with a minimum-degree ordering of its symmetric pattern. A step that lowers
the cost ``F`` is taken and ``lambda`` divided by 10, else ``lambda`` is multiplied by 10; it stops when a
taken step lowers ``F`` by less than ``tolerance F``, after ``max_iterations`` linearisations, or when no
step lowers ``F`` (``lambda > 1e12``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse.linalg import splu

from ..geometry.se2 import normalize_angles

# the damping at the start, its floor, and the ceiling at which no step is found
_LAMBDA_START, _LAMBDA_MIN, _LAMBDA_MAX = 1e-6, 1e-12, 1e12


class Linearisation(Protocol):
    """At some ``x``: whitened (and reweighted) residuals ``e`` (M,), their Jacobian ``J`` (M, N), the
    cost ``F``."""

    @property
    def e(self) -> NDArray[np.float64]: ...

    @property
    def J(self) -> sparse.csr_matrix: ...

    @property
    def cost(self) -> float: ...


L = TypeVar("L", bound=Linearisation)


def levenberg_marquardt(
    linearise: Callable[[NDArray[np.float64]], L],
    retract: Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]],
    x: NDArray[np.float64],
    max_iterations: int,
    tolerance: float,
) -> tuple[NDArray[np.float64], L, int]:
    """Levenberg-Marquardt from ``x`` (module docstring): ``linearise(x)`` gives the residuals there,
    ``retract(x, dx)`` moves ``x`` by a step; returns the optimum, the linearisation there and the number of
    linearisations."""
    lam = _LAMBDA_START
    lin = linearise(x)
    for iteration in range(1, max_iterations + 1):
        H = (lin.J.T @ lin.J).tocsc()
        g = lin.J.T @ lin.e
        diagonal = H.diagonal()
        while True:
            step = factorise(H + sparse.diags(lam * diagonal, format="csc")).solve(-g)
            candidate = retract(x, step)
            trial = linearise(candidate)
            if trial.cost < lin.cost:
                break
            lam *= 10.0
            if lam > _LAMBDA_MAX:
                return x, lin, iteration
        decrease = lin.cost - trial.cost
        x, lin, lam = candidate, trial, max(lam / 10.0, _LAMBDA_MIN)
        if decrease < tolerance * lin.cost:
            return x, lin, iteration
    return x, lin, max_iterations


def relative_pose_residuals(
    q_i: NDArray[np.float64], q_j: NDArray[np.float64], delta: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(r (k, 3), dr/dq_i (k, 3, 3), dr/dq_j (k, 3, 3))`` of relative-pose factors between poses
    ``q_i`` (k, 3) and ``q_j`` (k, 3) measured as ``delta`` (k, 3) (module docstring)."""
    c, s = np.cos(q_i[:, 2]), np.sin(q_i[:, 2])
    dx, dy = q_j[:, 0] - q_i[:, 0], q_j[:, 1] - q_i[:, 1]
    r = np.column_stack([c * dx + s * dy, -s * dx + c * dy, q_j[:, 2] - q_i[:, 2]]) - delta
    r[:, 2] = normalize_angles(r[:, 2])
    A = np.zeros((len(q_i), 3, 3))
    A[:, 0, 0], A[:, 0, 1], A[:, 0, 2] = -c, -s, -s * dx + c * dy
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 2] = s, -c, -c * dx - s * dy
    A[:, 2, 2] = -1.0
    B = np.zeros((len(q_i), 3, 3))
    B[:, 0, 0], B[:, 0, 1], B[:, 1, 0], B[:, 1, 1], B[:, 2, 2] = c, s, -s, c, 1.0
    return r, A, B


def whitening(S: NDArray[np.float64]) -> NDArray[np.float64]:
    """``L^-1`` (k, d, d) for covariances ``S = L L^T`` (k, d, d): ``e = L^-1 r`` has unit covariance."""
    L = np.linalg.cholesky(S)
    return np.linalg.solve(L, np.broadcast_to(np.eye(S.shape[-1]), S.shape))


def factorise(H: sparse.csc_matrix):
    """SuperLU of the symmetric positive definite ``H``: a minimum-degree ordering of its pattern, the
    diagonal as pivots (no row exchanges, so the ordering is kept). ValueError for a singular ``H`` (a
    variable no factor constrains)."""
    try:
        return splu(H, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError as error:
        raise ValueError(f"the least-squares problem has no unique optimum ({error})") from error


def sparse_blocks(
    blocks: list[tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]], shape: tuple[int, int]
) -> sparse.csr_matrix:
    """The sparse matrix of dense blocks ``(values (k, a, b), row0 (k,), col0 (k,))``: block ``n`` at rows
    ``row0[n]..+a`` and columns ``col0[n]..+b``."""
    rows, cols, vals = [], [], []
    for values, row0, col0 in blocks:
        _, a, b = values.shape
        rows.append((row0[:, None, None] + np.arange(a)[None, :, None] + np.zeros((1, 1, b), int)).ravel())
        cols.append((col0[:, None, None] + np.zeros((1, a, 1), int) + np.arange(b)[None, None, :]).ravel())
        vals.append(values.ravel())
    return sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape
    )
