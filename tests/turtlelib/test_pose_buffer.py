"""PoseBuffer: exact samples, interpolation along the twist between them, no extrapolation, bounds."""

import math

import numpy as np
import pytest

from turtlelib import Transform2D, Twist2D, integrate_twist
from turtlelib.geometry.pose_buffer import PoseBuffer


def test_samples_and_interpolation_along_one_arc():
    buffer = PoseBuffer(10)
    T0 = Transform2D(1.0, 2.0, 0.5)
    twist = Twist2D(0.8, 1.0, 0.0)  # an arc
    buffer.add(100, T0)
    buffer.add(300, T0 @ integrate_twist(twist))
    assert buffer.at(100) == T0
    # a quarter of the way: the quarter arc
    expected = T0 @ integrate_twist(twist * 0.25)
    np.testing.assert_allclose(buffer.at(150).as_array(), expected.as_array(), atol=1e-12)


def test_no_pose_outside_the_span():
    buffer = PoseBuffer(10)
    assert buffer.at(0) is None
    buffer.add(100, Transform2D())
    buffer.add(200, Transform2D(1.0, 0.0, 0.0))
    assert buffer.at(99) is None and buffer.at(201) is None
    assert buffer.at(200) == Transform2D(1.0, 0.0, 0.0)


def test_keeps_the_newest_samples_and_refuses_older_stamps():
    buffer = PoseBuffer(3)
    for k in range(5):
        buffer.add(k, Transform2D(float(k), 0.0, 0.0))
    assert len(buffer) == 3 and buffer.at(1) is None and buffer.at(2) == Transform2D(2.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="not after"):
        buffer.add(4, Transform2D())
    buffer.clear()
    assert buffer.latest_time_ns is None
    buffer.add(0, Transform2D())


def test_heading_interpolates_across_pi():
    buffer = PoseBuffer(4)
    buffer.add(0, Transform2D(0.0, 0.0, math.pi - 0.1))
    buffer.add(10, Transform2D(0.0, 0.0, -math.pi + 0.1))
    assert buffer.at(5).theta == pytest.approx(math.pi, abs=1e-12) or buffer.at(5).theta == pytest.approx(
        -math.pi, abs=1e-12
    )


@pytest.mark.parametrize("bad", [1.5, "3", None])
def test_invalid_stamps_raise(bad):
    with pytest.raises(ValueError):
        PoseBuffer(4).add(bad, Transform2D())
