"""Our trajectory metrics agree with evo's, the standard evaluator, on TUM files our writer wrote.

A reference driving loops (one pose every 0.1 m of path, at ROS-like absolute stamps) and a drifting,
noisy estimate of it in another frame: evo reads both files (file_interface), aligns the estimate with
Umeyama in SE(3) and reports the APE; its all-pairs RPE at a fixed path distance is ours over the band
``[d - tol, d + tol]`` (nuturtle_eval.relative_error's docstring), with the pairs taken on the reference.
"""

import copy

import numpy as np
import pytest
from evo.core import metrics, sync
from evo.tools import file_interface

from nuturtle_eval.metrics import PoseSeries, ate_rmse_aligned
from nuturtle_eval.relative_error import relative_pose_error
from nuturtle_eval.tum import read_tum, write_tum
from turtlelib import Transform2D

STEP_M = 0.1
# the TUM files round positions to 1e-7 m and quaternions to 1e-9
TOLERANCE_M, TOLERANCE_DEG = 1e-6, 1e-5


def _loop_pair(seed: int = 7, n: int = 900) -> tuple[PoseSeries, PoseSeries]:
    """The reference: 90 m of a winding loop, a pose each 0.1 m (0.5 s); the estimate: the reference's
    increments with a heading bias and noise composed from another start, plus jitter."""
    rng = np.random.default_rng(seed)
    turn = 2.0 * np.pi / 200 + rng.normal(0.0, 0.02, n - 1)
    heading = np.concatenate([[0.3], 0.3 + np.cumsum(turn)])
    xy = np.vstack(
        [
            [0.0, 0.0],
            np.cumsum(STEP_M * np.column_stack([np.cos(heading[:-1]), np.sin(heading[:-1])]), axis=0),
        ]
    )
    t = 1.7e9 + 0.5 * np.arange(n)
    reference = PoseSeries(t, np.column_stack([xy, heading]))
    T = Transform2D(2.0, -1.0, 0.4)
    poses = [T]
    for k in range(n - 1):
        increment = Transform2D(*reference.poses[k]).inverse() @ Transform2D(*reference.poses[k + 1])
        noisy = Transform2D(
            increment.x * 1.02 + rng.normal(0, 0.005),
            increment.y + rng.normal(0, 0.005),
            increment.theta + 0.002 + rng.normal(0, 0.004),
        )
        T = T @ noisy
        poses.append(T)
    estimate = np.array([p.as_array() for p in poses]) + rng.normal(0.0, [0.02, 0.02, 0.005], (n, 3))
    return reference, PoseSeries(t, estimate)


@pytest.fixture(scope="module")
def evo_pair(tmp_path_factory):
    reference, estimate = _loop_pair()
    folder = tmp_path_factory.mktemp("tum")
    ref = file_interface.read_tum_trajectory_file(str(write_tum(folder / "reference.tum", reference)))
    est = file_interface.read_tum_trajectory_file(str(write_tum(folder / "estimate.tum", estimate)))
    ref, est = sync.associate_trajectories(ref, est)
    assert ref.num_poses == est.num_poses == len(reference)
    return reference, estimate, ref, est


def test_the_aligned_ate_is_evo_s_ape_after_umeyama_alignment(evo_pair):
    reference, estimate, ref, est = evo_pair
    aligned = copy.deepcopy(est)
    aligned.align(ref, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, aligned))
    evo_rmse = ape.get_statistic(metrics.StatisticsType.rmse)
    ours = ate_rmse_aligned(estimate, reference)
    assert evo_rmse > 0.1
    assert ours == pytest.approx(evo_rmse, abs=TOLERANCE_M)


@pytest.mark.parametrize("delta_m", [1.0, 5.0])
def test_the_rpe_of_a_narrow_band_is_evo_s_all_pairs_rpe_at_that_distance(evo_pair, delta_m):
    reference, estimate, ref, est = evo_pair
    rel_tol = 0.2 * STEP_M / delta_m
    figures = {}
    for relation in (metrics.PoseRelation.translation_part, metrics.PoseRelation.rotation_angle_deg):
        rpe = metrics.RPE(
            relation,
            delta=delta_m,
            delta_unit=metrics.Unit.meters,
            rel_delta_tol=rel_tol,
            all_pairs=True,
            pairs_from_reference=True,
        )
        rpe.process_data((ref, est))
        figures[relation] = (rpe.get_statistic(metrics.StatisticsType.mean), rpe.error.size)
    ours = relative_pose_error(estimate, reference, delta_m * (1 - rel_tol), delta_m * (1 + rel_tol))
    translation, pairs = figures[metrics.PoseRelation.translation_part]
    rotation, _ = figures[metrics.PoseRelation.rotation_angle_deg]
    assert ours.pairs == pairs == len(reference) - round(delta_m / STEP_M)
    assert translation > 0.01 and rotation > 0.1
    assert ours.translation_m == pytest.approx(translation, abs=TOLERANCE_M)
    assert ours.rotation_deg == pytest.approx(rotation, abs=TOLERANCE_DEG)


def test_read_tum_reads_the_planar_poses_evo_writes(tmp_path):
    reference, _ = _loop_pair(n=50)
    ref = file_interface.read_tum_trajectory_file(str(write_tum(tmp_path / "ours.tum", reference)))
    file_interface.write_tum_trajectory_file(str(tmp_path / "evo.tum"), ref)
    read = read_tum(tmp_path / "evo.tum")
    np.testing.assert_allclose(read.t_s, reference.t_s, rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(read.poses[:, :2], reference.poses[:, :2], rtol=0.0, atol=TOLERANCE_M)
    heading_error = np.angle(np.exp(1j * (read.poses[:, 2] - reference.poses[:, 2])))
    np.testing.assert_allclose(heading_error, 0.0, atol=np.deg2rad(TOLERANCE_DEG))
    (tmp_path / "bad.tum").write_text("1.0 2.0 3.0\n", encoding="utf-8")
    with pytest.raises(ValueError, match="8 numbers"):
        read_tum(tmp_path / "bad.tum")
