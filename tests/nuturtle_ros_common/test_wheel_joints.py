"""wheel_values: the two wheel joints picked out of a JointState's parallel arrays; WheelJoints checks."""

from __future__ import annotations

import math

import pytest

from nuturtle_ros_common.wheel_joints import WheelJoints, wheel_values


def test_wheel_values_picks_the_wheels_among_other_joints():
    joints = WheelJoints()
    names = ["caster", "wheel_right_joint", "wheel_left_joint"]
    assert wheel_values(joints, names, [9.0, 2.0, 1.0]) == (1.0, 2.0)
    assert WheelJoints("a", "b").names == ["a", "b"]


@pytest.mark.parametrize(
    "names, values, match",
    [
        (["wheel_left_joint", "wheel_right_joint"], [1.0], "2 joint names but 1 values"),
        (["wheel_left_joint"], [1.0], "'wheel_right_joint' is missing"),
        (["wheel_left_joint", "wheel_right_joint", "wheel_right_joint"], [1, 2, 3], "more than once"),
        (["wheel_left_joint", "wheel_right_joint"], [math.nan, 2.0], "non-finite"),
        ([], [], "missing"),
    ],
)
def test_wheel_values_refuses_bad_messages(names, values, match):
    with pytest.raises(ValueError, match=match):
        wheel_values(WheelJoints(), names, values)


@pytest.mark.parametrize("fields", [dict(wheel_left=""), dict(wheel_right="wheel_left_joint")])
def test_wheel_joints_validation(fields):
    with pytest.raises(ValueError):
        WheelJoints(**fields)
