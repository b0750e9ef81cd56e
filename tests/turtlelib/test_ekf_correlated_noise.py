"""Correlated observation errors (SlamConfig.noise_correlation, noise_correlation_length).

The model: two views of one landmark ``d`` apart have errors correlated as ``rho = c exp(-d / l)``, and
each fused observation's ``R`` is scaled by ``(1 + rho) / (1 - rho)`` (``d`` from the landmark's last
view). ``n`` views from one spot (``rho = c`` each time) then carry the information of
``1 + (n - 1) (1 - c) / (1 + c)`` independent ones: the Fisher information of the mean of an AR(1)
sequence with step correlation ``c``.
"""

import math

import numpy as np
import pytest

from turtlelib import Transform2D, TwistNoise, UnicycleMotion
from turtlelib.estimation.ekf_slam import EkfSlam, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations

RANGE_STD, BEARING_STD = 0.05, 0.02
STILL = UnicycleMotion(TwistNoise())  # no motion noise: the pose stays exactly known


def config(c, length, **kwargs):
    return SlamConfig(
        range_std=RANGE_STD,
        bearing_std=BEARING_STD,
        max_range=10.0,
        noise_correlation=c,
        noise_correlation_length=length,
        **kwargs,
    )


@pytest.mark.parametrize(
    "values",
    [
        {"noise_correlation": 1.0},
        {"noise_correlation": -0.1},
        {"noise_correlation": math.nan},
        {"noise_correlation_length": -1.0},
        {"noise_correlation_length": math.inf},
    ],
)
def test_invalid_correlation_is_refused(values):
    with pytest.raises(ValueError):
        SlamConfig(**values)


def test_fusion_scale_hand_values():
    # rho = 0.5 exp(-d / 1): d = 0 -> 3; d = ln 2 -> rho = 0.25 -> 5/3; never viewed (inf) -> 1
    scale = config(0.5, 1.0).fusion_scale(np.array([0.0, math.log(2.0), math.inf]))
    np.testing.assert_allclose(scale, [3.0, 5.0 / 3.0, 1.0], rtol=1e-15)
    # either parameter 0: independent errors
    np.testing.assert_array_equal(config(0.0, 1.0).fusion_scale(np.zeros(2)), [1.0, 1.0])
    np.testing.assert_array_equal(config(0.5, 0.0).fusion_scale(np.zeros(2)), [1.0, 1.0])


@pytest.mark.parametrize("association", ["known", "unknown"])
@pytest.mark.parametrize("c", [0.0, 0.5, 0.9])
def test_views_from_one_spot_carry_the_information_of_an_ar1_sequence(association, c):
    # pose exactly known, landmark straight ahead: its x variance is the range's alone
    # 1 / var_x = (1 + (n - 1) (1 - c) / (1 + c)) / range_std^2
    slam = EkfSlam(config(c, 0.3, confirm_count=1), STILL)
    z = [[2.0, 0.0]]
    n = 6
    for k in range(n):
        if association == "known":
            slam.update_known([0], z)
        else:
            slam.update_unknown(z, stamp_ns=k)
    views = 1.0 + (n - 1) * (1.0 - c) / (1.0 + c)
    assert slam.covariance[3, 3] == pytest.approx(RANGE_STD**2 / views, rel=1e-9)


def test_views_from_far_apart_count_as_independent():
    # the second view 100 correlation lengths from the first: R unscaled (to exp(-100))
    slam = EkfSlam(config(0.9, 0.01), STILL, Transform2D(0.0, 0.0, 0.0))
    slam.update_known([0], [[2.0, 0.0]])
    slam.predict((1.0, 0.0, 1_000_000_000))  # 1 m forward, the landmark still ahead
    slam.update_known([0], [[1.0, 0.0]])
    assert slam.covariance[3, 3] == pytest.approx(RANGE_STD**2 / 2.0, rel=1e-9)


def _landmark_nees(seed, modelled, c=0.9, length=0.2, step=0.02, views=100):
    """NEES (2 dof) of one landmark mapped from ``views`` views ``step`` apart along a line, the errors
    drawn with correlation ``c exp(-d / length)`` (an AR(1) part plus an independent part)."""
    rng = np.random.default_rng(seed)
    slam = EkfSlam(config(c if modelled else 0.0, length if modelled else 0.0), STILL)
    landmark = np.array([[3.0, 1.0]])
    rho = math.exp(-step / length)
    ar1 = rng.normal(size=2)
    for k in range(views):
        if k:
            ar1 = rho * ar1 + math.sqrt(1.0 - rho**2) * rng.normal(size=2)
            slam.predict((step / 0.1, 0.0, 100_000_000))
        error = (math.sqrt(c) * ar1 + math.sqrt(1.0 - c) * rng.normal(size=2)) * [RANGE_STD, BEARING_STD]
        z, _, _ = predict_observations(slam.pose.as_array(), landmark, slam.config.T_body_sensor)
        slam.update_known([0], z + error)
    e = slam.landmarks[0] - landmark[0]
    return float(e @ np.linalg.solve(slam.covariance[3:5, 3:5], e))


def test_modelled_correlation_keeps_the_map_nearly_honest_where_independence_does_not():
    # Monte Carlo over 120 seeded runs (ideal NEES 2): fused as independent the landmark's covariance is
    # ~15 times too small; the model (exact for a pure AR(1) sequence, approximate with an independent
    # part) brings the NEES within a factor 2 of the ideal
    modelled = np.mean([_landmark_nees(seed, True) for seed in range(120)])
    independent = np.mean([_landmark_nees(seed, False) for seed in range(120)])
    assert modelled < 4.0
    assert independent > 15.0
