"""Loop closure for LiDAR odometry: a keyframe pose graph, revisits found by correlative scan matching,
refined by registration, verified before they close a loop.

Keyframes and odometry edges
----------------------------
:class:`turtlelib.estimation.lidar_odometry.LidarOdometry` gives each scan ``k`` its pose ``T_k``
(``T_odom_body``) and the covariance ``Sigma_k`` of its motion since scan ``k-1`` (additive ``[x, y, theta]``
in the odometry frame, independent increments; its anchored increment, which leaves out the motion of the
steps without a scan that a registered scan re-anchored: "Anchored increments" there). A scan that moved
``keyframe_distance_m`` or turned ``keyframe_angle_rad`` from the newest keyframe becomes one: its points
(body frame, thinned to the registration's ``voxel_m``), pose and stamp. Between keyframes ``a`` and ``b`` the
anchored increments compose, with ``Sigma_w`` the covariance of the newest scan's pose given ``T_a``::

    Sigma_w <- A_k Sigma_w A_k^T + Sigma_k,     A_k = [[1, 0, -(y_k - y_k-1)], [0, 1, x_k - x_k-1], [0, 0, 1]]

(a heading error at scan ``k-1`` swings scan ``k`` about it), and the odometry edge is::

    Z_ab = T_a^-1 T_b,   S_ab = B Sigma_w B^T,   B = blkdiag(R(theta_a)^T, 1)

(the steps' covariances carry the local maps' own drift, which a registration cannot see:
:class:`~turtlelib.estimation.lidar_odometry.LidarOdometryConfig`'s ``drift_m2_per_m``, ``drift_rad2_per_m``).

Detection
---------
At each new keyframe ``j`` the candidates are the keyframes ``i`` at least ``min_travel_m`` back along the
path (older than anything the local map holds) whose estimated position is within ``max_distance_m`` of
``j``'s; the nearest is matched. The graph predicts ``Z_pred = q_i^-1 q_j`` with covariance ``S_pred``
(:meth:`turtlelib.smoothing.pose_graph.PoseGraph.relative_covariance`, which grows with the drift since the
last loop closed); the search window is ``window_sigmas`` standard deviations of it (the largest eigenvalue
for ``x, y``), clipped to ``[min_window_m, max_window_m]`` and ``[min_window_rad, max_window_rad]``. The
submap is keyframe ``i`` and its ``submap_keyframes`` neighbours on each side (that are old enough), in
``i``'s frame at the graph's estimates. The correlative matcher
(:mod:`turtlelib.sensing.correlative_matcher`) searches the window exhaustively; its best pose seeds the
registration (:func:`turtlelib.sensing.scan_registration.register`, prior ``refine_std_m``,
``refine_std_rad``), whose pose and covariance are the loop's measurement ``Z_loop``, ``S_loop``.

Continuing a saved graph
------------------------
A graph saved by an earlier session (:mod:`turtlelib.smoothing.graph_file`: map poses, points, path,
edges; :meth:`LoopClosure.saved_graph`) is loaded whole: its keyframes become poses held where they are by
anchors (priors of the gauge's covariance, :data:`turtlelib.smoothing.pose_graph.ANCHOR_COVARIANCE`), so
that a loop onto them bends only the new session (the map, grid and landmarks saved with them stay
right). The new session lives in its own odometry frame; its first step is placed at ``start_pose`` in the
map (``T_map_odom = T_start T_odom_body_first^-1``), and its first keyframe is linked to the loaded graph
by a prior there, ``N(T_map_odom T_odom_body, S_0)`` with ``S_0`` the start pose's covariance
``start_covariance`` composed with the odometry to that keyframe as ``Sigma_w`` composes it (plus the
floor of an edge). Its path goes on from the loaded graph's, ``min_travel_m`` past its end (no loaded
keyframe is in the new session's local map, so each is a candidate from the start). A loop onto a loaded
keyframe is detected and verified as any other: ``S_pred`` is the new session's drift since its start
over the start pose's prior.

Verification: a wrong loop must never close
-------------------------------------------
A loop edge bends the whole graph, so a match is taken only when every test passes, each for a reason:

1. ``score >= min_score``: the scan is explained by the submap (a match in a place never seen scores low);
2. ``runner_up <= max_ambiguity score``: no distinct pose (``distinct_m``, ``distinct_rad`` away) fits nearly
   as well: a corridor matches anywhere along itself, a symmetric room at each of its symmetries;
3. the registration converges, with ``matched >= min_inlier_fraction n`` of the scan's points on the submap,
   and is not degenerate (``weakest_std_m <= degenerate_std_m``): the scan alone pins all three directions
   (a corridor's length, held only by the prior, would be a guess);
4. ``nu^T (S_pred + S_loop)^-1 nu <= chi2_3(gate_probability)``, ``nu = Z_loop (-) Z_pred``: the loop is a
   correction the graph's own uncertainty allows (an identical room elsewhere is a correction of metres
   where the graph is sure to decimetres);
5. two in a row: a verified loop is held until the next keyframe's loop is verified too and they agree:
   the corrections ``C = T_i Z_loop T_j^-1`` (``T_map_body`` of the keyframe ``j`` as the loop places it,
   over where the graph has it) of the two differ by at most ``agree_m`` and ``agree_rad``. One scan that
   happens to fit (a person, a moved door, a repeated structure) is not a loop; two successive scans that
   fit the same correction are. Both loops are then added, with the Cauchy kernel of the graph as the last
   defence, and the graph is optimised.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from ..estimation.lidar_odometry import OdometryStep
from ..geometry.se2 import Transform2D, normalize_angle, right_composition_jacobian
from ..sensing.correlative_matcher import (
    CorrelativeConfig,
    CorrelativeMatch,
    LikelihoodGrid,
    correlative_match,
    thin_scan,
)
from ..sensing.scan_registration import (
    LocalMap,
    Registration,
    RegistrationConfig,
    register,
    voxel_centroids,
)
from ..util.validation import covariance, in_range, integer, positive, store
from .graph_file import SavedGraph
from .pose_graph import ANCHOR_COVARIANCE, PoseGraph, PoseGraphConfig
from .smoothing_problem import LoopEdge


@dataclass(frozen=True)
class LoopClosureConfig:
    """Loop closure (module docstring); lengths in m, angles in rad, all > 0 unless said (ValueError).

    * ``keyframe_distance_m``, ``keyframe_angle_rad``: how far a scan must be from the newest keyframe;
    * ``min_travel_m``: a candidate is at least this far back along the path;
    * ``max_distance_m``: and at most this far from the new keyframe (estimated);
    * ``window_sigmas``, ``min_window_m``, ``max_window_m``, ``min_window_rad``, ``max_window_rad``: the
      search window;
    * ``submap_keyframes`` (int >= 0): neighbours of the candidate on each side in its submap;
    * ``refine_std_m``, ``refine_std_rad``: the registration's prior around the correlative match;
    * ``min_score``, ``max_ambiguity``, ``min_inlier_fraction`` (in (0, 1]), ``gate_probability`` (in
      (0, 1)), ``agree_m``, ``agree_rad``: verification;
    * ``registration``, ``correlative``, ``graph``: the registration's, the matcher's and the graph's.
    """

    keyframe_distance_m: float = 1.0
    keyframe_angle_rad: float = 0.5
    min_travel_m: float = 10.0
    max_distance_m: float = 3.0
    window_sigmas: float = 3.0
    min_window_m: float = 0.5
    max_window_m: float = 6.0
    min_window_rad: float = 0.1
    max_window_rad: float = 0.6
    submap_keyframes: int = 5
    refine_std_m: float = 0.1
    refine_std_rad: float = 0.05
    min_score: float = 0.5
    max_ambiguity: float = 0.9
    min_inlier_fraction: float = 0.6
    gate_probability: float = 0.999
    agree_m: float = 0.3
    agree_rad: float = 0.05
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    correlative: CorrelativeConfig = field(default_factory=CorrelativeConfig)
    graph: PoseGraphConfig = field(default_factory=PoseGraphConfig)

    def __post_init__(self) -> None:
        store(
            self,
            (
                "keyframe_distance_m",
                "keyframe_angle_rad",
                "min_travel_m",
                "max_distance_m",
                "window_sigmas",
                "min_window_m",
                "max_window_m",
                "min_window_rad",
                "max_window_rad",
                "refine_std_m",
                "refine_std_rad",
                "agree_m",
                "agree_rad",
            ),
            positive,
        )
        store(self, ("submap_keyframes",), partial(integer, minimum=0))
        store(
            self,
            ("min_score", "max_ambiguity", "min_inlier_fraction"),
            partial(in_range, low=0.0, high=1.0, open_low=True),
        )
        store(
            self, ("gate_probability",), partial(in_range, low=0.0, high=1.0, open_low=True, open_high=True)
        )
        if self.min_window_m > self.max_window_m or self.min_window_rad > self.max_window_rad:
            raise ValueError("the search window's minimum must not exceed its maximum")
        for name, kind in (
            ("registration", RegistrationConfig),
            ("correlative", CorrelativeConfig),
            ("graph", PoseGraphConfig),
        ):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"{name} must be a {kind.__name__}, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class Keyframe:
    """A keyframe: its stamp (ns), its pose ``T_odom_body`` as the odometry gave it (a loaded keyframe's:
    its map pose, its session's odometry being gone), its points (n, 2, body frame, thinned) and the path
    travelled to it (m)."""

    t_ns: int
    T_odom_body: Transform2D
    p_body: NDArray[np.float64]
    path_m: float


class Verdict(enum.Enum):
    """What became of a loop candidate (module docstring, "Verification")."""

    ACCEPTED = "accepted"
    HELD = "held"  # verified, waiting for the next keyframe's loop to agree
    LOW_SCORE = "low score"
    AMBIGUOUS = "ambiguous"
    NO_REGISTRATION = "no registration"
    FEW_INLIERS = "few inliers"
    DEGENERATE = "degenerate"
    INCONSISTENT = "inconsistent"
    DISAGREE = "disagree"


@dataclass(frozen=True)
class LoopCandidate:
    """A match of keyframe ``j`` against the submap of keyframe ``i``: the graph's prediction ``Z_pred``
    with ``S_pred``, the correlative ``match``, the ``registration`` (None if not reached or failed), the
    loop's measurement ``Z_loop``, ``S_loop`` (frame ``i``, None unless registered), its ``nis`` against the
    prediction, and the ``verdict``."""

    i: int
    j: int
    Z_pred: Transform2D
    S_pred: NDArray[np.float64]
    match: CorrelativeMatch
    registration: Registration | None
    Z_loop: Transform2D | None
    S_loop: NDArray[np.float64] | None
    nis: float
    verdict: Verdict

    @property
    def verified(self) -> bool:
        """Whether the candidate passed tests 1-4 (module docstring)."""
        return self.verdict in (Verdict.ACCEPTED, Verdict.HELD)


class LoopClosure:
    """The keyframe pose graph of a LiDAR odometry run and its loops (module docstring). Feed every
    odometry step with :meth:`add_step`; the graph's keyframe poses (frame ``map``) are
    :attr:`graph`'s, and :meth:`map_from_odom` is the correction of the odometry at a keyframe.

    ``loaded``: a saved graph to continue (module docstring, "Continuing a saved graph"), its keyframes
    the first :attr:`n_loaded`; ``start_pose`` (``T_map_body`` of the first step; default: the odometry's
    own pose, the graph then in the odometry frame) and ``start_covariance`` (3, 3, positive
    semi-definite; default zero) place this session in it. ValueError for an invalid covariance."""

    def __init__(
        self,
        config: LoopClosureConfig | None = None,
        loaded: SavedGraph | None = None,
        start_pose: Transform2D | None = None,
        start_covariance: NDArray[np.float64] | None = None,
    ) -> None:
        self.config = LoopClosureConfig() if config is None else config
        self.graph = PoseGraph(self.config.graph)
        self.keyframes: list[Keyframe] = []
        self.candidates: list[LoopCandidate] = []
        self._start_pose = start_pose
        self._start_covariance = (
            np.zeros((3, 3))
            if start_covariance is None
            else covariance("start_covariance", start_covariance, (3, 3), definite=False)
        )
        # T_map_odom of this session, set at its first step
        self._T_map_odom: Transform2D | None = None
        self._session_path_m = 0.0
        if loaded is not None:
            self._load(loaded)
        self.n_loaded = len(self.keyframes)
        self._gate = float(chi2.ppf(self.config.gate_probability, 3))
        # the newest verified loop and its place in candidates
        self._held: LoopCandidate | None = None
        self._held_at = -1
        # since the newest keyframe: Sigma_w, the path (m), the previous scan's pose
        self._Sigma_w = np.zeros((3, 3))
        self._path_m = 0.0
        self._last_T: Transform2D | None = None

    def _load(self, loaded: SavedGraph) -> None:
        """The saved graph's keyframes, anchored, and its edges (module docstring)."""
        for k in range(loaded.n_keyframes):
            T_map = Transform2D(*loaded.T_map_keyframe[k])
            self.keyframes.append(
                Keyframe(int(loaded.t_ns[k]), T_map, loaded.points[k], float(loaded.path_m[k]))
            )
            self.graph.add_pose(T_map)
            if k:
                self.graph.add_prior(k, T_map, ANCHOR_COVARIANCE)
        for e in range(loaded.n_edges):
            Z, S = Transform2D(*loaded.edge_Z[e]), loaded.edge_S[e]
            self.graph.add_edge(
                int(loaded.edge_i[e]), int(loaded.edge_j[e]), Z, S, loop=bool(loaded.edge_loop[e])
            )
        if loaded.n_keyframes:
            self._session_path_m = float(loaded.path_m.max()) + self.config.min_travel_m

    @property
    def session_keyframe(self) -> int | None:
        """The index of this session's newest keyframe (None before its first)."""
        return len(self.keyframes) - 1 if len(self.keyframes) > self.n_loaded else None

    def saved_graph(self, T_map_graph: Transform2D | None = None) -> SavedGraph:
        """The graph to save (:mod:`turtlelib.smoothing.graph_file`): this session's keyframes at
        ``T_map_graph`` composed with their graph poses (the graph's frame in the map; default identity),
        the loaded ones where they were loaded; every edge."""
        T_map_graph = Transform2D() if T_map_graph is None else T_map_graph
        poses = [
            self.graph.pose(k) if k < self.n_loaded else T_map_graph @ self.graph.pose(k)
            for k in range(len(self.keyframes))
        ]
        i, j, loop = self.graph.edges()
        measurements = [self.graph.measurement(e) for e in range(self.graph.n_edges)]
        return SavedGraph(
            t_ns=np.array([k.t_ns for k in self.keyframes], dtype=np.int64),
            T_map_keyframe=np.array([T.as_array() for T in poses]).reshape(-1, 3),
            points=tuple(k.p_body for k in self.keyframes),
            path_m=np.array([k.path_m for k in self.keyframes]),
            edge_i=i,
            edge_j=j,
            edge_Z=np.array([Z.as_array() for Z, _ in measurements]).reshape(-1, 3),
            edge_S=np.array([S for _, S in measurements]).reshape(-1, 3, 3),
            edge_loop=loop,
        )

    def add_step(self, step: OdometryStep, p_body: NDArray[np.float64]) -> list[LoopCandidate]:
        """One odometry step and its scan's points ``p_body`` (n, 2, body frame): composed into the edge from
        the newest keyframe, and made a keyframe if it moved far enough (module docstring). Returns the
        loops accepted at this step (empty for most)."""
        T = step.T_odom_body
        if self._T_map_odom is None:
            self._start_session(T)
        elif self._last_T is not None:
            dx, dy = T.x - self._last_T.x, T.y - self._last_T.y
            # Sigma_w <- A Sigma_w A^T + Sigma_k
            A = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
            self._Sigma_w = A @ self._Sigma_w @ A.T + step.Sigma_anchored
            self._path_m += math.hypot(dx, dy)
        self._last_T = T
        if self.session_keyframe is not None:
            moved = self.keyframes[-1].T_odom_body.inverse() @ T
            far = math.hypot(moved.x, moved.y) >= self.config.keyframe_distance_m
            turned = abs(normalize_angle(moved.theta)) >= self.config.keyframe_angle_rad
            if not (far or turned):
                return []
        points = voxel_centroids(np.asarray(p_body, dtype=np.float64), self.config.registration.voxel_m)
        if len(points) < self.config.registration.min_points:
            return []
        return self._add_keyframe(step.t_ns, T, points)

    def _start_session(self, T: Transform2D) -> None:
        """This session's first step, at ``T_odom_body`` ``T``: ``T_map_odom`` from the start pose, and
        ``Sigma_w`` the start pose's covariance carried into the odometry frame (module docstring)."""
        start = T if self._start_pose is None else self._start_pose
        self._T_map_odom = start @ T.inverse()
        R = np.eye(3)
        R[:2, :2] = self._T_map_odom.rotation_matrix()
        self._reset_edge(T)
        self._Sigma_w = R.T @ self._start_covariance @ R

    def _add_keyframe(self, t_ns: int, T: Transform2D, points: NDArray[np.float64]) -> list[LoopCandidate]:
        if self.session_keyframe is None:
            path_m = self._session_path_m + self._path_m
            self.keyframes.append(Keyframe(t_ns, T, points, path_m))
            T_map = self._T_map_odom @ T
            b = self.graph.add_pose(T_map)
            if b:  # linked to the loaded graph by its start pose's prior: S_0 = R Sigma_w R^T + floor
                R = np.eye(3)
                R[:2, :2] = self._T_map_odom.rotation_matrix()
                self.graph.add_prior(b, T_map, _floored(R @ self._Sigma_w @ R.T))
        else:
            previous = self.keyframes[-1]
            path_m = previous.path_m + self._path_m
            a = len(self.keyframes) - 1
            # Z_ab = T_a^-1 T_b,  S_ab = B Sigma_w B^T
            Z = previous.T_odom_body.inverse() @ T
            B = np.eye(3)
            B[:2, :2] = previous.T_odom_body.rotation_matrix().T
            S = _floored(B @ self._Sigma_w @ B.T)
            self.keyframes.append(Keyframe(t_ns, T, points, path_m))
            b = self.graph.add_pose(self.graph.pose(a) @ Z)
            self.graph.add_edge(a, b, Z, S, loop=False)
        self._reset_edge(T)
        i = self._candidate(b)
        if i is None:
            return []
        candidate = self.match(i, b)
        return self._confirm(candidate)

    def _reset_edge(self, T: Transform2D) -> None:
        self._Sigma_w = np.zeros((3, 3))
        self._path_m = 0.0
        self._last_T = T

    def _candidate(self, j: int) -> int | None:
        """The nearest keyframe old enough to be a loop for keyframe ``j``, or None."""
        path = np.array([k.path_m for k in self.keyframes])
        old = np.flatnonzero(path[j] - path >= self.config.min_travel_m)
        if len(old) == 0:
            return None
        q = self.graph.poses
        distance = np.hypot(*(q[old, :2] - q[j, :2]).T)
        nearest = int(np.argmin(distance))
        return int(old[nearest]) if distance[nearest] <= self.config.max_distance_m else None

    def match(self, i: int, j: int, Z_guess: Transform2D | None = None) -> LoopCandidate:
        """Match keyframe ``j`` against the submap of keyframe ``i`` around the graph's prediction (or
        ``Z_guess``, a relative pose ``T_i^-1 T_j`` to search around instead) and verify it (tests 1-4 of
        the module docstring; the verdict is ``HELD`` when they pass). The graph is not changed."""
        config = self.config
        graph = self.graph
        Z_pred = graph.pose(i).inverse() @ graph.pose(j)
        S_pred = graph.relative_covariance(i, j)
        sigma_xy = math.sqrt(max(float(np.linalg.eigvalsh(S_pred[:2, :2])[-1]), 0.0))
        window_m = float(np.clip(config.window_sigmas * sigma_xy, config.min_window_m, config.max_window_m))
        window_rad = float(
            np.clip(
                config.window_sigmas * math.sqrt(S_pred[2, 2]), config.min_window_rad, config.max_window_rad
            )
        )
        q_submap = self._submap(i, j)
        grid = LikelihoodGrid(q_submap, config.correlative)
        p_j = self.keyframes[j].p_body
        guess = Z_pred if Z_guess is None else Z_guess
        found = correlative_match(thin_scan(p_j, config.correlative), grid, guess, window_m, window_rad)

        def verdict(v: Verdict, registration=None, Z=None, S=None, nis=math.nan) -> LoopCandidate:
            return LoopCandidate(i, j, Z_pred, S_pred, found, registration, Z, S, nis, v)

        if found.score < config.min_score:
            return verdict(Verdict.LOW_SCORE)
        if found.runner_up > config.max_ambiguity * found.score:
            return verdict(Verdict.AMBIGUOUS)
        P_refine = np.diag([config.refine_std_m**2, config.refine_std_m**2, config.refine_std_rad**2])
        local_map = LocalMap(voxel_centroids(q_submap, config.registration.voxel_m), config.registration)
        registration = register(p_j, local_map, found.T_submap_body, P_refine, config.registration)
        if registration is None:
            return verdict(Verdict.NO_REGISTRATION)
        Z_loop = registration.T_map_body
        # S_loop: the registered pose's covariance in i's frame (additive [x, y, theta] there)
        S_loop = registration.Sigma
        if registration.matched < config.min_inlier_fraction * len(p_j):
            return verdict(Verdict.FEW_INLIERS, registration, Z_loop, S_loop)
        if registration.degenerate:
            return verdict(Verdict.DEGENERATE, registration, Z_loop, S_loop)
        # nu = Z_loop (-) Z_pred,  nis = nu^T (S_pred + S_loop)^-1 nu
        nu = Z_loop.as_array() - Z_pred.as_array()
        nu[2] = normalize_angle(nu[2])
        nis = float(nu @ np.linalg.solve(S_pred + S_loop, nu))
        if nis > self._gate:
            return verdict(Verdict.INCONSISTENT, registration, Z_loop, S_loop, nis)
        return verdict(Verdict.HELD, registration, Z_loop, S_loop, nis)

    def _submap(self, i: int, j: int) -> NDArray[np.float64]:
        """The points (m, 2) of keyframe ``i`` and its old enough neighbours, in ``i``'s frame."""
        path = np.array([k.path_m for k in self.keyframes])
        n = self.config.submap_keyframes
        members = [
            k
            for k in range(max(0, i - n), min(len(self.keyframes), i + n + 1))
            if path[j] - path[k] >= self.config.min_travel_m or k == i
        ]
        T_i_inv = self.graph.pose(i).inverse()
        return np.concatenate([(T_i_inv @ self.graph.pose(k)) @ self.keyframes[k].p_body for k in members])

    def _confirm(self, candidate: LoopCandidate) -> list[LoopCandidate]:
        """Test 5 (module docstring): a verified loop is held; two in a row that agree are accepted."""
        if not candidate.verified:
            self.candidates.append(candidate)
            return []
        held, held_at = self._held, self._held_at
        self._held, self._held_at = candidate, len(self.candidates)
        self.candidates.append(candidate)
        if held is None or held.j != candidate.j - 1:
            return []
        # C = T_i Z_loop T_j^-1 for each; agree when C_held^-1 C_new moves keyframe j by little
        C_held = self.graph.pose(held.i) @ held.Z_loop @ self.graph.pose(held.j).inverse()
        C_new = self.graph.pose(candidate.i) @ candidate.Z_loop @ self.graph.pose(candidate.j).inverse()
        T_j = self.graph.pose(candidate.j)
        D = (C_held @ T_j).inverse() @ (C_new @ T_j)
        if math.hypot(D.x, D.y) > self.config.agree_m or abs(D.theta) > self.config.agree_rad:
            self.candidates[-1] = replace(candidate, verdict=Verdict.DISAGREE)
            return []
        accepted = [c for c in (held, candidate) if not self._in_graph(c)]
        for c in accepted:
            self.graph.add_edge(c.i, c.j, c.Z_loop, c.S_loop, loop=True)
        self.graph.optimise()
        for at in (held_at, len(self.candidates) - 1):
            self.candidates[at] = replace(self.candidates[at], verdict=Verdict.ACCEPTED)
        return [replace(c, verdict=Verdict.ACCEPTED) for c in accepted]

    def _in_graph(self, candidate: LoopCandidate) -> bool:
        i, j, loop = self.graph.edges()
        return bool(np.any(loop & (i == candidate.i) & (j == candidate.j)))

    def loop_edges(self) -> list[LoopEdge]:
        """This session's loops, each between its keyframes' stamps (for a smoother of the whole run:
        :func:`turtlelib.smoothing.run_smoothing.smooth_history`); a loop onto a loaded keyframe is left
        out (that keyframe has no pose in this run: its stamp is another session's)."""
        i, j, loop = self.graph.edges()
        ours = loop & (i >= self.n_loaded) & (j >= self.n_loaded)
        return [
            LoopEdge(self.keyframes[i[e]].t_ns, self.keyframes[j[e]].t_ns, *self.graph.measurement(e))
            for e in np.flatnonzero(ours)
        ]

    def map_from_odom(self, k: int | None = -1) -> Transform2D:
        """``T_map_odom`` at keyframe ``k`` of this session (the newest by default): the graph's pose of the
        keyframe over the odometry's, ``T_map_body T_odom_body^-1``; a scan after keyframe ``k`` is at
        ``T_map_odom T_odom_body``. Before this session's first keyframe (or ``k`` None), where its start
        placed it (identity before the first step)."""
        if self.session_keyframe is None or k is None:
            return Transform2D() if self._T_map_odom is None else self._T_map_odom
        k = range(len(self.keyframes))[k]
        return self.graph.pose(k) @ self.keyframes[k].T_odom_body.inverse()


def _floored(S: NDArray[np.float64]) -> NDArray[np.float64]:
    """``S`` made symmetric, plus a floor so that a robot standing still keeps an invertible edge or prior:
    (1 mm, 1 mrad)^2."""
    return 0.5 * (S + S.T) + 1e-6 * np.eye(3)


def relocalized(
    T_map_body: Transform2D,
    P_pose: NDArray[np.float64],
    T_l: Transform2D,
    C_old: Transform2D,
    C_new: Transform2D,
) -> tuple[Transform2D, NDArray[np.float64], Transform2D]:
    """A filter's pose ``T_map_body`` (covariance ``P_pose`` (3, 3)) moved by a change of the graph's
    correction of the odometry from ``C_old`` to ``C_new`` (``T_map_odom``:
    :meth:`LoopClosure.map_from_odom`), with ``T_l`` LiDAR odometry's pose at the filter's time: the change
    of the graph's pose of the body,
    applied in the body frame (so that the filter's own frame, its start pose and what landmarks did to it
    stay as they are)::

        D = (C_old T_l)^-1 (C_new T_l),   T' = T_map_body D,   P' = G P G^T

    (``G``: :func:`~turtlelib.geometry.se2.right_composition_jacobian` of ``T_map_body`` to ``T'``, the
    covariance carried along as a motion carries it). Returns ``(T', P', D)``."""
    D = (C_old @ T_l).inverse() @ (C_new @ T_l)
    T_new = T_map_body @ D
    G = right_composition_jacobian(T_map_body, T_new)
    return T_new, G @ P_pose @ G.T, D
