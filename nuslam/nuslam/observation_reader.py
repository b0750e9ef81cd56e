"""slam's observation topics as the filter's observations: one MarkerArray (`landmarks` from the landmarks
node, or nusim's `fake_sensor`) to ``(t_ns, ids, z, R)``.

* Frames: the markers are in the sensor frame or the body frame; positions are moved into the sensor
  frame, ``p_sensor = T_sensor_frame p_frame``.
* Known association (`fake_sensor`, marker id = landmark id): positions with covariance
  ``fake_sensor_std^2 I`` in the markers' frame, rotated into the sensor frame,
  ``Sigma_sensor = C Sigma C^T``, and turned into range-bearing, ``R = J Sigma_sensor J^T``
  (`turtlelib.estimation.range_bearing.observations_from_points`).
* Unknown association (`landmarks`): each detection's own range-bearing noise, carried on its marker
  (`nuturtle_ros_common.markers.marker_noise`), taken about the markers' frame origin: as it is in the
  sensor frame, re-expressed from another frame
  (`turtlelib.estimation.range_bearing.observations_in_sensor_frame`); an array without noise (an old
  recording) gets the filter's default (``R`` None).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from visualization_msgs.msg import MarkerArray

from nuturtle_ros_common.conversions import stamp_nanoseconds
from nuturtle_ros_common.markers import marker_noise, marker_positions
from turtlelib import Transform2D
from turtlelib.estimation.range_bearing import observations_from_points, observations_in_sensor_frame

Observations = tuple[int, NDArray[np.int64] | None, NDArray[np.float64], NDArray[np.float64] | None]


class ObservationReader:
    """``read(msg) -> (t_ns, ids or None, z (K, 2) [range m, bearing rad] in the sensor frame, R (K, 2, 2) or
    None)`` (module docstring), for ``known`` association (ids, ``fake_sensor_std``) or unknown; markers in
    ``sensor_id`` or ``body_id`` (the sensor mounted at ``T_body_sensor``)."""

    def __init__(
        self, known: bool, fake_sensor_std: float, sensor_id: str, body_id: str, T_body_sensor: Transform2D
    ) -> None:
        self._known = known
        self._sensor_id = sensor_id
        self._fake_sensor_covariance = fake_sensor_std**2 * np.eye(2)
        # T_sensor_frame for the frames observations may come in
        self._T_sensor_from = {sensor_id: Transform2D(), body_id: T_body_sensor.inverse()}

    def read(self, msg: MarkerArray) -> Observations:
        """One array's observations (class docstring); ValueError for an unusable array."""
        positions = marker_positions(msg)
        T_sensor_frame = self._T_sensor_from.get(positions.frame_id)
        if T_sensor_frame is None:
            raise ValueError(
                f"markers in frame {positions.frame_id!r}; expected one of {sorted(self._T_sensor_from)}"
            )
        t_ns = stamp_nanoseconds(positions.stamp)
        count = len(positions.ids)
        # p_sensor = T_sensor_frame p_frame
        p_sensor = T_sensor_frame @ positions.xy if count else positions.xy
        if self._known:
            rotation = T_sensor_frame.rotation_matrix()
            # Sigma_sensor = C Sigma C^T
            covariance = np.broadcast_to(rotation @ self._fake_sensor_covariance @ rotation.T, (count, 2, 2))
            z, R = observations_from_points(p_sensor, covariance)
            return t_ns, positions.ids, z, R
        R_frame = marker_noise(msg)
        if R_frame is None or positions.frame_id == self._sensor_id:
            z, _ = observations_from_points(p_sensor, np.zeros((count, 2, 2)))
            return t_ns, None, z, R_frame
        z, R = observations_in_sensor_frame(positions.xy, R_frame, T_sensor_frame)
        return t_ns, None, z, R
