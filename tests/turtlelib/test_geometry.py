"""turtlelib.geometry.se2: angle wrapping, Twist2D and the SE(2) group (property tests + hand-computed cases).

Independent references: homogeneous 3x3 matrices (composition, points, inverse), scipy.linalg.expm of the
se(2) matrix (exponential), and T [V] T^-1 (adjoint).
"""

import dataclasses
import math

import numpy as np
import pytest
import scipy.linalg
from finite_differences import central_jacobian, wrapping
from hypothesis import given
from hypothesis import strategies as st

from turtlelib import Transform2D, Twist2D, integrate_twist, normalize_angle, normalize_angles
from turtlelib.geometry.se2 import SMALL_ANGLE_RAD, right_composition_jacobian

PI = math.pi
coords_m = st.floats(-10.0, 10.0, allow_nan=False)
any_angle_rad = st.floats(-4.0 * PI, 4.0 * PI, allow_nan=False)
transforms = st.builds(Transform2D, coords_m, coords_m, any_angle_rad)
# rotations in (-pi, pi], plus values clustered at 0 and +-pi where the closed forms degenerate
principal_omega = st.one_of(
    st.floats(-PI, PI, allow_nan=False).filter(lambda w: w != -PI),
    st.floats(-1e-3, 1e-3, allow_nan=False),
    st.floats(PI - 1e-6, PI),
    st.floats(-PI, -PI + 1e-6, exclude_min=True),
)
twists = st.builds(Twist2D, principal_omega, coords_m, coords_m)
NON_FINITE = [math.nan, math.inf, -math.inf]


def se2_hat(twist: Twist2D) -> np.ndarray:
    """[V] = [[0, -omega, vx], [omega, 0, vy], [0, 0, 0]]."""
    return np.array([[0.0, -twist.omega, twist.vx], [twist.omega, 0.0, twist.vy], [0.0, 0.0, 0.0]])


def assert_transform_close(actual: Transform2D, expected: Transform2D, atol: float = 1e-12) -> None:
    np.testing.assert_allclose(actual.as_matrix(), expected.as_matrix(), rtol=0.0, atol=atol)


# --- normalize_angle ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("theta", "expected"),
    [
        (0.0, 0.0),
        (PI, PI),
        (-PI, PI),
        (3.0 * PI, PI),
        (-3.0 * PI, PI),
        (2.0 * PI, 0.0),
        (1.5 * PI, -0.5 * PI),
        (-1.5 * PI, 0.5 * PI),
        (0.25 * PI + 10.0 * math.tau, 0.25 * PI),
    ],
)
def test_normalize_angle_hand_cases(theta, expected):
    assert normalize_angle(theta) == pytest.approx(expected, abs=1e-12)
    assert normalize_angles(np.array([theta]))[0] == pytest.approx(expected, abs=1e-12)


def test_normalize_angle_keeps_in_range_values_exactly():
    for theta in (1e-300, -1e-20, 1e-9, PI, -PI + 1e-15, 2.5):
        assert normalize_angle(theta) == theta
        assert normalize_angles([theta])[0] == theta


@given(st.floats(-1e6, 1e6, allow_nan=False))
def test_normalize_angle_range_and_equivalence(theta):
    wrapped = normalize_angle(theta)
    assert -PI < wrapped <= PI
    assert math.cos(wrapped) == pytest.approx(math.cos(theta), abs=1e-9)
    assert math.sin(wrapped) == pytest.approx(math.sin(theta), abs=1e-9)
    assert normalize_angle(wrapped) == wrapped


@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=12))
def test_normalize_angles_matches_scalar_and_keeps_shape(thetas):
    angles = np.array(thetas)
    wrapped = normalize_angles(angles)
    assert wrapped.shape == angles.shape and wrapped.dtype == np.float64
    np.testing.assert_array_equal(wrapped, [normalize_angle(t) for t in thetas])
    assert not np.shares_memory(wrapped, angles)
    grid = normalize_angles(np.tile(angles, (2, 1)))
    assert grid.shape == (2, len(thetas))
    np.testing.assert_array_equal(grid[1], wrapped)


@pytest.mark.parametrize("bad", NON_FINITE)
def test_normalize_angle_rejects_non_finite(bad):
    with pytest.raises(ValueError):
        normalize_angle(bad)
    with pytest.raises(ValueError):
        normalize_angles(np.array([0.0, bad]))


# --- Twist2D ---------------------------------------------------------------------------------------------


def test_twist_array_and_scaling():
    twist = Twist2D(1.0, 2.0, -3.0)
    np.testing.assert_array_equal(twist.as_array(), [1.0, 2.0, -3.0])
    assert twist * 0.5 == Twist2D(0.5, 1.0, -1.5)
    assert 0.5 * twist == Twist2D(0.5, 1.0, -1.5)
    scaled = np.float64(2.0) * twist
    assert isinstance(scaled, Twist2D) and scaled == Twist2D(2.0, 4.0, -6.0)
    assert Twist2D() == Twist2D(0.0, 0.0, 0.0)
    with pytest.raises(TypeError):
        twist * "2"
    with pytest.raises(dataclasses.FrozenInstanceError):
        twist.omega = 0.0


@pytest.mark.parametrize("field", ["omega", "vx", "vy"])
@pytest.mark.parametrize("bad", NON_FINITE)
def test_twist_rejects_non_finite(field, bad):
    with pytest.raises(ValueError):
        Twist2D(**{field: bad})


# --- Transform2D construction and accessors -------------------------------------------------------------


def test_transform_fields_and_accessors():
    T = Transform2D(1.0, 2.0, 2.5 * PI)
    assert T.theta == pytest.approx(0.5 * PI, abs=1e-12)
    assert Transform2D(theta=-PI).theta == PI
    np.testing.assert_array_equal(T.translation, [1.0, 2.0])
    np.testing.assert_allclose(T.rotation_matrix(), [[0.0, -1.0], [1.0, 0.0]], atol=1e-15)
    np.testing.assert_allclose(T.as_matrix(), [[0, -1, 1], [1, 0, 2], [0, 0, 1]], atol=1e-15)
    np.testing.assert_array_equal(T.as_array(), [T.x, T.y, T.theta])
    assert Transform2D.identity() == Transform2D(0.0, 0.0, 0.0)
    assert eval(repr(T)) == T
    assert "Transform2D(x=1.0, y=2.0" in repr(T)
    assert hash(T) == hash(Transform2D(1.0, 2.0, 2.5 * PI))
    with pytest.raises(dataclasses.FrozenInstanceError):
        T.x = 3.0


@pytest.mark.parametrize("field", ["x", "y", "theta"])
@pytest.mark.parametrize("bad", NON_FINITE)
def test_transform_rejects_non_finite(field, bad):
    with pytest.raises(ValueError):
        Transform2D(**{field: bad})


@given(transforms)
def test_from_matrix_round_trip(T):
    assert_transform_close(Transform2D.from_matrix(T.as_matrix()), T, atol=1e-14)
    assert Transform2D.from_matrix(T.as_matrix()).theta == pytest.approx(T.theta, abs=1e-14)


@pytest.mark.parametrize(
    "matrix",
    [
        np.eye(2),  # wrong shape
        np.eye(4),
        np.array([[1.0, 0.0, math.nan], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),  # non-finite
        np.array([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]),  # scaled, not orthonormal
        np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]),  # reflection, det -1
        np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.1, 0.0, 1.0]]),  # bad last row
    ],
)
def test_from_matrix_rejects_non_se2(matrix):
    with pytest.raises(ValueError):
        Transform2D.from_matrix(matrix)


# --- group axioms -----------------------------------------------------------------------------------------


@given(transforms, transforms)
def test_composition_matches_matrix_product(T_ab, T_bc):
    T_ac = T_ab @ T_bc
    assert isinstance(T_ac, Transform2D)
    np.testing.assert_allclose(T_ac.as_matrix(), T_ab.as_matrix() @ T_bc.as_matrix(), atol=1e-12)
    assert -PI < T_ac.theta <= PI


@given(transforms, transforms, transforms)
def test_associativity(T_ab, T_bc, T_cd):
    assert_transform_close((T_ab @ T_bc) @ T_cd, T_ab @ (T_bc @ T_cd), atol=1e-11)


@given(transforms)
def test_identity_and_inverse(T):
    identity = Transform2D.identity()
    assert T @ identity == T
    assert identity @ T == T
    assert_transform_close(T @ T.inverse(), identity, atol=1e-13)
    assert_transform_close(T.inverse() @ T, identity, atol=1e-13)
    np.testing.assert_allclose(T.inverse().as_matrix(), np.linalg.inv(T.as_matrix()), atol=1e-13)
    assert_transform_close(T.inverse().inverse(), T, atol=1e-13)


def test_hand_computed_rotations_and_inverse():
    quarter = Transform2D(theta=0.5 * PI)
    np.testing.assert_allclose(quarter @ np.array([1.0, 0.0]), [0.0, 1.0], atol=1e-15)
    half = quarter @ quarter
    assert half.theta == pytest.approx(PI, abs=1e-15)
    np.testing.assert_allclose(half @ np.array([1.0, 2.0]), [-1.0, -2.0], atol=1e-15)
    assert_transform_close(quarter @ quarter @ quarter @ quarter, Transform2D.identity(), atol=1e-15)
    T_ab = Transform2D(1.0, 2.0, 0.5 * PI)
    np.testing.assert_allclose(T_ab @ np.array([1.0, 0.0]), [1.0, 3.0], atol=1e-15)
    # R^T = [[0, 1], [-1, 0]], -R^T p = -(2, -1) = (-2, 1)
    assert_transform_close(T_ab.inverse(), Transform2D(-2.0, 1.0, -0.5 * PI), atol=1e-15)
    # a translation after a rotation: T_ab @ T_bc with T_bc = (1, 0, 0) moves along b's x = a's y
    assert_transform_close(T_ab @ Transform2D(1.0, 0.0, 0.0), Transform2D(1.0, 3.0, 0.5 * PI), atol=1e-15)


# --- points ----------------------------------------------------------------------------------------------


@given(transforms, st.lists(st.tuples(coords_m, coords_m), min_size=0, max_size=8))
def test_points_agree_with_homogeneous_matrix(T_ab, points):
    p_b = np.array(points, dtype=np.float64).reshape(-1, 2)
    p_a = T_ab @ p_b
    assert p_a.shape == p_b.shape
    homogeneous = np.column_stack([p_b, np.ones(len(p_b))])
    np.testing.assert_allclose(p_a, (homogeneous @ T_ab.as_matrix().T)[:, :2], atol=1e-12)
    for single_b, single_a in zip(p_b, p_a, strict=True):
        result = T_ab @ single_b
        assert result.shape == (2,)
        np.testing.assert_allclose(result, single_a, atol=1e-12)


def test_points_accept_lists_and_return_floats():
    np.testing.assert_allclose(Transform2D(1.0, 0.0, 0.0) @ [1, 2], [2.0, 2.0])
    assert (Transform2D() @ [[1, 2]]).dtype == np.float64


@pytest.mark.parametrize(
    "points",
    [
        np.zeros(3),
        np.zeros((2, 3)),
        np.zeros((2, 2, 2)),
        np.float64(1.0),
        np.array([1.0, math.nan]),
        np.array([[0.0, 0.0], [math.inf, 1.0]]),
        "ab",
        [[1.0, 2.0], [3.0]],
    ],
)
def test_points_reject_bad_shapes_and_values(points):
    with pytest.raises(ValueError):
        Transform2D(1.0, 2.0, 0.3) @ points


def test_matmul_refuses_twists_and_array_on_the_left():
    with pytest.raises(TypeError):
        Transform2D() @ Twist2D()
    with pytest.raises(TypeError):
        np.zeros(2) @ Transform2D()


# --- adjoint ---------------------------------------------------------------------------------------------


@given(transforms, twists)
def test_transform_twist_is_the_adjoint(T_ab, V_b):
    V_a = T_ab.transform_twist(V_b)
    # [V_a] = T [V_b] T^-1
    expected_hat = T_ab.as_matrix() @ se2_hat(V_b) @ np.linalg.inv(T_ab.as_matrix())
    np.testing.assert_allclose(se2_hat(V_a), expected_hat, atol=1e-11)
    # Ad_T = [[1, 0, 0], [y, c, -s], [-x, s, c]]
    c, s = math.cos(T_ab.theta), math.sin(T_ab.theta)
    ad = np.array([[1.0, 0.0, 0.0], [T_ab.y, c, -s], [-T_ab.x, s, c]])
    np.testing.assert_allclose(V_a.as_array(), ad @ V_b.as_array(), atol=1e-12)


def test_transform_twist_hand_case():
    # a frame at (1, 0) rotated by 90 degrees spinning at 1 rad/s: the world sees the origin of b
    # rotating about (1, 0), so the world-frame point at the origin moves with v = omega x (-p) = (0, -1)
    V_a = Transform2D(1.0, 0.0, 0.5 * PI).transform_twist(Twist2D(1.0, 0.0, 0.0))
    np.testing.assert_allclose(V_a.as_array(), [1.0, 0.0, -1.0], atol=1e-15)
    # a pure translation in b along x is along a's y
    V_a = Transform2D(1.0, 0.0, 0.5 * PI).transform_twist(Twist2D(0.0, 2.0, 0.0))
    np.testing.assert_allclose(V_a.as_array(), [0.0, 0.0, 2.0], atol=1e-15)


# --- exp / log -------------------------------------------------------------------------------------------


def test_integrate_twist_hand_cases():
    # pure translation
    assert_transform_close(integrate_twist(Twist2D(0.0, 1.0, 2.0)), Transform2D(1.0, 2.0, 0.0), atol=0.0)
    # pure rotation
    assert_transform_close(integrate_twist(Twist2D(0.5 * PI, 0.0, 0.0)), Transform2D(theta=0.5 * PI))
    # quarter circle of radius 1 turning left: omega = pi/2, vx = pi/2 ends at (1, 1) facing +y
    assert_transform_close(integrate_twist(Twist2D(0.5 * PI, 0.5 * PI, 0.0)), Transform2D(1.0, 1.0, 0.5 * PI))
    # half circle of radius 2 turning right: ends at (0, -4) facing -x
    assert_transform_close(integrate_twist(Twist2D(-PI, 2.0 * PI, 0.0)), Transform2D(0.0, -4.0, PI))
    # a sideways (vy) quarter arc: rotate the vx case by 90 degrees, i.e. start facing -y in the arc frame
    sideways = integrate_twist(Twist2D(0.5 * PI, 0.0, 0.5 * PI))
    assert_transform_close(sideways, Transform2D(-1.0, 1.0, 0.5 * PI))
    assert Transform2D.exp(Twist2D(0.3, 1.0, 0.2)) == integrate_twist(Twist2D(0.3, 1.0, 0.2))


@given(
    st.builds(
        Twist2D,
        st.one_of(st.floats(-10.0, 10.0, allow_nan=False), st.floats(-2e-2, 2e-2, allow_nan=False)),
        coords_m,
        coords_m,
    )
)
def test_integrate_twist_matches_matrix_exponential(V):
    expected = scipy.linalg.expm(se2_hat(V))
    np.testing.assert_allclose(integrate_twist(V).as_matrix(), expected, rtol=0.0, atol=1e-11)


@pytest.mark.parametrize(
    "omega",
    [
        0.0,
        1e-300,
        1e-12,
        -1e-8,
        1e-5,
        SMALL_ANGLE_RAD * (1 - 1e-12),
        -SMALL_ANGLE_RAD,
        SMALL_ANGLE_RAD * (1 + 1e-12),
    ],
)
def test_exp_log_round_trip_near_zero_rotation(omega):
    V = Twist2D(omega, 1.5, -0.5)
    T = Transform2D.exp(V)
    # first order: x ~ vx - omega vy / 2, y ~ vy + omega vx / 2
    assert T.x == pytest.approx(1.5 + 0.25 * omega, abs=omega**2 + 1e-15)
    assert T.y == pytest.approx(-0.5 + 0.75 * omega, abs=omega**2 + 1e-15)
    np.testing.assert_allclose(T.log().as_array(), V.as_array(), rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(T.as_matrix(), scipy.linalg.expm(se2_hat(V)), rtol=0.0, atol=1e-15)


def test_series_and_closed_forms_agree_at_the_threshold():
    below = Twist2D(math.nextafter(SMALL_ANGLE_RAD, 0.0), 1.0, 1.0)
    at = Twist2D(SMALL_ANGLE_RAD, 1.0, 1.0)
    np.testing.assert_allclose(integrate_twist(below).as_array(), integrate_twist(at).as_array(), atol=1e-15)
    np.testing.assert_allclose(
        integrate_twist(below).log().as_array(), integrate_twist(at).log().as_array(), atol=1e-15
    )


@given(twists)
def test_log_inverts_exp(V):
    np.testing.assert_allclose(Transform2D.exp(V).log().as_array(), V.as_array(), rtol=1e-9, atol=1e-9)


@given(
    st.builds(
        Transform2D,
        coords_m,
        coords_m,
        st.one_of(
            any_angle_rad, st.floats(PI - 1e-6, PI), st.floats(-PI, -PI + 1e-6), st.floats(-1e-6, 1e-6)
        ),
    )
)
def test_exp_inverts_log(T):
    V = T.log()
    assert V.omega == T.theta
    assert_transform_close(Transform2D.exp(V), T, atol=1e-11)


def test_log_hand_cases():
    V = Transform2D(1.0, 1.0, 0.5 * PI).log()
    np.testing.assert_allclose(V.as_array(), [0.5 * PI, 0.5 * PI, 0.0], atol=1e-15)
    np.testing.assert_allclose(Transform2D(3.0, -2.0, 0.0).log().as_array(), [0.0, 3.0, -2.0], atol=0.0)
    # half turn to (0, -4): omega = pi (never -pi), so the arc turns left while reversing, about (0, -2)
    V = Transform2D(0.0, -4.0, PI).log()
    np.testing.assert_allclose(V.as_array(), [PI, -2.0 * PI, 0.0], atol=1e-14)


@given(transforms, twists)
def test_exp_of_adjoint_is_conjugation(T, V):
    # exp(Ad_T V) = T exp(V) T^-1
    conjugated = T @ Transform2D.exp(V) @ T.inverse()
    assert_transform_close(Transform2D.exp(T.transform_twist(V)), conjugated, atol=1e-10)


@given(twists, st.integers(1, 6))
def test_exp_of_scaled_twist_composes(V, n):
    # exp(V) = exp(V / n)^n: one arc is n shorter arcs
    step = Transform2D.exp(V * (1.0 / n))
    T = Transform2D.identity()
    for _ in range(n):
        T = T @ step
    assert_transform_close(T, Transform2D.exp(V), atol=1e-11)


@given(transforms, transforms)
def test_right_composition_jacobian_matches_finite_differences(T_from, U):
    """``G`` of ``T_to = T_from U`` against central differences of ``[x, y, theta] -> T(x, y, theta) U``."""
    G = right_composition_jacobian(T_from, T_from @ U)
    numeric = central_jacobian(lambda q: (Transform2D(*q) @ U).as_array(), T_from.as_array(), wrapping(2))
    np.testing.assert_allclose(G, numeric, atol=1e-5 * (1.0 + abs(U.x) + abs(U.y)))
