"""Relative pose error (RPE) of an estimate against a reference over a band of travelled distance: no ROS.

Poses are planar, ``T = (x, y, theta)``, composed as SE(2). Along the reference ``R_0 .. R_{N-1}`` (stamps
``t_k``) the travelled path is ``s_k = sum_{l < k} |p_{l+1} - p_l|`` (m, the chord lengths between
consecutive reference positions). The estimate is read at the reference's stamps, ``E_k = E(t_k)``
(:meth:`~nuturtle_eval.metrics.PoseSeries.interpolate`: linear in x, y and the unwrapped heading); reference
stamps outside the estimate's time span are left out.

A dense reference (a simulator's truth at 100 Hz) is first thinned to the first pose in each
``SPACING_M`` (0.05 m) of its path, ``floor(s_k / SPACING_M)``, which bounds the pairs to about
``(max_m - min_m) / SPACING_M`` per pose and changes nothing for a reference whose poses are farther apart
(the real-building recordings': one per scan, ~0.5 m). Every pair ``i < j`` whose path distance lies in
the band, ``min_m <= s_j - s_i <= max_m``, compares the two relative motions::

    dR = R_i^-1 R_j,   dE = E_i^-1 E_j,   D_ij = dR^-1 dE

    translation error  |t(D_ij)| = |R(theta_i^E)^T (p_j^E - p_i^E) - R(theta_i^R)^T (p_j^R - p_i^R)|  (m)
    rotation error     |theta(D_ij)| = |wrap((theta_j^E - theta_i^E) - (theta_j^R - theta_i^R))|  (deg)

(``|t(dR^-1 dE)| = |t(dE) - t(dR)|`` because ``dR^-1`` rotates ``t(dE) - t(dR)`` only.) The RPE is the
mean of each over all pairs in the band: the default band, 1 to 10 m, is how the real-building recordings
are scored (docs/real_data.md).

A fixed-distance RPE, as evo's ``evo_rpe --delta d --delta_unit m --all_pairs`` computes it, takes for each
start pose ``i`` the one pose ``j`` whose path distance is nearest to ``d`` (kept when within its tolerance
``tol``). Where the reference's poses are equally spaced along the path (spacing ``h``) and the band is
``[d - tol, d + tol]`` with ``tol < h / 2``, each ``i`` has that one ``j`` in the band and the two agree
pair for pair (tests/nuturtle_eval/test_relative_error.py checks it against the real evo); the 1-10 m
figure is the average of such fixed-distance errors over every distance in the band, each pair counted
once.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from turtlelib import normalize_angles

if TYPE_CHECKING:
    from .metrics import PoseSeries

# The band of path distance the real-building recordings are scored over (m)
RPE_MIN_M, RPE_MAX_M = 1.0, 10.0
# A reference keeps its first pose in each this much of its path (m)
SPACING_M = 0.05
# Pairs handled at once (memory: a few arrays of this many floats)
PAIR_CHUNK = 1 << 20


@dataclass(frozen=True)
class RelativePoseError:
    """The mean ``translation_m`` (m) and ``rotation_deg`` (deg) errors over ``pairs`` pairs of reference
    poses ``min_m`` to ``max_m`` of path apart (module docstring); NaN when no pair is in the band."""

    translation_m: float
    rotation_deg: float
    pairs: int
    min_m: float
    max_m: float


def path_length_m(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """``s_k = sum_{l < k} |p_{l+1} - p_l|`` (N,) along the positions ``xy`` (N, 2) (m; ``s_0 = 0``)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    steps_m = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps_m)])[: xy.shape[0]]


def band_pairs(
    path_m: NDArray[np.float64], min_m: float, max_m: float, chunk: int = PAIR_CHUNK
) -> Iterator[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """Every pair ``(i, j)``, ``i < j``, with ``s_i + min_m <= s_j <= s_i + max_m`` for the path lengths ``s``
    (N,) non-decreasing, as index arrays ``(i, j)`` ordered by ``i`` then ``j``, in pieces of about
    ``chunk`` pairs (all of one ``i`` in one piece). ValueError unless ``0 < min_m <= max_m`` finite."""
    if not (0.0 < min_m <= max_m and math.isfinite(max_m)):
        raise ValueError(f"need 0 < min_m <= max_m finite, got {min_m!r}, {max_m!r}")
    s = np.asarray(path_m, dtype=np.float64).reshape(-1)
    # the j of each i are first[i] .. last[i] - 1 (s is sorted, and s_j - s_i >= min_m > 0 gives j > i)
    first = np.searchsorted(s, s + min_m, side="left")
    counts = np.maximum(np.searchsorted(s, s + max_m, side="right") - first, 0)
    ends = np.cumsum(counts)
    start = 0
    while start < s.size:
        # the start poses whose pairs fit in this piece (at least one)
        stop = max(int(np.searchsorted(ends, ends[start] - counts[start] + chunk, side="right")), start + 1)
        block = np.arange(start, stop)
        i = np.repeat(block, counts[block])
        if i.size:
            # j = first[i] + the pair's rank among those of its i
            rank = np.arange(i.size) - np.repeat(
                ends[block] - counts[block] - (ends[start] - counts[start]), counts[block]
            )
            yield i, first[i] + rank
        start = stop


def pair_errors(
    reference: NDArray[np.float64], estimate: NDArray[np.float64], i: NDArray, j: NDArray
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(|t(D_ij)|, |theta(D_ij)|)`` (P,) (m, rad) of the pairs ``(i, j)`` for poses ``reference``,
    ``estimate`` (N, 3) ``[x, y, theta]`` at the same stamps (module docstring)."""

    def relative(poses: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        # t(T_i^-1 T_j) = R(theta_i)^T (p_j - p_i), theta(T_i^-1 T_j) = theta_j - theta_i
        d = poses[j, :2] - poses[i, :2]
        c, s = np.cos(poses[i, 2]), np.sin(poses[i, 2])
        t = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        return t, poses[j, 2] - poses[i, 2]

    t_ref, theta_ref = relative(reference)
    t_est, theta_est = relative(estimate)
    return np.linalg.norm(t_est - t_ref, axis=1), np.abs(normalize_angles(theta_est - theta_ref))


def relative_pose_error(
    estimate: PoseSeries, reference: PoseSeries, min_m: float = RPE_MIN_M, max_m: float = RPE_MAX_M
) -> RelativePoseError:
    """The RPE of ``estimate`` against ``reference`` over pairs ``min_m`` to ``max_m`` (m) of the
    reference's path apart (module docstring): the estimate read at the reference stamps it covers."""
    if len(estimate) == 0:
        return RelativePoseError(math.nan, math.nan, 0, float(min_m), float(max_m))
    covered = np.flatnonzero(reference.within(estimate.t_s[0], estimate.t_s[-1]))
    path = path_length_m(reference.xy[covered])
    _, first = np.unique(np.floor(path / SPACING_M), return_index=True)
    kept = covered[first]
    ref_poses = reference.poses[kept]
    est_poses = estimate.interpolate(reference.t_s[kept])
    pairs = 0
    translation_sum = rotation_sum = 0.0
    for i, j in band_pairs(path[first], min_m, max_m):
        translation, rotation = pair_errors(ref_poses, est_poses, i, j)
        pairs += i.size
        translation_sum += float(translation.sum())
        rotation_sum += float(rotation.sum())
    if pairs == 0:
        return RelativePoseError(math.nan, math.nan, 0, float(min_m), float(max_m))
    return RelativePoseError(
        translation_m=translation_sum / pairs,
        rotation_deg=math.degrees(rotation_sum / pairs),
        pairs=pairs,
        min_m=float(min_m),
        max_m=float(max_m),
    )
