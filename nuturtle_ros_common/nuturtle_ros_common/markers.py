"""visualization_msgs helpers shared by the nodes: cylinders on the floor, and reading them back.

Landmarks travel as MarkerArrays (nusim's `fake_sensor`, the `landmarks` detector): one CYLINDER (action
ADD) per landmark, its centre in ``pose.position`` (x, y; m) in the header's frame, its diameter in
``scale.x``. DELETE / DELETEALL markers only tidy a display.

A detection's noise travels with it in ``Marker.text`` (which a CYLINDER does not draw): its range-bearing
covariance ``R`` (2 x 2; ``[range m, bearing rad]`` about the header frame's origin, m^2, m rad, rad^2) as
``R=<R_rr> <R_rb> <R_bb>``, each a Python ``repr`` of a float, so that the text gives back the very floats
written (:func:`noise_text` writes it, :func:`marker_noise` reads it). An array whose markers carry no
text (nusim's `fake_sensor`, a recording made before the convention) has no noise of its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Time
from numpy.typing import NDArray
from visualization_msgs.msg import Marker, MarkerArray

# Marker.text of a detection's noise: NOISE_PREFIX, then R_rr, R_rb, R_bb (repr floats) apart by spaces
NOISE_PREFIX = "R="
# Drawn height of cylinders (m): display only.
MARKER_HEIGHT_M = 0.25
RGBA = tuple[float, float, float, float]


def set_color(marker: Marker, rgba: RGBA) -> None:
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = rgba


def cylinder_marker(
    frame_id: str, stamp: Time, ns: str, marker_id: int, x: float, y: float, radius_m: float, rgba: RGBA
) -> Marker:
    """A CYLINDER (action ADD) of diameter 2 radius_m standing on the floor at (x, y)."""
    marker = Marker(ns=ns, id=marker_id, type=Marker.CYLINDER, action=Marker.ADD)
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    marker.pose.position.x = x
    marker.pose.position.y = y
    marker.pose.position.z = 0.5 * MARKER_HEIGHT_M
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = 2.0 * radius_m
    marker.scale.z = MARKER_HEIGHT_M
    set_color(marker, rgba)
    return marker


def delete_all_marker(frame_id: str, stamp: Time) -> Marker:
    """A DELETEALL marker: clears what the publisher showed before (sent first in each array)."""
    marker = Marker(action=Marker.DELETEALL)
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    return marker


@dataclass(frozen=True, eq=False)
class MarkerPositions:
    """The ADD markers of one MarkerArray: ``ids`` (K,), centres ``xy`` (K, 2) (m) in ``frame_id``, all
    stamped ``stamp``."""

    frame_id: str
    stamp: Time
    ids: NDArray[np.int64]
    xy: NDArray[np.float64]


def marker_positions(msg: MarkerArray) -> MarkerPositions:
    """Read the landmarks of ``msg`` (module docstring); DELETE / DELETEALL markers give the frame and
    stamp of an array without landmarks.

    ValueError for an empty array, markers of different frames or stamps, repeated ids among the ADD
    markers, or non-finite positions.
    """
    if not msg.markers:
        raise ValueError("empty MarkerArray: no frame or stamp")
    frames = {marker.header.frame_id for marker in msg.markers}
    stamps = {(marker.header.stamp.sec, marker.header.stamp.nanosec) for marker in msg.markers}
    if len(frames) != 1 or len(stamps) != 1:
        raise ValueError(f"markers of one array must share frame and stamp, got frames {sorted(frames)}")
    added = [marker for marker in msg.markers if marker.action == Marker.ADD]
    ids = np.array([marker.id for marker in added], dtype=np.int64)
    if len(set(ids.tolist())) != len(ids):
        raise ValueError(f"repeated marker ids {ids.tolist()}")
    xy = np.array([(marker.pose.position.x, marker.pose.position.y) for marker in added], dtype=np.float64)
    xy = xy.reshape(-1, 2)
    if not np.isfinite(xy).all():
        raise ValueError("non-finite marker position")
    first = msg.markers[0]
    return MarkerPositions(first.header.frame_id, first.header.stamp, ids, xy)


def noise_text(R: NDArray[np.float64]) -> str:
    """The ``Marker.text`` carrying a range-bearing covariance ``R`` (2, 2) (module docstring):
    ``R=<R_rr> <R_rb> <R_bb>``, exact floats (``R_br`` is ``R_rb``)."""
    r_rr, r_rb, r_bb = float(R[0, 0]), float(R[0, 1]), float(R[1, 1])
    return f"{NOISE_PREFIX}{r_rr!r} {r_rb!r} {r_bb!r}"


def marker_noise(msg: MarkerArray) -> NDArray[np.float64] | None:
    """The range-bearing covariances ``R`` (K, 2, 2) carried by the ADD markers of ``msg`` (module
    docstring), in the order of :func:`marker_positions`; None when none of them carries a text.

    ValueError when only some carry one, or for a text that is not ``R=`` followed by three finite numbers
    (whether ``R`` is a covariance is for its user to judge).
    """
    texts = [marker.text for marker in msg.markers if marker.action == Marker.ADD]
    if not any(texts):
        return None
    R = np.empty((len(texts), 2, 2))
    for k, text in enumerate(texts):
        values = text.removeprefix(NOISE_PREFIX).split(" ") if text.startswith(NOISE_PREFIX) else []
        try:
            r_rr, r_rb, r_bb = (float(value) for value in values)
        except ValueError:
            raise ValueError(
                f"marker text {text!r} is not a detection's noise {NOISE_PREFIX!r}<R_rr> <R_rb> <R_bb>"
            ) from None
        R[k] = ((r_rr, r_rb), (r_rb, r_bb))
    if not np.isfinite(R).all():
        raise ValueError("non-finite detection noise in a marker text")
    return R


def ellipse_marker(
    frame_id: str,
    stamp: Time,
    ns: str,
    marker_id: int,
    xy: NDArray[np.float64],
    covariance: NDArray[np.float64],
    n_sigma: float,
    rgba: RGBA,
) -> Marker:
    """A flat CYLINDER drawing the ``n_sigma`` ellipse of a 2D Gaussian (mean ``xy``, ``covariance``
    (2, 2), m^2): axes ``2 n_sigma sqrt(lambda_i)`` along the eigenvectors of the covariance."""
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    axes = 2.0 * n_sigma * np.sqrt(np.clip(eigenvalues, 0.0, None))
    yaw = math.atan2(eigenvectors[1, 1], eigenvectors[0, 1])  # the major axis (largest eigenvalue)
    marker = Marker(ns=ns, id=marker_id, type=Marker.CYLINDER, action=Marker.ADD)
    marker.header.frame_id = frame_id
    marker.header.stamp = stamp
    marker.pose.position.x = float(xy[0])
    marker.pose.position.y = float(xy[1])
    marker.pose.position.z = 0.005
    marker.pose.orientation.z = math.sin(yaw / 2.0)
    marker.pose.orientation.w = math.cos(yaw / 2.0)
    marker.scale.x, marker.scale.y, marker.scale.z = float(axes[1]), float(axes[0]), 0.01
    set_color(marker, rgba)
    return marker
