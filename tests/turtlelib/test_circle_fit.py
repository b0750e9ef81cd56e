"""turtlelib.sensing.circle_fit: the hyper fit (single and batched) and the range-sensor refinement.

Independent references: hand-computed circles through exact points, and the hyper fit's definition
(the generalised eigenvector of ``M A = eta H A`` with the smallest non-negative ``eta``) solved with
scipy.linalg.eig on the raw, unscaled moments. Properties: exact recovery on arcs (down to short arcs),
invariance under rotation, translation and scaling, batch = one-by-one. The Gauss-Newton refinement is
checked for quadratic convergence (a wrong Jacobian converges at best linearly) and, by Monte Carlo, for
beating the isotropic fit on simulated LiDAR data.
"""

import dataclasses
import math

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import (
    Circle,
    CircleFits,
    LidarConfig,
    Transform2D,
    fit_circle,
    fit_circles,
    refine_for_range_sensor,
    simulate_scan,
)

PI = math.pi
NON_FINITE = [math.nan, math.inf, -math.inf]


def arc_points(cx: float, cy: float, radius: float, start: float, span: float, n: int) -> np.ndarray:
    t = start + span * np.linspace(0.0, 1.0, n)
    return np.column_stack((cx + radius * np.cos(t), cy + radius * np.sin(t)))


def reference_hyper_fit(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The hyper fit from its definition: scipy's generalised eigensolver on the unscaled moments.

    The points are centred first (the fit is translation invariant, tested separately): raw moments of a
    small circle far from the origin lose digits to cancellation.
    """
    origin = points.mean(axis=0)
    points = points - origin
    x, y = points[:, 0], points[:, 1]
    z = x * x + y * y
    rows = np.column_stack((z, x, y, np.ones_like(x)))
    moments = rows.T @ rows / len(points)
    x_bar, y_bar, z_bar = x.mean(), y.mean(), z.mean()
    # H = 2 T - P: twice Taubin's constraint minus Pratt's
    taubin = np.array(
        [
            [4.0 * z_bar, 2.0 * x_bar, 2.0 * y_bar, 0.0],
            [2.0 * x_bar, 1.0, 0.0, 0.0],
            [2.0 * y_bar, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 0.0],
        ]
    )
    pratt = np.array(
        [[0.0, 0.0, 0.0, -2.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [-2.0, 0.0, 0.0, 0.0]]
    )
    constraint = 2.0 * taubin - pratt
    eta, vectors = scipy.linalg.eig(moments, constraint)
    eta = eta.real
    candidates = np.flatnonzero(eta >= 0.0)
    a = vectors[:, candidates[np.argmin(eta[candidates])]].real
    centre = origin - a[1:3] / (2.0 * a[0])
    return centre, math.sqrt(a[1] ** 2 + a[2] ** 2 - 4.0 * a[0] * a[3]) / (2.0 * abs(a[0]))


# --- Circle ------------------------------------------------------------------------------------------


def test_circle_is_a_frozen_value():
    circle = Circle(1, -2, 0.5)
    assert (circle.x, circle.y, circle.radius) == (1.0, -2.0, 0.5)
    np.testing.assert_array_equal(circle.centre, [1.0, -2.0])
    with pytest.raises(dataclasses.FrozenInstanceError):
        circle.radius = 1.0


@pytest.mark.parametrize(
    ("x", "y", "radius"),
    [(0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (math.nan, 0.0, 1.0), (0.0, math.inf, 1.0), (0.0, 0.0, math.inf)],
)
def test_circle_rejects_invalid_fields(x, y, radius):
    with pytest.raises(ValueError):
        Circle(x, y, radius)


# --- fit_circle: hand-computed cases -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("points", "expected"),
    [
        # three points on the unit circle
        ([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)], (0.0, 0.0, 1.0)),
        # (0, 0), (2, 0), (1, 1): the perpendicular bisector x = 1 meets |c - (0, 0)| = |c - (1, 1)| at (1, 0)
        ([(0.0, 0.0), (2.0, 0.0), (1.0, 1.0)], (1.0, 0.0, 1.0)),
        # the corners of a square lie on its circumcircle
        ([(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)], (0.0, 0.0, math.sqrt(2.0))),
        # four points of the circle centre (3, -2), r = 5
        ([(8.0, -2.0), (3.0, 3.0), (-2.0, -2.0), (3.0, -7.0)], (3.0, -2.0, 5.0)),
        # the 3-4-5 triangle's hypotenuse is a diameter of its circumcircle
        ([(0.0, 0.0), (4.0, 0.0), (0.0, 3.0)], (2.0, 1.5, 2.5)),
    ],
)
def test_fit_circle_hand_cases(points, expected):
    circle = fit_circle(np.array(points))
    assert (circle.x, circle.y, circle.radius) == pytest.approx(expected, abs=1e-12)


def test_fit_circle_symmetric_noisy_points_hand_case():
    # eight points at 45 deg steps, radii alternating 1.1 and 0.9: by symmetry the centre is the origin,
    # and the fit minimises the algebraic error over R alone
    angles = np.arange(8) * PI / 4.0
    radii = np.where(np.arange(8) % 2 == 0, 1.1, 0.9)
    points = np.column_stack((radii * np.cos(angles), radii * np.sin(angles)))
    circle = fit_circle(points)
    assert (circle.x, circle.y) == pytest.approx((0.0, 0.0), abs=1e-12)
    _, reference_radius = reference_hyper_fit(points)
    assert circle.radius == pytest.approx(reference_radius, abs=1e-12)
    # the residual of the batch fit is the RMS of |p - c| - R
    fits = fit_circles(points, [0, 8])
    expected_residual = math.sqrt(np.mean((radii - circle.radius) ** 2))
    assert fits.residual[0] == pytest.approx(expected_residual, abs=1e-12)


@settings(max_examples=150, deadline=None)
@given(
    cx=st.floats(-20.0, 20.0),
    cy=st.floats(-20.0, 20.0),
    radius=st.floats(0.01, 50.0),
    start=st.floats(-PI, PI),
    span=st.floats(0.2, 2.0 * PI),
    n=st.integers(3, 60),
)
def test_fit_circle_recovers_exact_arcs(cx, cy, radius, start, span, n):
    if n * 1e-3 > span and n > 3:
        n = 3  # keep the points distinct
    circle = fit_circle(arc_points(cx, cy, radius, start, min(span, 2.0 * PI * (n - 1) / n), n))
    scale = max(radius, abs(cx), abs(cy), 1.0)
    assert (circle.x, circle.y, circle.radius) == pytest.approx((cx, cy, radius), rel=0.0, abs=1e-8 * scale)


@pytest.mark.parametrize("span", [0.01, 0.05, 0.1])
def test_fit_circle_recovers_short_exact_arcs(span):
    # a 1 m circle seen over 0.6-6 deg: the conditioning degrades like 1 / span^2
    circle = fit_circle(arc_points(2.0, -1.0, 1.0, 0.3, span, 12))
    assert (circle.x, circle.y, circle.radius) == pytest.approx((2.0, -1.0, 1.0), abs=1e-12 / span**2)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(4, 40), span=st.floats(0.5, 2.0 * PI))
def test_fit_circle_matches_the_generalised_eigenproblem_on_noisy_arcs(seed, n, span):
    rng = np.random.default_rng(seed)
    radius = rng.uniform(0.05, 5.0)
    points = arc_points(*rng.uniform(-3.0, 3.0, 2), radius, rng.uniform(-PI, PI), span, n)
    points += rng.normal(0.0, 0.02 * radius, points.shape)
    circle = fit_circle(points)
    centre, reference_radius = reference_hyper_fit(points)
    # relative to the fit's own size as well: four noisy points of a short arc can fit a circle of km
    # radius (nearly a line), which both solvers find to 1e-10 of its size
    np.testing.assert_allclose(
        [circle.x, circle.y, circle.radius],
        [*centre, reference_radius],
        rtol=1e-9,
        atol=1e-7 * (1.0 + radius),
    )


def test_fit_circle_is_nearly_unbiased_on_noisy_half_arcs():
    # Monte Carlo: 20 points on a half circle, sigma = 5% of R; the hyper fit has no essential bias, so the
    # mean radius error is small next to sigma and within a few standard errors of its O(sigma^2 / (n R))
    rng = np.random.default_rng(11)
    radius, sigma, trials = 1.0, 0.05, 3000
    base = arc_points(0.0, 0.0, radius, 0.0, PI, 20)
    radii = [fit_circle(base + rng.normal(0.0, sigma, base.shape)).radius for _ in range(trials)]
    errors = np.array(radii) - radius
    standard_error = errors.std() / math.sqrt(trials)
    assert abs(errors.mean()) < 0.05 * sigma
    assert abs(errors.mean()) < 4.0 * standard_error + sigma**2 / radius
    # and its spread is the noise level's order (KCR bound for a half arc: a few sigma / sqrt(n))
    assert 0.5 * sigma / math.sqrt(20) < errors.std() < 5.0 * sigma / math.sqrt(20)


# --- invariance --------------------------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    pose=st.builds(Transform2D, st.floats(-50.0, 50.0), st.floats(-50.0, 50.0), st.floats(-PI, PI)),
    scale=st.floats(0.01, 100.0),
)
def test_fit_is_invariant_under_rotation_translation_and_scaling(seed, pose, scale):
    rng = np.random.default_rng(seed)
    centre, radius = rng.uniform(-2.0, 2.0, 2), rng.uniform(0.1, 2.0)
    points = arc_points(*centre, radius, rng.uniform(-PI, PI), rng.uniform(0.5, 4.0), 15)
    points += rng.normal(0.0, 0.02, points.shape)
    circle = fit_circle(points)
    moved = fit_circle(pose @ (scale * points))
    expected_centre = pose @ (scale * circle.centre)
    tolerance = 1e-9 * (scale * (1.0 + circle.radius) + abs(pose.x) + abs(pose.y))
    np.testing.assert_allclose(moved.centre, expected_centre, rtol=0.0, atol=tolerance)
    assert moved.radius == pytest.approx(scale * circle.radius, rel=1e-9)


# --- degenerate and invalid input --------------------------------------------------------------------


@pytest.mark.parametrize(
    "points",
    [
        [(0.0, 0.0), (1.0, 1.0), (2.0, 2.0)],
        [(0.0, 1.0), (1.0, 1.0), (2.0, 1.0), (5.0, 1.0)],
        [(3.0, -1.0), (3.0, 0.0), (3.0, 7.0)],
    ],
)
def test_collinear_points_have_no_finite_circle(points):
    with pytest.raises(ValueError, match="collinear"):
        fit_circle(np.array(points))
    fits = fit_circles(np.array(points), [0, len(points)])
    assert fits.radius[0] == math.inf and np.isnan(fits.centre[0]).all() and math.isnan(fits.residual[0])
    assert not fits.is_circle[0]


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 30))
def test_points_collinear_to_rounding_give_a_line_or_a_huge_circle(seed, n):
    rng = np.random.default_rng(seed)
    origin, direction = rng.uniform(-10.0, 10.0, 2), rng.normal(size=2)
    points = origin + np.sort(rng.uniform(-5.0, 5.0, n))[:, None] * direction
    if np.unique(points, axis=0).shape[0] >= 3:
        fits = fit_circles(points, [0, n])
        spread = math.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1)))
        assert not fits.is_circle[0] or fits.radius[0] > 1e6 * spread


@pytest.mark.parametrize(
    "points",
    [
        np.empty((0, 2)),
        [(0.0, 0.0), (1.0, 0.0)],
        [(0.0, 0.0), (1.0, 0.0), (0.0, 0.0)],
        [(1.0, 1.0)] * 5,
        [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)],
        [0.0, 1.0, 2.0],
        *([(0.0, 0.0), (1.0, 0.0), (0.0, bad)] for bad in NON_FINITE),
    ],
)
def test_fit_circle_rejects_invalid_input(points):
    with pytest.raises(ValueError):
        fit_circle(points)


@pytest.mark.parametrize(
    "offsets",
    [[1, 6], [0, 5], [0, 2, 6], [0, 3, 3, 6], [[0, 6]], [0.0, 6.0], [0, 7], []],
)
def test_fit_circles_rejects_invalid_offsets(offsets):
    points = arc_points(0.0, 0.0, 1.0, 0.0, 2.0, 6)
    with pytest.raises(ValueError):
        fit_circles(points, np.array(offsets))


def test_fit_circles_rejects_non_finite_points():
    points = arc_points(0.0, 0.0, 1.0, 0.0, 2.0, 6)
    points[2, 1] = math.nan
    with pytest.raises(ValueError):
        fit_circles(points, [0, 6])


# --- fit_circles: batching ---------------------------------------------------------------------------


def test_fit_circles_of_no_sets_is_empty():
    fits = fit_circles(np.empty((0, 2)), [0])
    assert len(fits) == 0 and fits.centre.shape == (0, 2)


def test_fit_circles_equals_one_by_one_fits():
    rng = np.random.default_rng(5)
    sets = []
    for n in (3, 4, 7, 12, 40, 5):
        centre, radius = rng.uniform(-3.0, 3.0, 2), rng.uniform(0.05, 2.0)
        points = arc_points(*centre, radius, rng.uniform(-PI, PI), rng.uniform(0.5, 5.0), n)
        sets.append(points + rng.normal(0.0, 0.01, points.shape))
    # a collinear set in the middle must not disturb its neighbours
    sets.insert(3, np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]))
    offsets = np.concatenate(([0], np.cumsum([len(s) for s in sets])))
    fits = fit_circles(np.concatenate(sets), offsets)
    assert isinstance(fits, CircleFits) and len(fits) == len(sets)
    np.testing.assert_array_equal(fits.is_circle, [True, True, True, False, True, True, True])
    for k, points in enumerate(sets):
        if k == 3:
            continue
        circle = fit_circle(points)
        np.testing.assert_allclose(fits.centre[k], circle.centre, rtol=0.0, atol=1e-12)
        assert fits.radius[k] == pytest.approx(circle.radius, abs=1e-12)
        expected_residual = math.sqrt(np.mean((np.hypot(*(points - circle.centre).T) - circle.radius) ** 2))
        assert fits.residual[k] == pytest.approx(expected_residual, abs=1e-12)


# --- refine_for_range_sensor -------------------------------------------------------------------------


def tangent_rays(centre: np.ndarray, radius: float) -> np.ndarray:
    """The two unit rays from the origin tangent to a circle, shape (2, 2)."""
    distance = math.hypot(*centre)
    bearing, half_width = math.atan2(centre[1], centre[0]), math.asin(radius / distance)
    angles = bearing + np.array([-half_width, half_width])
    return np.column_stack((np.cos(angles), np.sin(angles)))


def perturbed(centre: np.ndarray, radius: float, size: float) -> CircleFits:
    start = centre + np.array([size, -0.7 * size])
    return CircleFits(start[None], np.array([radius + 0.5 * size]), np.array([0.0]))


@pytest.mark.parametrize("with_edges", [False, True])
def test_refinement_converges_quadratically_on_exact_data(with_edges):
    # points of a circle seen from the origin; one Gauss-Newton step from an error of size h leaves O(h^2)
    centre, radius = np.array([1.5, 0.4]), 0.2
    bearing = math.atan2(centre[1], centre[0])
    points = arc_points(*centre, radius, bearing + PI - 1.2, 2.4, 9)
    edges = {}
    if with_edges:
        edges = {"edge_directions": tangent_rays(centre, radius)[None], "edge_std": np.full((1, 2), 0.005)}
    errors = []
    for size in (1e-2, 1e-3):
        fits = refine_for_range_sensor(points, [0, 9], perturbed(centre, radius, size), 0.01, 0.2, **edges)
        errors.append(max(np.abs(fits.centre[0] - centre).max(), abs(fits.radius[0] - radius)))
    assert errors[0] < 5.0 * 1e-2**2
    assert errors[1] < 5.0 * 1e-3**2
    assert errors[1] < errors[0] / 30.0


def test_refinement_along_the_edges_alone_converges_quadratically():
    # three points give an exact circle; with the ranges down-weighted 1000-fold the edges dominate
    centre, radius = np.array([2.0, -0.5]), 0.15
    points = arc_points(*centre, radius, math.atan2(centre[1], centre[0]) + PI - 0.5, 1.0, 3)
    rays = tangent_rays(centre, radius)[None]
    errors = []
    for size in (1e-2, 1e-3):
        start = perturbed(centre, radius, size)
        fits = refine_for_range_sensor(points, [0, 3], start, 1.0, 0.2, rays, np.full((1, 2), 1e-3))
        errors.append(abs(fits.radius[0] - radius))
    assert errors[1] < errors[0] / 30.0


def test_refinement_leaves_an_exact_fit_in_place_and_updates_the_residual():
    centre, radius = np.array([1.0, 1.0]), 0.3
    points = arc_points(*centre, radius, PI, 1.5, 8)
    exact = fit_circles(points, [0, 8])
    fits = refine_for_range_sensor(points, [0, 8], exact, 0.01)
    np.testing.assert_allclose(fits.centre, exact.centre, rtol=0.0, atol=1e-12)
    assert fits.residual[0] < 1e-12


def test_refinement_keeps_the_input_when_the_step_is_too_large():
    points = arc_points(1.0, 0.0, 0.2, 2.0, 2.0, 10)
    wild = CircleFits(np.array([[5.0, 5.0]]), np.array([0.01]), np.array([0.0]))
    fits = refine_for_range_sensor(points, [0, 10], wild, 0.01)
    np.testing.assert_array_equal(fits.centre, wild.centre)
    assert fits.radius[0] == 0.01


def test_refinement_passes_circle_less_sets_through():
    points = np.array([[1.0, 0.0], [1.0, 1.0], [1.0, 2.0], [1.0, 3.0]])
    fits = refine_for_range_sensor(points, [0, 4], fit_circles(points, [0, 4]), 0.01)
    assert not fits.is_circle[0] and np.isnan(fits.centre).all()


def test_refinement_beats_the_isotropic_fit_on_lidar_data():
    # Monte Carlo on simulated LDS-01 scans of one cylinder: range noise along the beams plus the
    # silhouette rays (half a beam outside the outermost hits) shrink the centre error
    config = LidarConfig(noise=0.01, angle_min=-PI / 2.0)
    rng = np.random.default_rng(2)
    cylinder = np.array([1.2, 0.1, 0.08])
    increment = config.angle_increment
    hyper_errors, refined_errors = [], []
    for _ in range(300):
        ranges = simulate_scan(Transform2D(), cylinder[None], np.empty((0, 4)), config, rng)
        beams = np.flatnonzero(ranges > 0.0)
        angles = config.angles()[beams]
        points = ranges[beams, None] * np.column_stack((np.cos(angles), np.sin(angles)))
        offsets = [0, len(points)]
        hyper = fit_circles(points, offsets)
        edge_angles = np.array([angles[0] - increment / 2.0, angles[-1] + increment / 2.0])
        rays = np.column_stack((np.cos(edge_angles), np.sin(edge_angles)))[None]
        edge_std = ranges[beams[[0, -1]]][None] * increment / math.sqrt(12.0)
        refined = refine_for_range_sensor(points, offsets, hyper, 0.01, 0.2, rays, edge_std)
        hyper_errors.append(np.hypot(*(hyper.centre[0] - cylinder[:2])))
        refined_errors.append(np.hypot(*(refined.centre[0] - cylinder[:2])))
    assert np.median(refined_errors) < 0.8 * np.median(hyper_errors)
    assert np.sqrt(np.mean(np.square(refined_errors))) < np.sqrt(np.mean(np.square(hyper_errors)))


@pytest.mark.parametrize(
    "changes",
    [
        {"range_std": 0.0},
        {"range_std": math.nan},
        {"min_cos_incidence": 0.0},
        {"min_cos_incidence": 1.5},
        {"offsets": [0, 5]},
        {"offsets": [0, 3, 6]},
        {"edge_directions": np.ones((1, 2, 2))},
        {"edge_std": np.ones((1, 2))},
        {"edge_directions": np.ones((2, 2, 2)), "edge_std": np.ones((1, 2))},
        {"edge_directions": np.ones((1, 2, 2)), "edge_std": np.zeros((1, 2))},
        {"edge_directions": np.ones((1, 2, 2)), "edge_std": np.full((1, 2), math.nan)},
        {"edge_directions": np.full((1, 2, 2), math.nan), "edge_std": np.ones((1, 2))},
        {"points": np.zeros((6, 2))},
    ],
)
def test_refinement_rejects_invalid_input(changes):
    points = arc_points(1.0, 0.0, 0.2, 2.0, 2.0, 6)
    arguments = {"points": points, "offsets": [0, 6], "fits": fit_circles(points, [0, 6]), "range_std": 0.01}
    arguments.update(changes)
    with pytest.raises(ValueError):
        refine_for_range_sensor(**arguments)
