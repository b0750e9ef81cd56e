"""nuturtle_demo.run.DemoOptions: what a demo run accepts (checked before anything starts)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nuturtle_demo.run import DemoOptions


def test_defaults_and_converted_values():
    options = DemoOptions(seed=np.int64(7), duration_s=30, max_realtime_factor=np.float64(5.0))
    assert options.association == "unknown" and options.world.is_file()
    assert type(options.seed) is int and options.seed == 7
    assert type(options.duration_s) is float and options.duration_s == 30.0
    assert options.realtime_factor == 5.0 and DemoOptions(realtime=True).realtime_factor == 1.0


@pytest.mark.parametrize(
    "fields, message",
    [
        (dict(association="maybe"), r"association must be one of \('known', 'unknown'\), got 'maybe'"),
        (dict(seed=-1), "seed must be >= 0, got -1"),
        (dict(seed=1.5), "seed must be an integer, got 1.5"),
        (dict(seed=True), "seed must be an integer, got True"),
        (dict(duration_s=0.0), "duration_s must be finite and > 0, got 0.0"),
        (dict(duration_s=math.inf), "duration_s must be a finite number, got inf"),
        (dict(duration_s="60"), "duration_s must be a finite number, got '60'"),
        (dict(max_realtime_factor=-2.0), "max_realtime_factor must be finite and > 0, got -2.0"),
        (dict(world="no/such/world.yaml"), "world file no/such/world.yaml does not exist"),
    ],
)
def test_invalid_options_raise_with_their_reason(fields, message):
    with pytest.raises(ValueError, match=message):
        DemoOptions(**fields)
