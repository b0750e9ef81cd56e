"""nuturtle_ros_common.markers: a detection's noise in Marker.text, written and read back exactly."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from ros_test_messages import stamp
from visualization_msgs.msg import Marker, MarkerArray

from nuturtle_ros_common.markers import cylinder_marker, delete_all_marker, marker_noise, noise_text

GREEN = (0.1, 0.8, 0.2, 1.0)
finite = st.floats(allow_nan=False, allow_infinity=False)


def array_of(texts: list[str]) -> MarkerArray:
    """DELETEALL, then one CYLINDER per text (as the landmarks node sends a scan's detections)."""
    markers = [delete_all_marker("base_scan", stamp(0))]
    for k, text in enumerate(texts):
        marker = cylinder_marker("base_scan", stamp(0), "landmarks", k, 1.0 + k, 0.0, 0.038, GREEN)
        marker.text = text
        markers.append(marker)
    return MarkerArray(markers=markers)


def test_hand_computed_noise_text_and_back():
    # range_std 0.02 m, bearing_std 0.006 rad: R = diag(0.0004, 3.6e-05), written as repr floats
    R = np.diag([0.02 * 0.02, 0.006 * 0.006])
    text = noise_text(R)
    assert text == "R=0.0004 0.0 3.6e-05"
    read = marker_noise(array_of([text, noise_text(np.array([[1.0, -0.5], [-0.5, 2.0]]))]))
    np.testing.assert_array_equal(read, [R, [[1.0, -0.5], [-0.5, 2.0]]])


@given(finite, finite, finite)
def test_the_text_gives_back_the_very_floats_written(r_rr, r_rb, r_bb):
    R = np.array([[r_rr, r_rb], [r_rb, r_bb]])
    read = marker_noise(array_of([noise_text(R)]))
    assert read is not None
    assert read.tobytes() == R[None].tobytes()  # bit for bit (signed zeros too)


def test_markers_without_text_carry_no_noise():
    assert marker_noise(array_of(["", ""])) is None
    assert marker_noise(array_of([])) is None


@pytest.mark.parametrize(
    "texts",
    [
        ["R=0.0004 0.0"],
        ["R=0.0004 0.0 0.0004 1.0"],
        ["R=0.0004 zero 0.0004"],
        ["0.0004 0.0 0.0004"],
        ["Q=0.0004 0.0 0.0004"],
        ["R=0.0004  0.0 0.0004"],
        ["R=nan 0.0 0.0004"],
        ["R=0.0004 0.0 inf"],
        ["R=0.0004 0.0 0.0004", ""],
    ],
)
def test_a_malformed_text_is_refused(texts):
    with pytest.raises(ValueError):
        marker_noise(array_of(texts))


def test_only_added_markers_count():
    array = array_of(["R=0.0004 0.0 0.0004"])
    array.markers.append(Marker(action=Marker.DELETE, text="anything"))
    np.testing.assert_array_equal(marker_noise(array), [np.diag([0.0004, 0.0004])])
