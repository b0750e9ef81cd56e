"""A pose graph over SE(2): poses linked by measured relative poses (odometry between consecutive keyframes,
loop closures between distant ones), optimised by sparse Levenberg-Marquardt.

Unknowns: poses ``q_k = [x, y, theta]`` (``T_map_body``; m, m, rad). Factors, each a residual ``r`` with a
Gaussian covariance ``S``::

    prior on k       r = q_k (-) q_bar                         S = S_prior
    edge e = (i, j)  r = (q_i^-1 q_j) (-) Z_e                  S = S_e

``Z_e = [x, y, theta]`` the relative pose ``T_i^-1 T_j`` measured in frame ``i`` and ``S_e`` its covariance
there (:func:`turtlelib.smoothing.sparse_least_squares.relative_pose_residuals` has the residual and its
Jacobians). Pose 0 gets a prior at its value when it was added, ``S = (1e-3 m, 1e-3 m, 1e-3 rad)^2 I``: the
gauge (its frame: the odometry's, or the map's). :meth:`PoseGraph.add_prior` adds others: a continued
session's loaded keyframes held at their map poses as anchors (the same tight prior), its own first keyframe
at its start pose (:mod:`turtlelib.smoothing.loop_closure`).

With ``e = S^-1/2 r`` and ``s_e = |e_e|^2`` an edge's squared Mahalanobis distance, the cost is::

    F(q) = 1/2 sum_priors |e_p|^2 + 1/2 sum_odometry s_e + 1/2 sum_loops rho(s_e),
    rho(s) = c^2 ln(1 + s / c^2)

the Cauchy kernel of width ``c`` (``loop_kernel``, whitened units) on the loop edges alone: a loop that
the rest of the graph contradicts costs only logarithmically (odometry edges are never outliers). It is
minimised as :class:`turtlelib.smoothing.smoother.Smoother` does: Levenberg-Marquardt, the kernel by
iteratively reweighted least squares (loop weights ``w_e = 1 / (1 + s_e / c^2)``), first without the kernel
from the current estimate (which may be far off after a long loop) and then with it from that optimum.

Marginals: the Laplace approximation ``Sigma = (J^T W J)^-1`` at the current estimate; the covariance of the
relative pose of ``i`` and ``j`` is ``[A B] Sigma_{ij} [A B]^T`` with ``A, B`` the relative pose's
Jacobians (:meth:`PoseGraph.relative_covariance`): what the graph predicts a loop between them may measure.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy import sparse

from ..geometry.se2 import Transform2D, normalize_angles
from ..util.validation import covariance, integer, positive, store
from .sparse_least_squares import (
    factorise,
    levenberg_marquardt,
    relative_pose_residuals,
    sparse_blocks,
    whitening,
)

# the gauge factor's standard deviation (m, m, rad)
_GAUGE_STD = 1e-3
# the gauge's covariance, also that of an anchor (PoseGraph.add_prior)
ANCHOR_COVARIANCE = _GAUGE_STD**2 * np.eye(3)


@dataclass(frozen=True)
class PoseGraphConfig:
    """``loop_kernel`` the Cauchy kernel's ``c`` on loop edges (whitened units, > 0); ``max_iterations``
    (int >= 1) linearisations per stage; ``tolerance`` (> 0) the relative cost decrease that ends a stage.
    ValueError for invalid values."""

    loop_kernel: float = 3.0
    max_iterations: int = 30
    tolerance: float = 1e-6

    def __post_init__(self) -> None:
        store(self, ("loop_kernel", "tolerance"), positive)
        store(self, ("max_iterations",), partial(integer, minimum=1))


@dataclass(frozen=True)
class GraphLinearisation:
    """At ``x`` (3P,): whitened, reweighted residuals ``e`` and their Jacobian ``J`` (rows: three per
    prior, then three per edge), each edge's squared Mahalanobis distance ``s`` (E,) and kernel weight ``w``
    (E,), the cost."""

    e: NDArray[np.float64]
    J: sparse.csr_matrix
    s: NDArray[np.float64]
    w: NDArray[np.float64]
    cost: float


@dataclass(frozen=True)
class GraphSolution:
    """An optimisation's result: the poses (P, 3), each edge's weight (E,) (1 for odometry; a loop's kernel
    weight: small for a loop the graph contradicts) and squared Mahalanobis distance (E,), the final cost
    and the linearisations used."""

    poses: NDArray[np.float64]
    weights: NDArray[np.float64]
    mahalanobis2: NDArray[np.float64]
    cost: float
    iterations: int


class PoseGraph:
    """Poses and relative-pose edges (module docstring). Poses are added in order and keep their index;
    :meth:`optimise` moves them all."""

    def __init__(self, config: PoseGraphConfig | None = None) -> None:
        self.config = PoseGraphConfig() if config is None else config
        self._poses: list[NDArray[np.float64]] = []
        self._i: list[int] = []
        self._j: list[int] = []
        self._Z: list[NDArray[np.float64]] = []
        self._S: list[NDArray[np.float64]] = []
        self._loop: list[bool] = []
        # priors: pose index, mean [x, y, theta], covariance
        self._prior_k: list[int] = []
        self._prior_q: list[NDArray[np.float64]] = []
        self._prior_S: list[NDArray[np.float64]] = []

    def __len__(self) -> int:
        return len(self._poses)

    @property
    def n_edges(self) -> int:
        return len(self._i)

    @property
    def poses(self) -> NDArray[np.float64]:
        """(P, 3) the current estimates ``[x, y, theta]``."""
        return np.array(self._poses).reshape(-1, 3)

    def pose(self, k: int) -> Transform2D:
        """Pose ``k``'s current estimate."""
        return Transform2D(*self._poses[k])

    def edges(self) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
        """``(i (E,), j (E,), loop (E,))``: each edge's poses and whether it is a loop edge."""
        return (
            np.array(self._i, dtype=np.int64),
            np.array(self._j, dtype=np.int64),
            np.array(self._loop, dtype=bool),
        )

    def measurement(self, e: int) -> tuple[Transform2D, NDArray[np.float64]]:
        """Edge ``e``'s measured relative pose ``Z_i_j`` and its covariance ``S`` (3, 3)."""
        return Transform2D(*self._Z[e]), self._S[e].copy()

    def add_pose(self, T_map_body: Transform2D) -> int:
        """Add a pose with its initial estimate; returns its index. The first pose fixes the gauge (a prior
        at its value, module docstring)."""
        self._poses.append(T_map_body.as_array())
        if len(self._poses) == 1:
            self.add_prior(0, T_map_body, ANCHOR_COVARIANCE)
        return len(self._poses) - 1

    def add_prior(self, k: int, T_map_body: Transform2D, S: NDArray[np.float64]) -> None:
        """A prior ``q_k ~ N(T_map_body, S)`` on pose ``k`` (``S`` (3, 3) positive definite, ``[x, y,
        theta]``; :data:`ANCHOR_COVARIANCE` holds the pose where it is). ValueError for an unknown pose or an
        invalid covariance."""
        k = integer("k", k, 0, len(self._poses) - 1)
        self._prior_S.append(covariance("prior covariance", S, (3, 3), definite=True))
        self._prior_k.append(k)
        self._prior_q.append(T_map_body.as_array())

    def add_edge(self, i: int, j: int, Z_i_j: Transform2D, S: NDArray[np.float64], *, loop: bool) -> int:
        """Add the measured relative pose ``Z_i_j = T_i^-1 T_j`` with covariance ``S`` (3, 3, positive
        definite, frame ``i``'s ``[x, y, theta]``) between poses ``i != j``; ``loop`` puts the robust kernel
        on it. Returns the edge's index. ValueError for an unknown pose or an invalid covariance."""
        n = len(self._poses)
        i, j = integer("i", i, 0, n - 1), integer("j", j, 0, n - 1)
        if i == j:
            raise ValueError(f"an edge joins two distinct poses, got {i} and {j}")
        self._S.append(covariance("edge covariance", S, (3, 3), definite=True))
        self._i.append(i)
        self._j.append(j)
        self._Z.append(Z_i_j.as_array())
        self._loop.append(bool(loop))
        return len(self._i) - 1

    def linearise(self, x: NDArray[np.float64], width: float = np.inf) -> GraphLinearisation:
        """The residuals and Jacobian at poses ``x`` (3P,), loop kernel of width ``width`` (inf: none)."""
        q = x.reshape(-1, 3)
        i, j, loop = self.edges()
        U = whitening(np.array(self._S).reshape(-1, 3, 3))
        k = np.array(self._prior_k, dtype=np.int64)
        U_prior = whitening(np.array(self._prior_S).reshape(-1, 3, 3))
        r_prior = q[k] - np.array(self._prior_q).reshape(-1, 3)
        r_prior[:, 2] = normalize_angles(r_prior[:, 2])
        e_prior = np.einsum("kij,kj->ki", U_prior, r_prior).ravel()
        r, A, B = relative_pose_residuals(q[i], q[j], np.array(self._Z).reshape(-1, 3))
        e_edge = np.einsum("kij,kj->ki", U, r)
        s = np.einsum("ki,ki->k", e_edge, e_edge)
        # IRLS on loop edges: rows scaled by sqrt(w), w = 1 / (1 + s / c^2)
        w = np.where(loop, 1.0 / (1.0 + s / width**2), 1.0) if np.isfinite(width) else np.ones(len(s))
        root_w = np.sqrt(w)[:, None]
        n_prior = 3 * len(k)
        rows = n_prior + 3 * np.arange(len(i))
        J = sparse_blocks(
            [
                (U_prior, 3 * np.arange(len(k)), 3 * k),
                ((U @ A) * root_w[:, :, None], rows, 3 * i),
                ((U @ B) * root_w[:, :, None], rows, 3 * j),
            ],
            (n_prior + 3 * len(i), len(x)),
        )
        e = np.concatenate([e_prior, (e_edge * root_w).ravel()])
        if np.isfinite(width):
            edge_cost = np.where(loop, width**2 * np.log1p(s / width**2), s)
        else:
            edge_cost = s
        cost = 0.5 * (float(np.sum(e_prior**2)) + float(np.sum(edge_cost)))
        return GraphLinearisation(e, J, s, w, cost)

    @staticmethod
    def retract(x: NDArray[np.float64], dx: NDArray[np.float64]) -> NDArray[np.float64]:
        """``x (+) dx``: added, headings wrapped."""
        moved = x + dx
        moved[2::3] = normalize_angles(moved[2::3])
        return moved

    def optimise(self) -> GraphSolution:
        """Minimise ``F`` (module docstring) from the current estimates, least squares first and then with
        the loop kernel; the poses are replaced by the optimum. ValueError for a graph whose poses are not
        all linked to a prior (through edges or their own)."""
        x = self.poses.ravel()
        iterations = 0
        for width in (np.inf, self.config.loop_kernel):
            x, lin, used = levenberg_marquardt(
                partial(self.linearise, width=width),
                self.retract,
                x,
                self.config.max_iterations,
                self.config.tolerance,
            )
            iterations += used
        self._poses = list(x.reshape(-1, 3).copy())
        return GraphSolution(self.poses, lin.w, lin.s, lin.cost, iterations)

    def relative_covariance(self, i: int, j: int) -> NDArray[np.float64]:
        """(3, 3) the covariance of the relative pose ``q_i^-1 q_j`` (frame ``i``'s ``[x, y, theta]``) at the
        current estimates (module docstring: the Laplace approximation, loop weights as they are there)."""
        x = self.poses.ravel()
        lin = self.linearise(x, self.config.loop_kernel)
        H = (lin.J.T @ lin.J).tocsc()
        columns = np.r_[3 * i + np.arange(3), 3 * j + np.arange(3)]
        rhs = np.zeros((len(x), 6))
        rhs[columns, np.arange(6)] = 1.0
        Sigma = factorise(H).solve(rhs)[columns]
        q = x.reshape(-1, 3)
        _, A, B = relative_pose_residuals(q[[i]], q[[j]], np.zeros((1, 3)))
        AB = np.concatenate([A[0], B[0]], axis=1)
        S = AB @ Sigma @ AB.T
        return 0.5 * (S + S.T)
