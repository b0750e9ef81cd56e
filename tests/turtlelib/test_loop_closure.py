"""Loop closure (turtlelib.smoothing.loop_closure), its pose graph (turtlelib.smoothing.pose_graph) and the
correlative matcher (turtlelib.sensing.correlative_matcher), against simulated scans with exact truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from turtlelib.estimation.lidar_odometry import Basis, OdometryStep, scan_points
from turtlelib.geometry.se2 import Transform2D
from turtlelib.sensing.correlative_matcher import (
    CorrelativeConfig,
    LikelihoodGrid,
    correlative_match,
    thin_scan,
)
from turtlelib.sensing.scan_model import LidarConfig, polygon_walls, simulate_scan
from turtlelib.smoothing.graph_file import load_graph, save_graph
from turtlelib.smoothing.loop_closure import LoopClosure, LoopClosureConfig, Verdict, relocalized
from turtlelib.smoothing.pose_graph import ANCHOR_COVARIANCE, PoseGraph

LIDAR = LidarConfig(range_max=6.0, noise=0.01)
# a ring of corridors 2.5 m wide around a block, with pillars that break its symmetry
RING = np.concatenate(
    [
        polygon_walls([[-5, -4], [5, -4], [5, 4], [-5, 4]]),
        polygon_walls([[-2.5, -1.5], [2.5, -1.5], [2.5, 1.5], [-2.5, 1.5]]),
    ]
)
RING_PILLARS = np.array([[4.4, -3.4, 0.15], [-1.0, 3.5, 0.2], [-4.5, -1.0, 0.1], [1.5, -3.6, 0.12]])
# a corridor 2 m wide and 40 m long, nothing along it
CORRIDOR = polygon_walls([[-20, -1], [20, -1], [20, 1], [-20, 1]])
# an L-shaped room with a pillar (as tests/turtlelib/test_scan_registration.py) and its twin 10 m east
ROOM_CORNERS = np.array([[-3, -2], [4, -2], [4, 1], [1, 1], [1, 3], [-3, 3]], dtype=float)
TWIN_ROOMS = np.concatenate([polygon_walls(ROOM_CORNERS), polygon_walls(ROOM_CORNERS + [10.0, 0.0])])
TWIN_PILLARS = np.array([[2.0, -0.5, 0.15], [12.0, -0.5, 0.15]])
# the odometry's noise per step: (m, m, rad) standard deviations, world-additive, as its Sigma says
STEP_STD = np.array([0.01, 0.01, 0.004])


def scan_at(T: Transform2D, walls, circles, rng) -> np.ndarray:
    """A simulated scan's points (body frame) from ``T`` (LiDAR at the body origin)."""
    return scan_points(LIDAR.range_scan(simulate_scan(T, circles, walls, LIDAR, rng)), Transform2D())


def path_through(waypoints, step_m: float = 0.25, turn_rad: float = 0.4) -> list[Transform2D]:
    """Poses along straight legs between ``waypoints`` (heading along each leg), turning in place between
    legs in steps of at most ``turn_rad``."""
    poses = []
    heading = None
    for a, b in zip(waypoints[:-1], waypoints[1:], strict=True):
        a, b = np.asarray(a, float), np.asarray(b, float)
        leg_heading = math.atan2(b[1] - a[1], b[0] - a[0])
        if heading is not None:
            turn = math.remainder(leg_heading - heading, math.tau)
            n = math.ceil(abs(turn) / turn_rad)
            poses += [Transform2D(a[0], a[1], heading + turn * k / n) for k in range(1, n)]
        n = math.ceil(np.linalg.norm(b - a) / step_m)
        poses += [Transform2D(*(a + (b - a) * k / n), leg_heading) for k in range(n)]
        heading = leg_heading
    return poses


def drive(loops: LoopClosure, truth, walls, circles, rng, noise_std=STEP_STD, bias_rad=0.0, odom_start=None):
    """Feed ``loops`` the odometry of the true poses drifting by ``bias_rad`` of heading per step, with
    random-walk noise of a quarter of ``noise_std`` per step (its Sigma ``diag(noise_std^2)``: bias and
    noise within it), scans simulated at the truth; the odometry starts at ``odom_start`` (default the
    true start pose). Returns the odometry's poses and the accepted loops."""
    T_odom = truth[0] if odom_start is None else odom_start
    odometry, accepted = [], []
    for k, T_true in enumerate(truth):
        if k:
            U = truth[k - 1].inverse() @ T_true
            T_odom = T_odom @ U
            noise = rng.normal(0.0, noise_std / 4.0) + [0.0, 0.0, bias_rad]
            T_odom = Transform2D(*(T_odom.as_array() + noise))
        odometry.append(T_odom)
        Sigma = np.diag(noise_std**2) * (k > 0)
        step = OdometryStep(k * 10**8, T_odom, Sigma, Basis.REGISTERED, None, 10**8, Sigma)
        accepted += loops.add_step(step, scan_at(T_true, walls, circles, rng))
    return odometry, accepted


def keyframe_errors(loops: LoopClosure, truth_at_keyframe: list[Transform2D], poses) -> np.ndarray:
    """Position errors (m) of keyframe ``poses`` (P, 3) against the truth."""
    return np.array(
        [math.hypot(q[0] - T.x, q[1] - T.y) for q, T in zip(poses, truth_at_keyframe, strict=True)]
    )


def test_a_drifting_loop_is_closed_and_the_graph_lands_on_the_truth():
    rng = np.random.default_rng(3)
    lap = [[-3.75, -2.75], [3.75, -2.75], [3.75, 2.75], [-3.75, 2.75], [-3.75, -2.75]]
    truth = path_through(lap + [[3.75, -2.75], [3.75, 0.0]])
    loops = LoopClosure(LoopClosureConfig())
    # a heading drift of 1.5 mrad per step: 0.16 rad over the lap, the end of it 0.9 m off
    odometry, accepted = drive(loops, truth, RING, RING_PILLARS, rng, bias_rad=0.0015)
    assert len(accepted) >= 2
    assert all(c.verdict is Verdict.ACCEPTED for c in accepted)
    # the loops as a smoother takes them: between their keyframes' stamps, as measured
    edges = loops.loop_edges()
    assert len(edges) == len(accepted)
    for edge, candidate in zip(edges, accepted, strict=True):
        assert (edge.t_a_ns, edge.t_b_ns) == (
            loops.keyframes[candidate.i].t_ns,
            loops.keyframes[candidate.j].t_ns,
        )
        np.testing.assert_array_equal(edge.Z.as_array(), candidate.Z_loop.as_array())
        np.testing.assert_array_equal(edge.S, candidate.S_loop)
    stamps = [keyframe.t_ns for keyframe in loops.keyframes]
    truth_kf = [truth[t // 10**8] for t in stamps]
    odometry_kf = np.array([odometry[t // 10**8].as_array() for t in stamps])
    closed = keyframe_errors(loops, truth_kf, loops.graph.poses)
    open_chain = keyframe_errors(loops, truth_kf, odometry_kf)
    # the loop pulls the end of the run back onto the truth; the open chain has drifted
    assert closed.max() < 0.12
    assert open_chain.max() > 0.6 and open_chain.max() > 5.0 * closed.max()


def test_a_continued_session_closes_a_loop_onto_the_saved_graph(tmp_path):
    rng = np.random.default_rng(11)
    # session 1: the bottom and right corridors of the ring, no loop; its odometry in a frame of its own
    first = path_through([[-3.75, -2.75], [3.75, -2.75], [3.75, 2.75]])
    session_1 = LoopClosure(start_pose=first[0])
    _, accepted = drive(session_1, first, RING, RING_PILLARS, rng, odom_start=Transform2D(1.0, 2.0, 0.5))
    assert accepted == []
    # the graph in the map: the first keyframe at the start pose
    np.testing.assert_allclose(session_1.graph.poses[0], first[0].as_array(), atol=1e-12)
    save_graph(tmp_path / "map.graph.npz", session_1.saved_graph())
    loaded = load_graph(tmp_path / "map.graph.npz")
    K = loaded.n_keyframes
    assert K == len(session_1.keyframes) and loaded.n_edges == K - 1
    # session 2 starts at the top left (its start pose known), drives down the left corridor and along the
    # bottom one that session 1 saw, its heading drifting by 3 mrad per step (in its Sigma, 4 mrad)
    second = path_through([[-3.75, 2.75], [-3.75, -2.75], [3.75, -2.75]])
    session_2 = LoopClosure(loaded=loaded, start_pose=second[0])
    bias = 0.003
    odometry, accepted = drive(
        session_2, second, RING, RING_PILLARS, rng, bias_rad=bias, odom_start=Transform2D(-2.0, 0.5, -1.0)
    )
    assert session_2.n_loaded == K
    # its path goes on min_travel_m past the loaded graph's end: every loaded keyframe a candidate at once
    assert session_2.keyframes[K].path_m == pytest.approx(
        loaded.path_m.max() + LoopClosureConfig().min_travel_m
    )
    # loops onto loaded keyframes, from this session's
    assert len(accepted) >= 2
    assert all(c.i < K <= c.j for c in accepted)
    assert session_2.loop_edges() == []  # none between this run's own keyframes, for its smoother
    # the loaded keyframes are anchors: they stay (to 1 mm: the anchor's standard deviation)
    assert np.abs(session_2.graph.poses[:K] - loaded.T_map_keyframe).max() < 1e-3
    # the open chain's heading at the last keyframe, 53 steps in, is off by the bias over them (0.159 rad,
    # +- the random walk of std 1 mrad per step, 7.3 mrad over them), its position by 0.7 m; the loops pull
    # it back onto the truth
    stamps = [k.t_ns for k in session_2.keyframes[K:]]
    T_map_odom = second[0] @ odometry[0].inverse()
    n = stamps[-1] // 10**8
    open_end, T_true = T_map_odom @ odometry[n], second[n]
    assert n == 53
    assert open_end.theta - T_true.theta == pytest.approx(n * bias, abs=0.025)
    assert math.hypot(open_end.x - T_true.x, open_end.y - T_true.y) > 0.6
    closed_end = session_2.graph.pose(len(session_2.keyframes) - 1)
    assert math.hypot(closed_end.x - T_true.x, closed_end.y - T_true.y) < 0.03
    assert abs(closed_end.theta - T_true.theta) < 0.01
    # saved again: both sessions' keyframes and the loops, for a third session
    again = session_2.saved_graph()
    assert again.n_keyframes == len(session_2.keyframes) and again.edge_loop.sum() == len(accepted)
    assert LoopClosure(loaded=again).n_loaded == again.n_keyframes


def test_a_corridor_never_closes_a_loop_along_itself():
    rng = np.random.default_rng(4)
    truth = path_through([[-12.0, 0.0], [2.0, 0.0], [-12.0, 0.0]])
    loops = LoopClosure()
    _, accepted = drive(loops, truth, CORRIDOR, np.zeros((0, 3)), rng)
    assert accepted == []
    assert loops.candidates, "the return leg must be offered as loops"
    # what it refuses, it refuses for the corridor's ambiguity
    assert {c.verdict for c in loops.candidates} <= {Verdict.AMBIGUOUS, Verdict.DEGENERATE, Verdict.LOW_SCORE}


def test_an_identical_room_elsewhere_is_refused_by_the_graph_it_contradicts():
    rng = np.random.default_rng(5)
    loops = LoopClosure()
    room_a = path_through([[-2.0, -1.0], [3.0, -1.0], [3.0, 0.0], [-2.0, 0.0], [-2.0, 2.0]])
    drive(loops, room_a, TWIN_ROOMS, TWIN_PILLARS, rng, noise_std=np.full(3, 1e-4))
    loop_edges = loops.graph.edges()[2].sum()
    # the robot goes on to the twin room, 10 m east, the graph knowing it to millimetres
    i = 2
    T_i = loops.graph.pose(i)
    T_j = T_i @ Transform2D(0.3, 0.2, 0.1)
    T_j_twin = Transform2D(T_j.x + 10.0, T_j.y, T_j.theta)
    Sigma = np.diag([1e-8, 1e-8, 1e-8])
    step = OdometryStep(10**12, T_j_twin, Sigma, Basis.REGISTERED, None, 10**8, Sigma)
    loops.add_step(step, scan_at(T_j_twin, TWIN_ROOMS, TWIN_PILLARS, rng))
    j = len(loops.keyframes) - 1
    # offered the room's perfect fit (keyframe j where i's room has it), the match is good ...
    wrong = loops.match(i, j, Z_guess=T_i.inverse() @ T_j)
    assert wrong.match.score > 0.8 and wrong.registration is not None and not wrong.registration.degenerate
    # ... and refused: 10 m where the graph allows millimetres
    assert wrong.verdict is Verdict.INCONSISTENT and wrong.nis > 1e4
    assert loops.graph.edges()[2].sum() == loop_edges


def test_correlative_matching_finds_the_pose_and_a_corridor_has_a_runner_up():
    config = CorrelativeConfig()
    rng = np.random.default_rng(6)
    room = polygon_walls(ROOM_CORNERS)
    pillar = TWIN_PILLARS[:1]
    submap = np.concatenate(
        [T @ scan_at(T, room, pillar, rng) for T in (Transform2D(), Transform2D(0.5, 0.3, 0.5))]
    )
    T_true = Transform2D(0.3, -0.4, 0.3)
    p = thin_scan(scan_at(T_true, room, pillar, rng), config)
    found = correlative_match(p, LikelihoodGrid(submap, config), Transform2D(0.9, 0.2, 0.1), 1.0, 0.4)
    assert abs(found.T_submap_body.x - T_true.x) <= config.resolution_m
    assert abs(found.T_submap_body.y - T_true.y) <= config.resolution_m
    assert abs(found.T_submap_body.theta - T_true.theta) <= math.radians(1.0)
    assert found.score > 0.9 and found.runner_up < 0.8 * found.score
    corridor = CORRIDOR
    submap = np.concatenate(
        [T @ scan_at(T, corridor, np.zeros((0, 3)), rng) for T in (Transform2D(), Transform2D(1.0, 0.0, 0.0))]
    )
    p = thin_scan(scan_at(Transform2D(0.2, 0.1, 0.05), corridor, np.zeros((0, 3)), rng), config)
    found = correlative_match(p, LikelihoodGrid(submap, config), Transform2D(0.9, 0.3, 0.1), 1.0, 0.4)
    assert found.runner_up > 0.9 * found.score


def test_correlative_search_is_exact_against_brute_force():
    """Branch and bound finds the best score of every pose of the window, evaluated one by one."""
    config = CorrelativeConfig(coarse_cells=4)
    rng = np.random.default_rng(8)
    submap = rng.uniform(-2.0, 2.0, size=(60, 2))
    p = thin_scan(rng.uniform(-2.0, 2.0, size=(40, 2)), config)
    grid = LikelihoodGrid(submap, config)
    found = correlative_match(p, grid, Transform2D(), 0.3, 0.05)
    r_90 = np.percentile(np.hypot(*p.T), 90)
    step = min(max(config.resolution_m / r_90, math.radians(0.25)), math.radians(2.0))
    best = 0.0
    for theta in step * np.arange(-math.floor(0.05 / step), math.floor(0.05 / step) + 1):
        for dx in range(-6, 7):
            for dy in range(-6, 7):
                T = Transform2D(dx * config.resolution_m, dy * config.resolution_m, theta)
                cells = grid.cells(T @ p)
                best = max(best, float(grid.lookup(grid.G, cells[:, 0], cells[:, 1]).mean()))
    assert found.score == pytest.approx(best, abs=1e-12)


def test_pose_graph_jacobians_match_finite_differences():
    rng = np.random.default_rng(9)
    graph = PoseGraph()
    for _ in range(4):
        graph.add_pose(Transform2D(*rng.normal(0.0, 1.0, 3)))
    for i, j, loop in ((0, 1, False), (1, 2, False), (2, 3, False), (3, 0, True), (1, 3, True)):
        S = np.diag(rng.uniform(0.01, 0.1, 3))
        graph.add_edge(i, j, Transform2D(*rng.normal(0.0, 1.0, 3)), S, loop=loop)
    x = graph.poses.ravel()
    J = graph.linearise(x).J.toarray()
    numeric = np.empty_like(J)
    h = 1e-6
    for k in range(len(x)):
        dx = np.zeros(len(x))
        dx[k] = h
        numeric[:, k] = (graph.linearise(x + dx).e - graph.linearise(x - dx).e) / (2 * h)
    np.testing.assert_allclose(J, numeric, atol=1e-6)


def test_a_graph_without_edges_lists_none_and_no_loop():
    graph = PoseGraph()
    graph.add_pose(Transform2D())
    i, j, loop = graph.edges()
    assert (i.dtype, j.dtype, loop.dtype) == (np.int64, np.int64, np.bool_)
    assert graph.poses[i[loop]].shape == (0, 3)  # a mask of no edge selects nothing (was float: IndexError)
    assert LoopClosure().loop_edges() == []


def test_a_loop_moves_the_filter_by_the_change_of_the_graph_s_pose_of_the_body():
    # the filter on LiDAR odometry's own pose (no landmark moved it): it lands where the new graph puts it
    T_l = Transform2D(4.0, 1.0, 0.3)
    C_old, C_new = Transform2D(), Transform2D(0.2, -0.1, 0.05)
    P = np.diag([0.01, 0.02, 0.003])
    T_new, P_new, D = relocalized(T_l, P, T_l, C_old, C_new)
    np.testing.assert_allclose(T_new.as_array(), (C_new @ T_l).as_array(), atol=1e-12)
    # a filter in another frame B (its start pose): moved by the same D in the body frame, so B stays
    B = Transform2D(-1.0, 2.0, 1.2)
    T_other, _, D_other = relocalized(B @ T_l, P, T_l, C_old, C_new)
    np.testing.assert_allclose(D_other.as_array(), D.as_array(), atol=1e-12)
    np.testing.assert_allclose(T_other.as_array(), (B @ C_new @ T_l).as_array(), atol=1e-12)
    # the covariance carried along the move: heading variance 0.003 swings the position by the move's lever
    dx, dy = T_new.x - T_l.x, T_new.y - T_l.y
    np.testing.assert_allclose(P_new[0, 0], 0.01 + dy**2 * 0.003, atol=1e-12)
    np.testing.assert_allclose(P_new[1, 1], 0.02 + dx**2 * 0.003, atol=1e-12)
    np.testing.assert_allclose(P_new[2, 2], 0.003, atol=1e-12)


def test_pose_graph_hand_computed():
    # two measurements of the same motion, (1, 0, 0) and (1.2, 0, 0), equally sure: the optimum between
    graph = PoseGraph()
    graph.add_pose(Transform2D())
    graph.add_pose(Transform2D(0.5, 0.3, 0.2))
    S = np.diag([1.0, 1.0, 1.0])
    graph.add_edge(0, 1, Transform2D(1.0, 0.0, 0.0), S, loop=False)
    graph.add_edge(0, 1, Transform2D(1.2, 0.0, 0.0), S, loop=True)
    solution = graph.optimise()
    # least squares gives 1.1; the kernel weighs the loop by 1 / (1 + 0.01 / 9): x = 1 + 0.2 w / (1 + w)
    w = 1.0 / (1.0 + 0.01 / 9.0)
    np.testing.assert_allclose(solution.poses[1], [1.0 + 0.2 * w / (1.0 + w), 0.0, 0.0], atol=1e-6)
    # a straight chain 0 -> 1 -> 2 along x, S = diag(a, b, c) on each edge: the heading error of the first
    # edge swings pose 2 by 1 m across: Sigma_02 = [[2a, 0, 0], [0, 2b + c, c], [0, c, 2c]]
    a, b, c = 0.04, 0.01, 0.002
    chain = PoseGraph()
    for x in (0.0, 1.0, 2.0):
        chain.add_pose(Transform2D(x, 0.0, 0.0))
    for i in (0, 1):
        chain.add_edge(i, i + 1, Transform2D(1.0, 0.0, 0.0), np.diag([a, b, c]), loop=False)
    expected = np.array([[2 * a, 0, 0], [0, 2 * b + c, c], [0, c, 2 * c]])
    np.testing.assert_allclose(chain.relative_covariance(0, 2), expected, atol=1e-9)
    # a prior on pose 1 at x = 1.2 against the edge's 1.0 from pose 0 (held by the gauge), equally sure:
    # between them, pose 0 moved by the gauge's share only (1e-6 of the pull)
    anchored = PoseGraph()
    anchored.add_pose(Transform2D())
    anchored.add_pose(Transform2D(1.0, 0.0, 0.0))
    anchored.add_edge(0, 1, Transform2D(1.0, 0.0, 0.0), S, loop=False)
    anchored.add_prior(1, Transform2D(1.2, 0.0, 0.0), S)
    np.testing.assert_allclose(anchored.optimise().poses, [[0.0, 0, 0], [1.1, 0, 0]], atol=1e-6)
    # an anchor's prior holds its pose as the gauge holds pose 0
    anchored.add_prior(1, Transform2D(1.0, 0.0, 0.0), ANCHOR_COVARIANCE)
    np.testing.assert_allclose(anchored.optimise().poses[1], [1.0, 0, 0], atol=1e-6)


def test_invalid_configuration_and_edges_are_refused():
    with pytest.raises(ValueError, match="min_score"):
        LoopClosureConfig(min_score=0.0)
    with pytest.raises(ValueError, match="window"):
        LoopClosureConfig(min_window_m=7.0, max_window_m=6.0)
    graph = PoseGraph()
    graph.add_pose(Transform2D())
    graph.add_pose(Transform2D())
    with pytest.raises(ValueError, match="distinct"):
        graph.add_edge(1, 1, Transform2D(), np.eye(3), loop=False)
    with pytest.raises(ValueError, match="covariance"):
        graph.add_edge(0, 1, Transform2D(), np.zeros((3, 3)), loop=False)


def test_an_odometry_edge_composes_the_anchored_increments():
    """The edge between two keyframes is what the steps' anchored increments compose to (by hand along a
    straight line: A = [[1, 0, 0], [0, 1, dx], [0, 0, 1]] per step, then into frame a), not the filter's
    increments, which also hold the input's motion between scans (here 100 times larger)."""
    rng = np.random.default_rng(5)
    loops = LoopClosure(LoopClosureConfig())
    anchored = np.diag([1e-6, 4e-6, 1e-6])
    S = np.zeros((3, 3))
    for k in range(6):  # 0.2 m a step: keyframes at 0 and 1 m
        T = Transform2D(0.2 * k, 0.0, 0.0)
        step = OdometryStep(k * 10**8, T, 100 * anchored, Basis.REGISTERED, None, 10**8, anchored * (k > 0))
        loops.add_step(step, scan_at(T, RING, RING_PILLARS, rng))
        if k:
            A = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.2], [0.0, 0.0, 1.0]])
            S = A @ S @ A.T + anchored
    assert len(loops.keyframes) == 2 and loops.graph.n_edges == 1
    _, S_edge = loops.graph.measurement(0)
    np.testing.assert_allclose(S_edge, S + 1e-6 * np.eye(3), rtol=1e-12, atol=1e-18)
