"""What one scan's beams say about posts expected at known places: there, gone (seen through), or nothing.

A post of radius ``r`` expected at ``p`` (m, scan frame) with position covariance ``Sigma`` (2, 2) lies at
range ``d = |p|`` and bearing ``beta = atan2(p_y, p_x)``. With ``u = p / d`` and ``v = [-u_y, u_x] / d``
the standard deviations of that range and bearing are::

    sigma_d = sqrt(u^T Sigma u),    sigma_beta = sqrt(v^T Sigma v)

A beam at angle ``phi`` surely meets the post, wherever it is within ``k`` standard deviations (``k``
``sigmas``), when it lies in the post's **core**::

    |wrap(phi - beta)| <= asin(r / d) - k sigma_beta

Each core beam reads ``rho`` and is, with ``s = sqrt(sigma_range^2 + sigma_d^2)`` (the LiDAR's range noise
and the post's range uncertainty):

* **beyond**: ``rho > d + r + k s`` (past the post's far side), or no return within the sensor's reach
  (``+inf``, or ``rho >= range_max``: REP 117);
* **at**: a return in ``[d - r - k s, d + r + k s]`` (something where the post is);
* **short**: ``rho < d - r - k s`` (something nearer hides the post);
* **unknown**: ``0.0``, NaN, ``-inf`` or below ``range_min`` (an LDS-01 writes 0.0 for any missing return,
  a dropout on the post itself among them).

The post is **seen through** when its core holds at least one beam and every core beam is beyond; it is
**present** when some core beam is at it; otherwise the scan says nothing about it: occluded (a short
beam), a dropout, an empty core (small, far, or uncertain), or a post not wholly inside the scan's reach
(``d - r - k s < range_min`` or ``d + r + k s >= range_max``) or field of view (a core beam index off the
scan's beams when the scan is not a full turn).

Vectorised over the posts: O(n w) for the widest core of ``w`` beams.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .detection import beams_in_one_turn
from .range_scan import RangeScan


class Evidence(IntEnum):
    """What a scan says about one expected post (module docstring)."""

    NONE = 0  # nothing: occluded, out of reach or view, no beam surely on it, a dropout
    PRESENT = 1  # a core beam returns where the post is
    SEEN_THROUGH = 2  # every core beam (at least one) passes beyond its far side


def post_evidence(
    scan: RangeScan,
    p_scan: ArrayLike,
    covariance: ArrayLike,
    radius_m: float,
    range_std_m: float,
    sigmas: float,
) -> NDArray[np.int8]:
    """:class:`Evidence` (n,) of posts of radius ``radius_m`` expected at ``p_scan`` (n, 2) (m, the scan's
    frame) with position covariance ``covariance`` (n, 2, 2) (m^2), read from ``scan`` whose ranges have
    standard deviation ``range_std_m``, at ``sigmas`` standard deviations (module docstring). ValueError
    for shapes that disagree."""
    p = np.asarray(p_scan, dtype=np.float64)
    Sigma = np.asarray(covariance, dtype=np.float64)
    n = len(p)
    if p.shape != (n, 2) or Sigma.shape != (n, 2, 2):
        raise ValueError(f"need posts (n, 2) and covariances (n, 2, 2), got {p.shape} and {Sigma.shape}")
    evidence = np.full(n, Evidence.NONE, dtype=np.int8)
    d = np.hypot(p[:, 0], p[:, 1])
    if n == 0:
        return evidence
    u = p / np.maximum(d, 1e-12)[:, None]
    v = np.stack([-u[:, 1], u[:, 0]], axis=1) / np.maximum(d, 1e-12)[:, None]
    # sigma_d^2 = u^T Sigma u, sigma_beta^2 = v^T Sigma v
    sigma_d = np.sqrt(np.maximum(np.einsum("ki,kij,kj->k", u, Sigma, u), 0.0))
    sigma_beta = np.sqrt(np.maximum(np.einsum("ki,kij,kj->k", v, Sigma, v), 0.0))
    margin = sigmas * np.hypot(range_std_m, sigma_d)
    near, far = d - radius_m - margin, d + radius_m + margin
    in_reach = (near >= scan.range_min) & (far < scan.range_max) & (d > radius_m)
    # core half-width: asin(r / d) - k sigma_beta
    half = np.arcsin(np.minimum(radius_m / np.maximum(d, radius_m), 1.0)) - sigmas * sigma_beta
    candidates = (in_reach & (half >= 0.0)).nonzero()[0]
    if len(candidates) == 0:
        return evidence
    step = abs(scan.angle_increment)
    samples = scan.ranges.shape[0]
    turn = beams_in_one_turn(samples, scan.angle_increment)
    full_turn = (turn + 0.5) * step >= math.tau
    # beam index of the bearing, counted from angle_min in the direction of the increment, in [0, tau / step)
    beta = np.arctan2(p[candidates, 1], p[candidates, 0])
    offset = np.mod((beta - scan.angle_min) * math.copysign(1.0, scan.angle_increment), math.tau)
    centre, width = offset / step, half[candidates] / step
    first, last = np.ceil(centre - width).astype(np.int64), np.floor(centre + width).astype(np.int64)
    widest = int(np.max(last - first + 1, initial=0))
    if widest <= 0:
        return evidence
    index = first[:, None] + np.arange(widest)
    in_core = index <= last[:, None]
    if full_turn:
        index = np.mod(index, turn)
        in_view = np.ones(len(candidates), dtype=bool)
    else:
        in_view = (first >= 0) & (last < samples)
        index = np.clip(index, 0, samples - 1)
    rho = scan.ranges[index]
    no_return = (rho == math.inf) | (np.isfinite(rho) & (rho >= scan.range_max))
    returned = np.isfinite(rho) & (rho > 0.0) & (rho >= scan.range_min) & (rho < scan.range_max)
    beyond = no_return | (returned & (rho > far[candidates, None]))
    at = returned & (rho >= near[candidates, None]) & (rho <= far[candidates, None])
    has_core = in_core.any(axis=1) & in_view
    seen_through = has_core & (beyond | ~in_core).all(axis=1)
    present = has_core & (at & in_core).any(axis=1)
    evidence[candidates[present]] = Evidence.PRESENT
    evidence[candidates[seen_through]] = Evidence.SEEN_THROUGH
    return evidence
