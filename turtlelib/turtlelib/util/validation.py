"""The one way config values and inputs are checked in this suite (ValueError, never assert).

Every config dataclass (turtlelib's, the nodes', the simulator's) validates its fields in
``__post_init__`` with these functions, so every message reads ``<name> must be ..., got <value>``. Each
returns the value converted (``float`` or ``int``); a frozen dataclass stores it back with
:func:`store`.

Arrays: :func:`finite_array` (real numbers of a shape), :func:`landmark_ids` (distinct integer ids) and
:func:`covariance`, the one rule for covariance matrices, alone or stacked: finite; symmetric to
``|P_ij - P_ji| <= SYMMETRY_RTOL max|P|``; positive semi-definite, ``lambda_min(P) >= -EIGENVALUE_RTOL
max|P|``, or positive definite, ``lambda_min(P) > EIGENVALUE_RTOL max|P|`` (both tolerances relative to the
matrix's largest entry, so they do not depend on its units).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterable
from numbers import Integral, Real
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg.lapack import dpotrf

T = TypeVar("T")
_FLOATS = (float, np.float64)
_INT64_MAX = 2**63 - 1
# |P_ij - P_ji| <= SYMMETRY_RTOL max|P|: rounding in a covariance computed by a filter, or written to a file
SYMMETRY_RTOL = 1e-9
# positive semi-definite: lambda_min >= -EIGENVALUE_RTOL max|P|; positive definite: lambda_min > that bound
EIGENVALUE_RTOL = 1e-9


def finite_real(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is a real number (bools excluded) whose float is finite
    (so an int beyond the float range, about 1.8e308, is refused too)."""
    # floats (and numpy's float64, a float subclass) first: the numbers.Real check costs about 1 us
    if type(value) in _FLOATS:
        if math.isfinite(value):
            return float(value)
    elif not isinstance(value, bool) and isinstance(value, Real):
        try:
            as_float = float(value)
        except OverflowError:  # an int beyond the float range
            as_float = math.inf
        if math.isfinite(as_float):
            return as_float
    raise ValueError(f"{name} must be a finite number, got {value!r}")


def positive(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is finite and > 0."""
    if finite_real(name, value) <= 0.0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return float(value)


def non_negative(name: str, value: object) -> float:
    """``value`` as a float; ValueError unless it is finite and >= 0."""
    if finite_real(name, value) < 0.0:
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return float(value)


def integer(name: str, value: object, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an int; ValueError unless it is an integer (bools excluded) with
    ``minimum <= value <= maximum`` (a bound left None is not checked)."""
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value!r}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value!r}")
    return int(value)


def in_range(
    name: str, value: object, low: float, high: float, *, open_low: bool = False, open_high: bool = False
) -> float:
    """``value`` as a float; ValueError unless it is finite and in the interval from ``low`` to ``high``:
    ``[low, high]``, without ``low`` if ``open_low`` and without ``high`` if ``open_high``."""
    x = finite_real(name, value)
    if (x <= low if open_low else x < low) or (x >= high if open_high else x > high):
        interval = f"{'(' if open_low else '['}{low}, {high}{')' if open_high else ']'}"
        raise ValueError(f"{name} must be in {interval}, got {value!r}")
    return x


def one_of(name: str, value: T, choices: Collection[T]) -> T:
    """``value``; ValueError unless it is one of ``choices``."""
    if value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def names(kind: str, **values: object) -> None:
    """ValueError unless every value is a non-empty string and no two are equal (frame ids, joint
    names: ``kind`` says which, for the message)."""
    for name, value in values.items():
        if not isinstance(value, str) or not value:
            raise ValueError(f"{name} must be a non-empty {kind}, got {value!r}")
    if len(set(values.values())) != len(values):
        raise ValueError(f"{', '.join(values)} must be distinct {kind}s, got {list(values.values())}")


def store(
    config: object, fields: Iterable[str], check: Callable[[str, object], object], prefix: str = ""
) -> None:
    """Check each field of a (frozen) dataclass with ``check(prefix + name, value)`` and store what it
    returns (``prefix`` says whose field it is in the message, e.g. ``"lidar "``)."""
    for name in fields:
        object.__setattr__(config, name, check(prefix + name, getattr(config, name)))


def finite_array(name: str, value: ArrayLike, shape: tuple[int, ...]) -> NDArray[np.float64]:
    """``value`` as a C-contiguous float64 copy of ``shape``: ValueError unless real numbers (not
    booleans), finite, of that shape (an empty array for a shape with no elements)."""
    try:
        array = np.array(value)
    except ValueError as error:  # ragged nested lists
        raise ValueError(f"{name} must be a {shape} array of numbers: {error}") from None
    if array.size == 0 and math.prod(shape) == 0:
        return np.zeros(shape)
    if array.dtype == bool or not (np.issubdtype(array.dtype, np.integer) or array.dtype.kind == "f"):
        raise ValueError(f"{name} must be a {shape} array of real numbers, got dtype {array.dtype}")
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    array = np.array(array, dtype=np.float64, order="C")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite, got {np.count_nonzero(~np.isfinite(array))} non-finite")
    return array


def landmark_ids(name: str, ids: ArrayLike) -> NDArray[np.int64]:
    """``ids`` as (n,) int64: ValueError unless a 1-D array of integers (not booleans; Python ints of any
    size too) ``0 <= id < 2^63``, no two equal. An empty array (of any shape or dtype) gives ``n = 0``."""
    array = np.asarray(ids)
    if array.size == 0:
        return np.zeros(0, dtype=np.int64)
    if array.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array, got shape {array.shape}")
    if array.dtype == object:  # Python ints of any size (from a file)
        if not all(isinstance(value, Integral) and not isinstance(value, bool) for value in array):
            raise ValueError(f"{name} must be integers, got {array.tolist()!r}")
    elif array.dtype.kind not in "iu":
        raise ValueError(f"{name} must be integers, got {array.dtype} {array.tolist()!r}")
    values = array.tolist()
    if min(values) < 0:
        raise ValueError(f"{name} must be >= 0, got {[value for value in values if value < 0]}")
    if max(values) > _INT64_MAX:
        raise ValueError(f"{name} must be < 2^63, got {[value for value in values if value >= 2**63]}")
    if len(set(values)) != len(values):
        unique, counts = np.unique(values, return_counts=True)
        raise ValueError(f"{name} must be distinct, got duplicates {unique[counts > 1].tolist()}")
    return np.array(values, dtype=np.int64)


def covariance(name: str, value: ArrayLike, shape: tuple[int, ...], *, definite: bool) -> NDArray[np.float64]:
    """``value`` as a float64 array of ``shape``, one covariance ``(d, d)`` or a stack ``(..., d, d)``, each
    matrix ``P`` finite, symmetric, ``|P_ij - P_ji| <= SYMMETRY_RTOL max|P|``, and positive semi-definite,
    ``lambda_min(P) >= -EIGENVALUE_RTOL max|P|``, or with ``definite`` positive definite,
    ``lambda_min(P) > EIGENVALUE_RTOL max|P|`` (a zero matrix is not).

    Returned exactly symmetric: entries that differ from their transpose become the mean of the two, the
    others stay bit for bit. ValueError naming ``name`` (with the index of the matrix in a stack) and the
    violated bound otherwise.
    """
    if len(shape) < 2 or shape[-1] != shape[-2]:
        raise ValueError(f"{name}: a covariance's shape ends in (d, d), got {shape}")
    P = finite_array(name, value, shape)
    if P.size == 0:
        return P
    P_t = np.swapaxes(P, -1, -2)
    scale = np.abs(P).max(axis=(-2, -1))
    asymmetry = np.abs(P - P_t).max(axis=(-2, -1))
    bound = SYMMETRY_RTOL * scale
    rule = f"symmetric: max |P - P^T| = {{}} > {SYMMETRY_RTOL} * max |P| = {{}}"
    _refuse(name, asymmetry > bound, rule, asymmetry, bound)
    # mean of P_ij and P_ji where they differ (both halves, so no overflow); equal entries stay bit for bit
    P = np.where(P == P_t, P, 0.5 * P + 0.5 * P_t)
    bound = EIGENVALUE_RTOL * scale
    if shape[-1] == 2:
        # 2x2: lambda_min = (a + c) / 2 - sqrt(((a - c) / 2)^2 + b^2) in closed form, a whole stack at once
        # (its rounding, about eps max|P|, is far below the bound)
        a, b, c = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
        smallest = (0.5 * a + 0.5 * c) - np.hypot(0.5 * a - 0.5 * c, b)
    else:
        if P.ndim == 2:
            # lambda_min > -bound (> bound)  <=>  P + bound I (P - bound I) is positive definite: a Cholesky
            # factorisation (a quarter of the time of the eigenvalues) accepts it; the eigenvalues decide
            # the rest
            _, info = dpotrf(
                P + (-bound if definite else bound) * np.eye(len(P)), lower=1, clean=0, overwrite_a=1
            )
            if info == 0:
                return P
        smallest = np.linalg.eigvalsh(P)[..., 0]
    if definite:
        rule = f"positive definite: smallest eigenvalue {{}} <= {EIGENVALUE_RTOL} * max |P| = {{}}"
        _refuse(name, ~(smallest > bound), rule, smallest, bound)
    else:
        rule = f"positive semi-definite: smallest eigenvalue {{}} < -{EIGENVALUE_RTOL} * max |P| = {{}}"
        _refuse(name, smallest < -bound, rule, smallest, -bound)
    return P


def _refuse(
    name: str, violated: NDArray[np.bool_], rule: str, value: NDArray[np.float64], bound: NDArray[np.float64]
) -> None:
    """ValueError ``<name>[index] must be <rule>`` for the first matrix (of a stack) that ``violated`` the
    rule, ``rule``'s two ``{}`` filled with its ``value`` and its ``bound``."""
    if violated.any():
        index = np.unravel_index(np.argmax(violated), violated.shape)
        where = f"[{', '.join(str(i) for i in index)}]" if index else ""
        raise ValueError(
            f"{name}{where} must be " + rule.format(f"{value[index]:.3g}", f"{bound[index]:.3g}")
        )
