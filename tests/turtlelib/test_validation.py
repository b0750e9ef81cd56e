"""turtlelib.util.validation: every check accepts exactly the values it documents, returns them converted, and
names the field in a ``<name> must be ..., got <value>`` message."""

from __future__ import annotations

import dataclasses
import math
import re
from fractions import Fraction
from functools import partial

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from turtlelib.util.validation import (
    EIGENVALUE_RTOL,
    SYMMETRY_RTOL,
    covariance,
    finite_array,
    finite_real,
    in_range,
    integer,
    landmark_ids,
    names,
    non_negative,
    one_of,
    positive,
    store,
)

# not a real number, or one without a finite float (10**400 is beyond the float range)
NOT_NUMBERS = [math.nan, math.inf, -math.inf, 10**400, True, False, "1.0", "x", None, [1.0], 1j, np.ones(1)]
NOT_INTEGERS = [1.0, 2.5, math.nan, True, False, "3", None, np.float64(2.0), Fraction(3, 1)]
finite_floats = st.floats(allow_nan=False, allow_infinity=False)
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])
beyond_floats = st.integers(min_value=2**1024)
field_names = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_.[]0123456789 ", min_size=1, max_size=20)


def raises_naming(name: str, value: object):
    """pytest.raises for ``<name> must be ..., got <value!r>`` (the whole message anchored)."""
    return pytest.raises(ValueError, match=rf"^{re.escape(name)} must be .*, got {re.escape(repr(value))}$")


# --- finite_real -------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "value, expected",
    [(0, 0.0), (-3, -3.0), (1.5, 1.5), (np.float64(-2.25), -2.25), (np.int64(7), 7.0), (np.float32(0.5), 0.5),
     (Fraction(1, 4), 0.25), (1e308, 1e308), (-5e-324, -5e-324)],
)  # fmt: skip
def test_finite_real_returns_a_float(value, expected):
    result = finite_real("gain", value)
    assert type(result) is float and result == expected


@pytest.mark.parametrize("value", NOT_NUMBERS)
def test_finite_real_refuses_non_finite_and_non_numbers(value):
    with raises_naming("gain", value):
        finite_real("gain", value)


@given(field_names, st.one_of(finite_floats, st.integers(-(10**300), 10**300)))
def test_finite_real_accepts_every_finite_number_unchanged(name, value):
    result = finite_real(name, value)
    assert type(result) is float and result == float(value)


@given(field_names, st.one_of(non_finite, beyond_floats, st.booleans(), st.text(), st.none()))
def test_finite_real_refuses_what_is_not_a_finite_number(name, value):
    with raises_naming(name, value):
        finite_real(name, value)


# --- positive, non_negative --------------------------------------------------------------------------------


def test_positive_and_non_negative_hand_cases():
    assert positive("r", 1) == 1.0 and type(positive("r", 1)) is float
    assert positive("r", 5e-324) == 5e-324
    assert non_negative("r", 0) == 0.0 and type(non_negative("r", 0)) is float
    assert non_negative("r", -0.0) == 0.0
    with raises_naming("r", 0.0):
        positive("r", 0.0)
    with raises_naming("r", -1):
        positive("r", -1)
    with raises_naming("r", -1e-300):
        non_negative("r", -1e-300)
    with pytest.raises(ValueError, match=r"^r must be finite and > 0, got -2$"):
        positive("r", -2)
    with pytest.raises(ValueError, match=r"^r must be finite and >= 0, got -2$"):
        non_negative("r", -2)


@pytest.mark.parametrize("check", [positive, non_negative])
@pytest.mark.parametrize("value", NOT_NUMBERS)
def test_positive_and_non_negative_refuse_non_finite_and_non_numbers(check, value):
    with raises_naming("noise", value):
        check("noise", value)


@given(field_names, finite_floats)
def test_positive_accepts_exactly_the_finite_numbers_above_zero(name, value):
    if value > 0.0:
        assert positive(name, value) == value
    else:
        with raises_naming(name, value):
            positive(name, value)


@given(field_names, finite_floats)
def test_non_negative_accepts_exactly_the_finite_numbers_from_zero(name, value):
    if value >= 0.0:
        assert non_negative(name, value) == value
    else:
        with raises_naming(name, value):
            non_negative(name, value)


# --- integer -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("value", [0, -4, 10**30, np.int64(3), np.uint8(255)])
def test_integer_returns_an_int(value):
    result = integer("count", value)
    assert type(result) is int and result == int(value)


@pytest.mark.parametrize("value", NOT_INTEGERS)
def test_integer_refuses_what_is_not_an_integer(value):
    with pytest.raises(ValueError, match=rf"^count must be an integer, got {re.escape(repr(value))}$"):
        integer("count", value)


def test_integer_bounds_hand_cases():
    assert integer("count", 1, minimum=1) == 1
    assert integer("count", 2, maximum=2) == 2
    assert integer("count", 0, minimum=0, maximum=0) == 0
    with pytest.raises(ValueError, match=r"^count must be >= 1, got 0$"):
        integer("count", 0, minimum=1)
    with pytest.raises(ValueError, match=r"^count must be <= 2, got 3$"):
        integer("count", 3, minimum=0, maximum=2)
    with pytest.raises(ValueError, match=r"^count must be >= 0, got -1$"):
        integer("count", -1, minimum=0, maximum=2)


@given(field_names, st.integers(), st.one_of(st.none(), st.integers()), st.one_of(st.none(), st.integers()))
def test_integer_accepts_exactly_the_integers_within_its_bounds(name, value, minimum, maximum):
    inside = (minimum is None or value >= minimum) and (maximum is None or value <= maximum)
    if inside:
        assert integer(name, value, minimum, maximum) == value
    else:
        with raises_naming(name, value):
            integer(name, value, minimum, maximum)


@given(field_names, st.one_of(st.floats(), st.booleans(), st.text(), st.none()))
def test_integer_refuses_floats_bools_strings_and_none(name, value):
    with raises_naming(name, value):
        integer(name, value)


# --- in_range ----------------------------------------------------------------------------------------------


def test_in_range_hand_cases():
    assert in_range("p", 0, 0.0, 1.0) == 0.0 and type(in_range("p", 0, 0.0, 1.0)) is float
    assert in_range("p", 1.0, 0.0, 1.0) == 1.0
    assert in_range("p", 1.0, 0.0, 1.0, open_low=True) == 1.0
    assert in_range("p", 0.0, 0.0, 1.0, open_high=True) == 0.0
    with pytest.raises(ValueError, match=r"^p must be in \(0.0, 1.0\], got 0.0$"):
        in_range("p", 0.0, 0.0, 1.0, open_low=True)
    with pytest.raises(ValueError, match=r"^p must be in \[0.0, 1.0\), got 1$"):
        in_range("p", 1, 0.0, 1.0, open_high=True)
    with pytest.raises(ValueError, match=r"^p must be in \(0.0, 1.0\), got 1.5$"):
        in_range("p", 1.5, 0.0, 1.0, open_low=True, open_high=True)
    with pytest.raises(ValueError, match=r"^p must be in \[-1, 1\], got -1.5$"):
        in_range("p", -1.5, -1, 1)


@pytest.mark.parametrize("value", NOT_NUMBERS)
def test_in_range_refuses_non_finite_and_non_numbers(value):
    with raises_naming("p", value):
        in_range("p", value, -math.inf, math.inf)


@given(field_names, finite_floats, finite_floats, finite_floats, st.booleans(), st.booleans())
def test_in_range_accepts_exactly_the_interval(name, value, a, b, open_low, open_high):
    low, high = min(a, b), max(a, b)
    above = value > low if open_low else value >= low
    below = value < high if open_high else value <= high
    if above and below:
        assert in_range(name, value, low, high, open_low=open_low, open_high=open_high) == value
    else:
        with raises_naming(name, value):
            in_range(name, value, low, high, open_low=open_low, open_high=open_high)


# --- one_of ------------------------------------------------------------------------------------------------


def test_one_of_hand_cases():
    assert one_of("matcher", "nn", ("nn", "jcbb")) == "nn"
    with pytest.raises(ValueError, match=r"^matcher must be one of \('nn', 'jcbb'\), got 'icp'$"):
        one_of("matcher", "icp", ("nn", "jcbb"))
    with pytest.raises(ValueError, match="matcher must be one of"):
        one_of("matcher", None, ["nn"])


@given(field_names, st.lists(st.text(max_size=5), min_size=1, max_size=5, unique=True), st.text(max_size=5))
def test_one_of_accepts_exactly_the_choices(name, choices, value):
    if value in choices:
        assert one_of(name, value, choices) is value
    else:
        with raises_naming(name, value):
            one_of(name, value, choices)


# --- names -------------------------------------------------------------------------------------------------


def test_names_hand_cases():
    assert names("frame id", map_id="map", odom_id="odom") is None
    with pytest.raises(ValueError, match=r"^odom_id must be a non-empty frame id, got ''$"):
        names("frame id", map_id="map", odom_id="")
    with pytest.raises(ValueError, match=r"^wheel_left must be a non-empty joint name, got None$"):
        names("joint name", wheel_left=None, wheel_right="b")
    with pytest.raises(ValueError, match=r"^a, b, c must be distinct frame ids, got \['x', 'y', 'x'\]$"):
        names("frame id", a="x", b="y", c="x")


@given(st.lists(st.text(max_size=3), min_size=1, max_size=5))
def test_names_accepts_exactly_non_empty_distinct_strings(values):
    fields = {f"f{k}": value for k, value in enumerate(values)}
    if "" in values:
        with pytest.raises(ValueError, match=rf"^f{values.index('')} must be a non-empty thing, got ''$"):
            names("thing", **fields)
    elif len(set(values)) < len(values):
        with pytest.raises(ValueError, match="must be distinct things"):
            names("thing", **fields)
    else:
        names("thing", **fields)


@given(st.one_of(st.integers(), st.floats(), st.none(), st.binary(min_size=1)))
def test_names_refuses_what_is_not_a_string(value):
    with raises_naming("body_id", value):
        names("frame id", body_id=value, odom_id="odom")


# --- store -------------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Example:
    gain: object = 1
    count: object = 2


def test_store_writes_the_converted_values_back_into_a_frozen_dataclass():
    config = Example(gain=np.float64(2.5), count=np.int64(3))
    store(config, ("gain",), positive)
    store(config, ("count",), partial(integer, minimum=1))
    assert type(config.gain) is float and config.gain == 2.5
    assert type(config.count) is int and config.count == 3
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.gain = 1.0


def test_store_names_the_field_with_its_prefix_and_leaves_later_fields_alone():
    config = Example(gain=3, count=-1.5)
    with pytest.raises(ValueError, match=r"^lidar count must be finite and >= 0, got -1.5$"):
        store(config, ("gain", "count"), non_negative, prefix="lidar ")
    assert type(config.gain) is float  # checked and stored before the failing field
    with pytest.raises(ValueError, match=r"^gain must be an integer, got 3.0$"):
        store(config, ("gain",), integer)


@given(finite_floats, st.integers(-(2**63), 2**63))
def test_store_stores_what_the_check_returns(gain, count):
    config = Example(gain=gain, count=count)
    store(config, ("gain", "count"), finite_real)
    assert (config.gain, config.count) == (gain, float(count))
    assert type(config.gain) is float and type(config.count) is float


# --- finite_array ------------------------------------------------------------------------------------------


def test_finite_array_returns_a_float64_copy_of_the_shape():
    source = np.array([[1, 2], [3, 4]])
    array = finite_array("xy", source, (2, 2))
    assert array.dtype == np.float64 and array.flags.c_contiguous
    source[0, 0] = 9
    assert array[0, 0] == 1.0
    assert finite_array("xy", [], (0, 2)).shape == (0, 2)


@pytest.mark.parametrize(
    "value, message",
    [
        ([[1.0, 2.0]], r"^xy must have shape \(2, 2\), got \(1, 2\)$"),
        ([[1.0, math.inf], [0.0, 0.0]], r"^xy must be finite, got 1 non-finite$"),
        ([[True, False], [False, True]], "xy must be a .* array of real numbers, got dtype bool"),
        ([["a", "b"], ["c", "d"]], "xy must be a .* array of real numbers"),
        ([[1.0], [1.0, 2.0]], "xy must be a .* array of numbers"),
    ],
)
def test_finite_array_refuses_what_is_not_finite_reals_of_the_shape(value, message):
    with pytest.raises(ValueError, match=message):
        finite_array("xy", value, (2, 2))


# --- landmark_ids ------------------------------------------------------------------------------------------


@given(st.lists(st.integers(0, 2**63 - 1), unique=True, max_size=20))
def test_landmark_ids_accept_distinct_non_negative_integers_in_their_order(ids):
    for given_ids in (ids, np.array(ids, dtype=np.int64), np.array(ids, dtype=object)):
        result = landmark_ids("ids", given_ids)
        assert result.dtype == np.int64 and result.shape == (len(ids),)
        assert result.tolist() == ids


@pytest.mark.parametrize("empty", [[], np.zeros(0), np.zeros((0, 2), dtype=int), np.array([], dtype=object)])
def test_no_landmark_ids_is_an_empty_int64_array(empty):
    result = landmark_ids("ids", empty)
    assert result.dtype == np.int64 and result.shape == (0,)


@given(st.lists(st.integers(0, 2**63 - 1), min_size=1, max_size=10), st.data())
def test_landmark_ids_refuse_a_repeated_id(ids, data):
    repeated = data.draw(st.sampled_from(ids))
    position = data.draw(st.integers(0, len(ids)))
    with pytest.raises(ValueError, match=rf"^landmark ids must be distinct, got duplicates .*\b{repeated}\b"):
        landmark_ids("landmark ids", [*ids[:position], repeated, *ids[position:]])


@pytest.mark.parametrize(
    "ids, message",
    [
        ([[0, 1]], r"must be a 1-D array, got shape \(1, 2\)"),
        ([0.0, 1.0], "must be integers, got float64"),
        (np.array([True, False]), "must be integers, got bool"),
        (np.array([1, True], dtype=object), r"must be integers, got \[1, True\]"),
        (np.array([1, 2.0], dtype=object), "must be integers"),
        (["1", "2"], "must be integers"),
        ([3, -1, -7], r"must be >= 0, got \[-1, -7\]"),
        (np.array([0, 2**63], dtype=object), r"must be < 2\^63, got \[9223372036854775808\]"),
        (np.array([5, 2**64 - 1], dtype=np.uint64), r"must be < 2\^63"),
        ([4, 1, 4, 1, 2], r"must be distinct, got duplicates \[1, 4\]"),
    ],
)
def test_landmark_ids_refuse_what_are_not_distinct_ids(ids, message):
    with pytest.raises(ValueError, match=rf"^ids {message}"):
        landmark_ids("ids", ids)


# --- covariance --------------------------------------------------------------------------------------------

ROTATION = np.array([[0.6, -0.8], [0.8, 0.6]])


def rotated(eigenvalues) -> np.ndarray:
    """``R diag(eigenvalues) R^T``, exactly symmetric."""
    P = ROTATION @ np.diag(eigenvalues) @ ROTATION.T
    return 0.5 * (P + P.T)


@given(
    st.sampled_from([1e-300, 1e-12, 1e-3, 1.0, 1e6, 1e300]),
    st.sampled_from([-10.0, -2.0, -0.5, 0.0, 0.5, 2.0, 10.0]),
    st.integers(1, 4),
    st.booleans(),
)
def test_definiteness_is_judged_relative_to_the_largest_entry(scale, ratio, d, stacked):
    # diag(scale, ..., ratio * EIGENVALUE_RTOL * scale): the smallest eigenvalue in units of the bound
    P = (
        np.diag([scale] * (d - 1) + [ratio * EIGENVALUE_RTOL * scale])
        if d > 1
        else np.array([[scale * ratio]])
    )
    largest = np.abs(P).max()
    smallest = P.diagonal().min()
    given_P, shape = (P[None], (1, d, d)) if stacked else (P, (d, d))
    for definite, accepted in ((False, smallest >= -EIGENVALUE_RTOL * largest),
                               (True, smallest > EIGENVALUE_RTOL * largest)):  # fmt: skip
        if accepted:
            np.testing.assert_array_equal(covariance("P", given_P, shape, definite=definite), given_P)
        else:
            kind = "positive definite" if definite else "positive semi-definite"
            with pytest.raises(ValueError, match=rf"^P(\[0\])? must be {kind}: smallest eigenvalue"):
                covariance("P", given_P, shape, definite=definite)


@pytest.mark.parametrize(
    "smallest, psd, pd",
    [
        (-2e-9, False, False),
        (-0.5e-9, True, False),
        (0.0, True, False),
        (0.5e-9, True, False),
        (2e-9, True, True),
    ],
)
def test_definiteness_of_a_rotated_matrix_to_1e_9_of_its_largest_entry(smallest, psd, pd):
    # eigenvalues 1 and smallest * max|P|; the largest entry is 0.64 + 0.36 * smallest ~ 0.64
    P = rotated([1.0, 0.0])
    P = rotated([1.0, smallest * np.abs(P).max()])
    for stacked in (False, True):
        given_P, shape = (P[None], (1, 2, 2)) if stacked else (P, (2, 2))
        for definite, accepted in ((False, psd), (True, pd)):
            if accepted:
                covariance("P", given_P, shape, definite=definite)
            else:
                with pytest.raises(ValueError):
                    covariance("P", given_P, shape, definite=definite)


@pytest.mark.parametrize("asymmetry, valid", [(0.5, True), (2.0, False)])
def test_symmetry_is_judged_to_SYMMETRY_RTOL_of_the_largest_entry_and_restored_exactly(asymmetry, valid):
    # largest entry 4; P_01 - P_10 = asymmetry * SYMMETRY_RTOL * 4
    P = np.array([[4.0, 0.5, 0.0], [0.5 + asymmetry * SYMMETRY_RTOL * 4.0, 2.0, 0.1], [0.0, 0.1, 1.0]])
    if not valid:
        with pytest.raises(
            ValueError, match=r"^P must be symmetric: max \|P - P\^T\| = 8e-09 > 1e-09 \* max"
        ):
            covariance("P", P, (3, 3), definite=True)
        return
    result = covariance("P", P, (3, 3), definite=True)
    np.testing.assert_array_equal(result, result.T)
    assert result[0, 1] == 0.5 * P[0, 1] + 0.5 * P[1, 0]
    # entries equal to their transpose are kept bit for bit
    np.testing.assert_array_equal(
        result[[0, 1, 1, 2, 2, 2], [0, 1, 2, 0, 1, 2]], P[[0, 1, 1, 2, 2, 2], [0, 1, 2, 0, 1, 2]]
    )


@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 5), st.sampled_from([1e-100, 1.0, 1e100]))
def test_any_gram_matrix_is_a_covariance_and_comes_back_exactly_symmetric(seed, d, rank, scale):
    # A A^T is positive semi-definite; computed in floating point it is symmetric only to rounding
    rng = np.random.default_rng(seed)
    A = rng.normal(0.0, 1.0, (d, rank)) * scale
    P = A @ A.T + rng.normal(0.0, 1e-12, (d, d)) * np.abs(A @ A.T).max()
    for value, shape in ((P, (d, d)), (np.stack([P, np.eye(d)]), (2, d, d))):
        result = covariance("P", value, shape, definite=False)
        swapped = np.swapaxes(value, -1, -2)
        np.testing.assert_array_equal(result, np.swapaxes(result, -1, -2))
        # each entry moves halfway to its transpose (to rounding), no further
        moved = np.abs(result - value)
        assert np.all(moved <= 0.5 * np.abs(value - swapped) + 4 * np.finfo(float).eps * np.abs(value))


def test_a_stack_names_the_first_matrix_that_breaks_the_rule():
    R = np.stack([np.eye(2), np.diag([1.0, 0.0]), np.diag([1.0, -1.0])])
    with pytest.raises(ValueError, match=r"^R\[1\] must be positive definite: smallest eigenvalue 0 <= "):
        covariance("R", R, (3, 2, 2), definite=True)
    with pytest.raises(
        ValueError, match=r"^R\[2\] must be positive semi-definite: smallest eigenvalue -1 < "
    ):
        covariance("R", R, (3, 2, 2), definite=False)
    grid = np.broadcast_to(np.eye(2), (2, 3, 2, 2)).copy()
    grid[1, 2, 0, 1] = 0.5
    with pytest.raises(ValueError, match=r"^S\[1, 2\] must be symmetric"):
        covariance("S", grid, (2, 3, 2, 2), definite=True)


def test_a_zero_matrix_is_positive_semi_definite_but_not_definite():
    np.testing.assert_array_equal(covariance("P", np.zeros((3, 3)), (3, 3), definite=False), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"^P must be positive definite: smallest eigenvalue 0 <= .* = 0$"):
        covariance("P", np.zeros((3, 3)), (3, 3), definite=True)


def test_empty_covariances_are_accepted():
    assert covariance("P", [], (0, 0), definite=True).shape == (0, 0)
    assert covariance("R", np.zeros((0, 2, 2)), (0, 2, 2), definite=True).shape == (0, 2, 2)


@pytest.mark.parametrize(
    "value, shape, message",
    [
        (np.eye(3), (2, 2), r"^P must have shape \(2, 2\), got \(3, 3\)$"),
        (np.diag([1.0, math.nan]), (2, 2), r"^P must be finite, got 1 non-finite$"),
        (np.eye(2, dtype=bool), (2, 2), "^P must be a .* array of real numbers, got dtype bool$"),
        (np.eye(2), (2, 3), r"^P: a covariance's shape ends in \(d, d\), got \(2, 3\)$"),
        (np.ones(2), (2,), r"^P: a covariance's shape ends in \(d, d\), got \(2,\)$"),
    ],
)
def test_covariance_refuses_bad_shapes_and_values(value, shape, message):
    with pytest.raises(ValueError, match=message):
        covariance("P", value, shape, definite=False)
