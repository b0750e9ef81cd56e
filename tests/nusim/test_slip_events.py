"""Slip events and bumps in nusim's simulation, closed loop (tests/slip_scenarios.py: the world, the LiDAR,
the landmark detector and EKF SLAM on its timeline with turtlelib.estimation.slip_recovery), in mapping and in
localization (a phantom turn in place, a wheel slipping while the robot drives, a push into a cylinder):
20 s after the event the pose is within 5 cm of the truth, no landmark was mapped beside the cylinders, and
the recovery's status named the cause while it lasted."""

from __future__ import annotations

import pytest

from slip_scenarios import run_scenario
from turtlelib.estimation.slip_recovery import SlipRecoveryConfig

CAUSES = {"phantom_turn": "wheel slip", "wheel_slip": "wheel slip", "bump": "bump or stall"}


@pytest.mark.parametrize("mode", ["mapping", "localization"])
@pytest.mark.parametrize("event", ["phantom_turn", "wheel_slip", "bump"])
def test_the_filter_recovers_from_the_event_and_names_its_cause(event: str, mode: str):
    result = run_scenario(event, mode)
    _assert_recovered(result, event)


def test_a_waffle_recovers_from_a_wheel_slipping_while_it_drives():
    """The Waffle's wider track: the same 0.75 rad takes its left wheel twice as long on the slick patch."""
    _assert_recovered(run_scenario("wheel_slip", "mapping", model="waffle"), "wheel_slip")


def _assert_recovered(result, event: str) -> None:
    assert result.final_error_m <= 0.05, result
    assert result.spurious == 0
    assert any(CAUSES[event] in message for message in result.messages), result.messages
    assert result.levels[-1] == "ok"


def test_without_recovery_a_phantom_turn_is_locked_in():
    """The same phantom turn with the recovery switched off: the heading error stays, landmarks are mapped
    beside the cylinders (what the recovery is for)."""
    result = run_scenario("phantom_turn", "mapping", recovery=SlipRecoveryConfig(slip_recovery=False))
    assert result.final_heading_rad > 0.5 and result.spurious > 0
