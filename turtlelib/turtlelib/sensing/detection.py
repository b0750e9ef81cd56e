"""Cylinder (landmark) detection in a 2D LiDAR scan: clustering, circle fitting, classification.

Pipeline (all in the sensor frame; m, rad)
------------------------------------------
1. Points: beam ``b`` at ``phi_b = angle_min + b angle_increment`` within the first full turn
   (:func:`beams_in_one_turn`) with a valid range ``rho_b`` (finite, ``> 0`` and inside ``[range_min,
   range_max]``: 0.0, NaN and inf mean no return) gives ``p_b = rho_b [cos(phi_b), sin(phi_b)]``; other
   beams are dropped.
2. Clustering: consecutive valid points ``p_i, p_{i+1}`` with ``k`` beams without a return between them
   belong to the same cluster when ``|p_{i+1} - p_i| < cluster_threshold + k min(rho_i, rho_{i+1})
   |angle_increment|`` and ``k <= max_dropout_beams``: a missing beam is taken as a dropout (the LDS-02
   loses points on dark and glancing surfaces) and adds the width it would have covered, so dropouts
   neither split a post nor cut a wall into post-sized fragments. When the scan covers a full turn the
   point sequence is cyclic: the last and the first cluster are merged if the gap across the seam passes
   the same test.
3. Candidates: clusters with ``n >= min_points`` points and a chord ``|p_n - p_1| <= 2 max_radius``
   (no cylinder is wider than its diameter).
4. Beyond each end (:func:`_cluster_sides`): the first return within ``max_dropout_beams + 1`` beams past
   the end *saw past* the cluster when its range jumps away by more than the gap across the beams (a
   silhouette edge), hides it when it jumps towards the sensor (an occluder), and otherwise continues
   the same surface (the cluster is a fragment of something larger: rejected); no return in all those
   beams is open space (saw past). The cylinder's outline (a ray from the sensor tangent to it) lies
   between the end beam and the beam that saw past.
5. Circle fit, all candidates in one batched pass: the hyper fit
   (:func:`turtlelib.sensing.circle_fit.fit_circles`), then one Gauss-Newton step of the LiDAR likelihood
   (:func:`turtlelib.sensing.circle_fit.refine_for_range_sensor`): range noise ``beam_range_std`` along each
   beam plus the silhouette rays, each known to a uniform error over one beam step (lateral standard deviation
   ``rho_end * angle_increment / sqrt(12)``). With 1 cm noise and a handful of points per cylinder the
   silhouette fixes the radius far better than the ranges do.
6. Classification: a candidate is a cylinder when every test passes:
   * it shows at least ``min_silhouette_edges`` silhouette edges (a wall seen between two nearer
     objects shows none) and no end where the surface goes on;
   * its ``n`` returns are at least ``min_return_fraction`` of the beams from its first to its last
     (a cluster made mostly of bridged dropouts is no evidence of a shape);
   * the radius lies in ``[min_radius, max_radius]`` and the RMS residual is ``<= max_residual``;
   * the centre lies beyond the points, ``|c| > mean_i |p_i|`` (the sensor sees a cylinder's outside;
     an arena corner or any concave curve has its centre on the sensor's side);
   * inscribed-angle test (Xavier et al., "Fast line, arc/circle and leg detection from laser scan
     data", ICRA 2005): by the inscribed angle theorem every interior point ``p_i`` of an arc sees the
     chord ``p_1 p_n`` under the same angle ``alpha_i = angle(p_1 - p_i, p_n - p_i) = pi - arc / 2``,
     and a cylinder seen from outside shows at most half its circumference, so the mean of ``alpha_i``
     lies in ``[min_inscribed_angle, max_inscribed_angle]`` and their standard deviation is at most
     ``max_inscribed_angle_std``; a wall gives about 180 deg and a corner widely varying angles. (The
     upper bound sits well above the noise-free 135 deg: with 1 cm noise a far cylinder's few points
     look flatter than they are.)
   * silhouette clearance: a beam that saw past the cluster misses the circle, ``|v x c| >= R -
     silhouette_tolerance`` for its direction ``v``.
7. Measurement: centre ``c`` gives ``range_m = |c|``, ``bearing_rad = atan2(c_y, c_x)`` and the
   range-bearing covariance ``R = diag(range_std^2, bearing_std^2)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import partial
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..util.validation import finite_real, in_range, integer, non_negative, positive, store
from .circle_fit import fit_circles, refine_for_range_sensor
from .range_scan import RangeScan

# A scan is a full turn when the angular gap from its last beam back to its first is at most this many
# beam increments.
_SEAM_GAP_INCREMENTS = 1.5
# Direction from a cluster's first and last beam to the beams outside it
_BEFORE_AFTER = np.array([-1, 1])
# Floor on a silhouette edge's standard deviation: at a subnormal range rho * increment / sqrt(12) underflows
_SMALLEST_EDGE_STD = float(np.finfo(np.float64).tiny)


@dataclass(frozen=True)
class DetectorConfig:
    """Thresholds of the cylinder detector (field names are the ``landmarks`` node's ROS parameters).

    Clustering and candidates:

    * ``cluster_threshold`` (m, > 0): largest gap between consecutive points of one cluster;
    * ``max_dropout_beams`` (int >= 0): most beams without a return in a row taken as dropouts (bridged
      inside a cluster, looked past beside it: :func:`_cluster_sides`);
    * ``min_points`` (int >= 3): fewest points (returns) of a cylinder;
    * ``min_return_fraction`` (in [0, 1]): fewest returns per beam the cluster spans.

    Classification (see the module docstring):

    * ``min_radius``, ``max_radius`` (m, ``0 <= min_radius < max_radius``): radius window;
    * ``max_residual`` (m, > 0): largest RMS distance of the points from the fitted circle;
    * ``min_inscribed_angle``, ``max_inscribed_angle`` (rad, ``0 <= min < max <= pi``): window of the
      mean inscribed angle; ``max_inscribed_angle_std`` (rad, > 0): largest spread of the angles;
    * ``min_silhouette_edges`` (int in [0, 2]): fewest silhouette edges a cylinder must show;
    * ``silhouette_tolerance`` (m, >= 0): how far a circle may reach into a beam that saw past it.

    Fit and measurement:

    * ``beam_range_std`` (m, > 0): range noise of one beam (noise and quantisation), for the refinement;
    * ``min_cos_incidence`` (in (0, 1]): floor on the cosine of a beam's incidence angle there;
    * ``range_std`` (m, > 0), ``bearing_std`` (rad, > 0): standard deviations of a detection's range and
      bearing, ``R = diag(range_std^2, bearing_std^2)``: THE observation noise of a detection, which slam
      fuses it with (the ``landmarks`` node sends it along with each detection).

    The defaults suit the TurtleBot3 LiDARs (LDS-01, LDS-02, Gazebo's: beams of about 1 deg, about 1 cm
    range noise) and cylinders of 0.03-0.2 m radius (ours are 0.038 m, turtlebot3_world's 0.15 m);
    ``range_std`` and ``bearing_std`` (0.02 m, 0.01 rad) are what the detector achieves as the filter needs
    it (docs/benchmarks.md, "Detection noise in the demo"): the errors of its detections against nusim's
    truth are 11 mm RMS in range (a bias of -5 mm, the fit's on a 0.038 m post, included: shared by every
    sighting, so the range is given more) and 3.9 mrad RMS in bearing (no bias, uncorrelated from scan to
    scan), 4.3 mrad on the synthetic LDS-01 scenes; 0.01 rad leaves the margin that keeps the pose
    consistent over the demo's seeds (NEES mean 3.1 for 3 dof; 0.005 rad makes it overconfident, the
    earlier 0.02 rad underconfident once landmarks confirm from several viewpoints).
    Invalid values raise ValueError.
    """

    cluster_threshold: float = 0.1
    max_dropout_beams: int = 2
    min_points: int = 4
    min_return_fraction: float = 0.6
    min_radius: float = 0.02
    max_radius: float = 0.25
    max_residual: float = 0.02
    min_inscribed_angle: float = math.radians(80.0)
    max_inscribed_angle: float = math.radians(160.0)
    max_inscribed_angle_std: float = 0.8
    min_silhouette_edges: int = 1
    silhouette_tolerance: float = 0.03
    beam_range_std: float = 0.01
    min_cos_incidence: float = 0.2
    range_std: float = 0.02
    bearing_std: float = 0.01

    def __post_init__(self) -> None:
        prefix = "detector "
        store(self, ("min_points",), partial(integer, minimum=3, maximum=2**31 - 1), prefix)
        store(self, ("max_dropout_beams",), partial(integer, minimum=0, maximum=2**31 - 1), prefix)
        store(self, ("min_return_fraction",), partial(in_range, low=0.0, high=1.0), prefix)
        store(self, ("min_silhouette_edges",), partial(integer, minimum=0, maximum=2), prefix)
        positive_fields = ("cluster_threshold", "max_residual", "max_inscribed_angle_std", "beam_range_std")
        store(self, (*positive_fields, "range_std", "bearing_std"), positive, prefix)
        store(self, ("silhouette_tolerance", "min_radius"), non_negative, prefix)
        store(self, ("max_radius",), finite_real, prefix)
        store(self, ("min_cos_incidence",), partial(in_range, low=0.0, high=1.0, open_low=True), prefix)
        angles = ("min_inscribed_angle", "max_inscribed_angle")
        store(self, angles, partial(in_range, low=0.0, high=math.pi), prefix)
        if not self.min_radius < self.max_radius:
            raise ValueError(f"need min_radius < max_radius, got {self.min_radius}, {self.max_radius}")
        if not self.min_inscribed_angle < self.max_inscribed_angle:
            raise ValueError(
                "need min_inscribed_angle < max_inscribed_angle, got "
                f"{self.min_inscribed_angle}, {self.max_inscribed_angle}"
            )


@dataclass(frozen=True, eq=False)
class Clusters:
    """K clusters of scan points stored back to back.

    ``p_sensor`` (P, 2): points in the sensor frame (m); cluster k is
    ``p_sensor[offsets[k]:offsets[k + 1]]``, its points in scan order (a cluster merged across the seam
    of a full-turn scan starts with the end of the scan). ``offsets`` (K + 1,) rises from 0 to P;
    ``beam_index`` (P,) is each point's beam number in the scan.
    """

    p_sensor: NDArray[np.float64]
    offsets: NDArray[np.intp]
    beam_index: NDArray[np.intp]

    def __len__(self) -> int:
        return self.offsets.shape[0] - 1

    @property
    def sizes(self) -> NDArray[np.intp]:
        """Points per cluster, shape (K,)."""
        return np.diff(self.offsets)

    @property
    def labels(self) -> NDArray[np.intp]:
        """Each point's cluster number, shape (P,)."""
        return np.repeat(np.arange(len(self)), self.sizes)

    def points(self, k: int) -> NDArray[np.float64]:
        """The points of cluster ``k``, shape (n_k, 2)."""
        if not 0 <= k < len(self):
            raise IndexError(f"cluster {k} out of range for {len(self)} clusters")
        return self.p_sensor[self.offsets[k] : self.offsets[k + 1]]


@dataclass(frozen=True, eq=False)
class Detections:
    """K detected cylinders, as arrays (sensor frame; m, rad).

    ``p_sensor`` (K, 2) centres, ``radius`` (K,), ``n_points`` (K,) int, ``residual`` (K,) RMS fit
    error, ``range_m`` (K,) and ``bearing_rad`` (K,) of the centres, ``covariance`` (K, 2, 2) of the
    measurement ``[range_m, bearing_rad]``, and ``cluster_index`` (K,) the cluster of the scan's
    :class:`Clusters` each came from (-1 when not given). Inconsistent shapes raise ValueError.
    """

    p_sensor: NDArray[np.float64]
    radius: NDArray[np.float64]
    n_points: NDArray[np.intp]
    residual: NDArray[np.float64]
    range_m: NDArray[np.float64]
    bearing_rad: NDArray[np.float64]
    covariance: NDArray[np.float64]
    cluster_index: NDArray[np.intp] | None = None

    def __post_init__(self) -> None:
        k = self.radius.shape[0] if self.radius.ndim == 1 else -1
        if self.cluster_index is None:
            object.__setattr__(self, "cluster_index", np.full(max(k, 0), -1, dtype=np.intp))
        vectors = (
            self.radius,
            self.n_points,
            self.residual,
            self.range_m,
            self.bearing_rad,
            self.cluster_index,
        )
        if (
            k < 0
            or any(v.shape != (k,) for v in vectors)
            or self.p_sensor.shape != (k, 2)
            or self.covariance.shape != (k, 2, 2)
        ):
            raise ValueError("detection arrays must have shapes (K, 2), (K,) x 5 and (K, 2, 2)")

    def __len__(self) -> int:
        return self.radius.shape[0]

    def measurements(self) -> NDArray[np.float64]:
        """``[range_m, bearing_rad]`` per detection, shape (K, 2)."""
        return np.column_stack((self.range_m, self.bearing_rad))


def _is_full_turn(angles_rad: NDArray[np.float64]) -> bool:
    """Whether the beams wrap around: the gap from the last beam back to the first is at most
    ``_SEAM_GAP_INCREMENTS`` beam steps (in the scan's direction of rotation)."""
    if angles_rad.shape[0] < 2:
        return False
    step = float(angles_rad[1] - angles_rad[0])
    closing = math.fmod(math.copysign(1.0, step) * float(angles_rad[0] - angles_rad[-1]), math.tau) % math.tau
    return step != 0.0 and closing <= _SEAM_GAP_INCREMENTS * abs(step)


@dataclass(frozen=True, eq=False)
class _ScanGeometry:
    """Beam directions of a scan layout, computed once per layout: ``directions`` (B, 2), whether the
    beams make a ``full_turn``, and the beam step ``increment = |angle_increment|`` (rad)."""

    directions: NDArray[np.float64]  # (B, 2) unit vectors [cos(phi), sin(phi)]
    full_turn: bool
    increment: float

    @classmethod
    def of_layout(cls, samples: int, angle_min: float, angle_increment: float) -> _ScanGeometry:
        """The geometry of beams ``angle_min + b angle_increment``, ``b = 0 .. samples - 1`` (rad)."""
        angles_rad = angle_min + angle_increment * np.arange(samples, dtype=np.float64)
        directions = np.column_stack((np.cos(angles_rad), np.sin(angles_rad)))
        increment = abs(float(angles_rad[1] - angles_rad[0])) if angles_rad.shape[0] > 1 else 0.0
        return cls(directions, _is_full_turn(angles_rad), increment)


def _cluster(
    range_m: NDArray[np.float64],
    valid: NDArray[np.bool_],
    geometry: _ScanGeometry,
    cluster_threshold: float,
    max_dropout_beams: int,
) -> Clusters:
    """Steps 1-2 of the pipeline (see the module docstring) on validated input."""
    beam_index = valid.nonzero()[0]
    # p_b = rho_b [cos(phi_b), sin(phi_b)]
    p_sensor = range_m[beam_index, None] * geometry.directions[beam_index]
    n = beam_index.shape[0]
    if n == 0:
        return Clusters(p_sensor, np.zeros(1, dtype=np.intp), beam_index)
    rho = range_m[beam_index]
    # a new cluster starts where |p_{i+1} - p_i| >= d_max(k_i), k_i the beams without a return between them
    step = p_sensor[1:] - p_sensor[:-1]
    gap2 = step[:, 0] * step[:, 0] + step[:, 1] * step[:, 1]
    reach = _bridged_gap(
        beam_index[1:] - beam_index[:-1] - 1,
        np.minimum(rho[1:], rho[:-1]),
        geometry,
        cluster_threshold,
        max_dropout_beams,
    )
    breaks = (gap2 >= reach * reach).nonzero()[0] + 1
    if geometry.full_turn and breaks.shape[0] > 0:
        seam = p_sensor[0] - p_sensor[-1]
        missing = beam_index[0] + range_m.shape[0] - 1 - beam_index[-1]
        seam_reach = _bridged_gap(
            np.array([missing]), np.minimum(rho[:1], rho[-1:]), geometry, cluster_threshold, max_dropout_beams
        )[0]
        if seam @ seam < seam_reach * seam_reach:
            # merge across the seam: move the last cluster to the front
            last = breaks[-1]
            p_sensor = np.concatenate((p_sensor[last:], p_sensor[:last]))
            beam_index = np.concatenate((beam_index[last:], beam_index[:last]))
            breaks = breaks[:-1] + (n - last)
    offsets = np.empty(breaks.shape[0] + 2, dtype=np.intp)
    offsets[0], offsets[1:-1], offsets[-1] = 0, breaks, n
    return Clusters(p_sensor, offsets, beam_index)


def _bridged_gap(
    missing: NDArray[np.intp],
    rho_m: NDArray[np.float64],
    geometry: _ScanGeometry,
    cluster_threshold: float,
    max_dropout_beams: int,
) -> NDArray[np.float64]:
    """Largest distance (m) that joins two returns with ``missing`` beams without a return between them,
    the nearer at ``rho_m``: ``d_max = cluster_threshold + k rho |increment|`` for ``k <= max_dropout_beams``
    (each missing beam adds the width it would have covered), 0 beyond (never joined)."""
    reach = cluster_threshold + missing * rho_m * geometry.increment
    return np.where(missing <= max_dropout_beams, reach, 0.0)


def beams_in_one_turn(samples: int, angle_increment: float) -> int:
    """How many of a scan's ``samples`` beams the detector uses: the first beams up to one full turn.

    Beam ``b`` lies ``b |angle_increment|`` (rad) past the first; it is kept while ``(b + 1/2)
    |angle_increment| < 2 pi``. A later beam points within half a step of the first beam, one turn on (or
    further round), so it repeats a direction already scanned: Gazebo's LiDAR spans 0 to 6.28 rad in 360
    beams of 6.28/359 rad, and its last beam, 0.0032 rad short of a turn, repeats the first (359 kept).
    LDS-01 (360 beams of 2 pi / 360) and LDS-02 layouts keep every beam. At least one beam is kept.
    ``angle_increment`` must be finite and non-zero.
    """
    step = abs(angle_increment)
    if (samples - 0.5) * step < math.tau:
        return samples
    return max(1, math.ceil(math.tau / step - 0.5))


def _used_beams(scan: RangeScan) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The ranges (m) of the beams of the scan's first full turn (:func:`beams_in_one_turn`) and which of
    them have a return (:meth:`RangeScan.returns`)."""
    samples = beams_in_one_turn(scan.ranges.shape[0], scan.angle_increment)
    return scan.ranges[:samples], scan.returns()[:samples]


def cluster_scan(scan: RangeScan, config: DetectorConfig) -> Clusters:
    """Steps 1-2 of the pipeline (module docstring) on a scan's beams of one full turn.

    Drops beams without a return (0.0, NaN, inf, outside ``[range_min, range_max]``), splits the
    remaining points where consecutive points are ``cluster_threshold`` (m) or more apart, and, when the
    beams cover a full turn (the gap from the last beam back to the first is at most 1.5 beam steps),
    merges the last cluster into the first across the seam.
    """
    range_m, valid = _used_beams(scan)
    geometry = _ScanGeometry.of_layout(range_m.shape[0], scan.angle_min, scan.angle_increment)
    return _cluster(range_m, valid, geometry, config.cluster_threshold, config.max_dropout_beams)


@dataclass(eq=False)
class LandmarkDetector:
    """Finds cylinders in 2D LiDAR scans (see the module docstring for the pipeline and its tests).

    Holds the beam directions of the last scan layout it saw, so it is cheap to call once per scan.
    """

    config: DetectorConfig
    # the last scan layout (samples, angle_min, angle_increment) and its beam geometry
    _layout: tuple[tuple[int, float, float], _ScanGeometry] | None = field(
        default=None, init=False, repr=False
    )

    def detect(self, scan: RangeScan) -> Detections:
        """Cylinders in ``scan`` (sensor frame; m, rad).

        Beams without a return (0.0, NaN, inf, outside ``[range_min, range_max]``) are ignored, and so are
        beams beyond one full turn (:func:`beams_in_one_turn`: Gazebo's last beam repeats its first). The
        scan was validated when it was built (:class:`turtlelib.sensing.range_scan.RangeScan`).
        """
        return self.detect_with_clusters(scan)[0]

    def detect_with_clusters(self, scan: RangeScan) -> tuple[Detections, Clusters]:
        """As :meth:`detect`, also returning every cluster of the scan (for a debug topic)."""
        range_m, valid = _used_beams(scan)
        geometry = self._scan_geometry(range_m.shape[0], scan.angle_min, scan.angle_increment)
        cfg = self.config
        clusters = _cluster(range_m, valid, geometry, cfg.cluster_threshold, cfg.max_dropout_beams)
        return self._classify(clusters, range_m, valid, geometry), clusters

    def _scan_geometry(self, samples: int, angle_min: float, angle_increment: float) -> _ScanGeometry:
        key = (samples, angle_min, angle_increment)
        if self._layout is None or self._layout[0] != key:
            self._layout = (key, _ScanGeometry.of_layout(samples, angle_min, angle_increment))
        return self._layout[1]

    def _classify(
        self,
        clusters: Clusters,
        range_m: NDArray[np.float64],
        valid: NDArray[np.bool_],
        geometry: _ScanGeometry,
    ) -> Detections:
        """Steps 3-7 of the pipeline: fit the candidates, keep those that pass every test."""
        cfg = self.config
        sizes = clusters.offsets[1:] - clusters.offsets[:-1]
        first_all, last_all = clusters.offsets[:-1], clusters.offsets[1:] - 1
        chord = clusters.p_sensor[last_all] - clusters.p_sensor[first_all]
        # 3. candidates: n >= min_points and |p_n - p_1| <= 2 max_radius
        candidate = (sizes >= cfg.min_points) & (
            chord[:, 0] * chord[:, 0] + chord[:, 1] * chord[:, 1] <= 4.0 * cfg.max_radius * cfg.max_radius
        )
        if not candidate.any():
            nothing = np.empty(0, dtype=np.intp)
            return self._detections(np.empty((0, 2)), np.empty(0), nothing, np.empty(0), nothing)
        n = sizes[candidate]
        p = clusters.p_sensor[candidate.repeat(sizes)]
        offsets = np.zeros(n.shape[0] + 1, dtype=np.intp)
        np.cumsum(n, out=offsets[1:])
        starts, ends = offsets[:-1], offsets[1:] - 1
        end_beam = np.empty((n.shape[0], 2), dtype=np.intp)
        end_beam[:, 0] = clusters.beam_index[first_all[candidate]]
        end_beam[:, 1] = clusters.beam_index[last_all[candidate]]

        # 4. what lies beyond each end: the beam that saw past it, an occluder, or more of the same surface
        sides = _cluster_sides(end_beam, range_m, valid, geometry, cfg.max_dropout_beams)
        saw_past = sides.saw_past
        # the outline ray runs halfway between the end beam and the beam that saw past, known to within
        # the m beam steps between them: sigma = m rho_end increment / sqrt(12), inf where none saw past
        edge = _halfway_rays(geometry.directions[end_beam], geometry.directions[sides.neighbour])
        edge_std = np.maximum(
            sides.steps * range_m[end_beam] * (geometry.increment / math.sqrt(12.0)), _SMALLEST_EDGE_STD
        )
        edge_std[~saw_past] = np.inf

        # 5. hyper fit, then one Gauss-Newton step of the LiDAR likelihood (where the hyper fit found a
        # line the fit has no circle, and the cluster is rejected below)
        fits = refine_for_range_sensor(
            p, offsets, fit_circles(p, offsets), cfg.beam_range_std, cfg.min_cos_incidence, edge, edge_std
        )
        centre, radius, residual, is_circle = fits.centre, fits.radius, fits.residual, fits.is_circle
        rho = np.hypot(p[:, 0], p[:, 1])

        # 6. tests
        # |c| > mean_i |p_i|
        beyond = np.hypot(centre[:, 0], centre[:, 1]) * n > np.add.reduceat(rho, starts)
        alpha_mean, alpha_var = _inscribed_angles(p, starts, ends, n)
        # |v x c| >= R - tolerance for each neighbour v that saw past
        v = geometry.directions[sides.neighbour]
        distance = np.abs(v[:, :, 0] * centre[:, None, 1] - v[:, :, 1] * centre[:, None, 0])
        clear = ~saw_past | (distance >= radius[:, None] - cfg.silhouette_tolerance)
        edges_seen = saw_past[:, 0].astype(np.intp) + saw_past[:, 1]
        # n returns over the B = b_last - b_first + 1 beams the cluster spans: n >= min_return_fraction B
        spanned = (end_beam[:, 1] - end_beam[:, 0]) % range_m.shape[0] + 1
        is_cylinder = (
            is_circle
            & (edges_seen >= cfg.min_silhouette_edges)
            & ~sides.continues.any(axis=1)
            & (n >= cfg.min_return_fraction * spanned)
            & (radius >= cfg.min_radius)
            & (radius <= cfg.max_radius)
            & (residual <= cfg.max_residual)
            & beyond
            & (alpha_mean >= cfg.min_inscribed_angle)
            & (alpha_mean <= cfg.max_inscribed_angle)
            & (alpha_var <= cfg.max_inscribed_angle_std * cfg.max_inscribed_angle_std)
            & clear[:, 0]
            & clear[:, 1]
        )
        return self._detections(
            centre[is_cylinder],
            radius[is_cylinder],
            n[is_cylinder],
            residual[is_cylinder],
            np.flatnonzero(candidate)[is_cylinder],
        )

    def _detections(
        self,
        p_sensor: NDArray[np.float64],
        radius: NDArray[np.float64],
        n_points: NDArray[np.intp],
        residual: NDArray[np.float64],
        cluster_index: NDArray[np.intp],
    ) -> Detections:
        """Step 7: range, bearing and covariance of the kept centres."""
        cfg = self.config
        covariance = np.zeros((radius.shape[0], 2, 2))
        # R = diag(range_std^2, bearing_std^2)
        covariance[:, 0, 0] = cfg.range_std * cfg.range_std
        covariance[:, 1, 1] = cfg.bearing_std * cfg.bearing_std
        return Detections(
            p_sensor=p_sensor,
            radius=radius,
            n_points=n_points,
            residual=residual,
            # range = |c|, bearing = atan2(c_y, c_x)
            range_m=np.hypot(p_sensor[:, 0], p_sensor[:, 1]),
            bearing_rad=np.arctan2(p_sensor[:, 1], p_sensor[:, 0]),
            covariance=covariance,
            cluster_index=cluster_index,
        )


class _Sides(NamedTuple):
    """What lies beyond the two ends of K clusters, (K, 2) each (first end, last end): ``neighbour`` the beam
    that tells (the first return outside the end, or the beam next to the end where none does),
    ``steps`` its distance from the end beam in beams, ``saw_past`` whether it saw past the cluster (a
    silhouette edge), ``continues`` whether the surface goes on beyond the end (the cluster is a piece of
    something larger)."""

    neighbour: NDArray[np.intp]
    steps: NDArray[np.intp]
    saw_past: NDArray[np.bool_]
    continues: NDArray[np.bool_]


def _cluster_sides(
    end_beam: NDArray[np.intp],
    range_m: NDArray[np.float64],
    valid: NDArray[np.bool_],
    geometry: _ScanGeometry,
    max_dropout_beams: int,
) -> _Sides:
    """Step 4 of the pipeline: what lies beyond each end of each cluster.

    ``end_beam`` (K, 2) holds each cluster's first and last beam. Beyond an end, up to
    ``max_dropout_beams`` beams without a return may be dropouts (a dark or glancing surface, the LDS-02's
    lost points) rather than open space, so the beam that tells is the first return among the ``m = 1 ..
    max_dropout_beams + 1`` beams beyond the end (wrapping in a full-turn scan, never past the end of a
    partial one). With ``rho_e`` the end's range and ``rho_n`` that return's, the jump between them is
    ``m rho_e increment`` across the beams and ``rho_n - rho_e`` along them:

    * ``rho_n - rho_e > m rho_e increment``: mostly along the beam, away: the beam saw past the
      cluster (a silhouette edge: the sensor sees the end of the object);
    * ``rho_e - rho_n > m rho_e increment``: mostly along the beam, towards the sensor: an occluder hides
      the rest (no silhouette, nothing known);
    * otherwise mostly across the beams: the same surface goes on beyond a gap or a dropout (a wall cut
      by missing beams, the end of a wall continued by the next piece): the cluster is a fragment.

    Where none of the ``max_dropout_beams + 1`` beams returns, the beam next to the end saw past the
    cluster (open space: nothing within range behind it); where the scan (a partial one) ends before a
    return or those beams, that side shows nothing.
    """
    samples = range_m.shape[0]
    step = np.arange(1, max_dropout_beams + 2)
    # beams beyond each end: (K, 2, m), before the first end and after the last
    beyond = end_beam[:, :, None] + _BEFORE_AFTER[None, :, None] * step[None, None, :]
    if geometry.full_turn:
        beyond %= samples
        inside = np.ones(beyond.shape, dtype=bool)
    else:
        inside = (beyond >= 0) & (beyond < samples)
        beyond = np.clip(beyond, 0, samples - 1)
    # the beams up to the scan's edge count; the first return among them tells
    inside = np.logical_and.accumulate(inside, axis=2)
    returned = inside & valid[beyond]
    found = returned.any(axis=2)
    first = np.argmax(returned, axis=2)
    neighbour = np.where(
        found, np.take_along_axis(beyond, first[:, :, None], axis=2)[:, :, 0], beyond[:, :, 0]
    )
    steps = np.where(found, first + 1, 1)
    rho_end = range_m[end_beam]
    across = steps * rho_end * geometry.increment
    along = np.where(found, range_m[neighbour] - rho_end, 0.0)
    open_space = ~found & inside[:, :, -1]
    saw_past = open_space | (found & (along > across))
    continues = found & (np.abs(along) <= across)
    return _Sides(neighbour, steps, saw_past, continues)


def _halfway_rays(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit rays (..., 2) halfway between unit rays ``u`` and ``v`` (..., 2): ``(u + v) / |u + v|``, or ``u``
    where they are opposite."""
    total = u + v
    norm = np.hypot(total[..., 0], total[..., 1])[..., None]
    return np.where(norm > 1e-12, total / np.maximum(norm, 1e-12), u)


def _inscribed_angles(
    p: NDArray[np.float64], starts: NDArray[np.intp], ends: NDArray[np.intp], n: NDArray[np.intp]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean and variance of ``alpha_i = angle(p_1 - p_i, p_n - p_i)`` over each set's interior points."""
    to_first = p[starts].repeat(n, axis=0) - p
    to_last = p[ends].repeat(n, axis=0) - p
    cross = to_first[:, 0] * to_last[:, 1] - to_first[:, 1] * to_last[:, 0]
    dot = to_first[:, 0] * to_last[:, 0] + to_first[:, 1] * to_last[:, 1]
    alpha = np.arctan2(np.abs(cross), dot)
    # the end points see a zero-length side: leave them out
    alpha[starts] = 0.0
    alpha[ends] = 0.0
    interior = n - 2
    alpha_mean = np.add.reduceat(alpha, starts) / interior
    # var = mean(alpha^2) - mean(alpha)^2
    alpha_var = np.add.reduceat(alpha * alpha, starts) / interior - alpha_mean * alpha_mean
    return alpha_mean, alpha_var
