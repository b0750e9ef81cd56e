"""Maps and localization in the demo, in process (run_demo): a mapping run saves its map through slam's
~/save_map; a localization run from another true start, given to slam through initialpose, keeps that map
bit for bit and adds no landmark; a second mapping session, started where the first one's route stopped,
continues its map (its landmarks kept, new ones added, none twice) within the demo's targets; slam fed by
odom instead of joint_states meets the accuracy targets. Short runs (docs/maps.md has the two-minute
figures, two sessions against one run of the same route included (bench/continued_mapping.py); how odom
compares with joint_states over five seeds is bench/motion_sources.py's)."""

import json

import numpy as np
import pytest

from nuturtle_demo.run import DemoOptions, run_demo, seen_walls, world_outline
from nuturtle_eval.grid_score import FALSE_OCCUPIED_TARGET, WALLS_FOUND_TARGET, score_grid
from nuturtle_eval.run_evaluation import REFERENCE_TUM, RunScope, failed_targets
from nuturtle_eval.tum import read_tum
from turtlelib.mapping.grid_map_file import load_grid_map
from turtlelib.mapping.landmark_map import load_map

MAP_S = 20.0
LOCALIZE_S = 10.0
CONTINUE_S = 10.0
ODOM_S = 10.0
# 0.5 m and 0.5 rad off the map origin; with 0.6 m loops the figure eight from there keeps clear of the
# cylinders and the walls (docs/maps.md)
OTHER_START = (0.4, 0.3, 0.5)
ROUTE_RADIUS_M = 0.6


def same_map(a, b) -> bool:
    return (
        np.array_equal(a.ids, b.ids)
        and np.array_equal(a.xy, b.xy)
        and np.array_equal(a.covariance, b.covariance)
    )


@pytest.fixture(scope="module")
def mapped(tmp_path_factory):
    """The first session: MAP_S s of mapping saved to map.json (+ map.yaml, map.pgm); (map file, result,
    system)."""
    folder = tmp_path_factory.mktemp("maps")
    map_file = folder / "map.json"
    held = {}
    result = run_demo(
        DemoOptions(
            duration_s=MAP_S, out_dir=folder / "map", map_file=map_file, save_map=True, progress=False
        ),
        lambda system, _: held.setdefault("system", system),
    )
    return map_file, result, held["system"]


@pytest.mark.ros
def test_mapping_saves_a_map_that_localization_keeps_bit_for_bit(mapped, tmp_path):
    map_file, mapping, _ = mapped
    assert mapping.saved_map is not None and mapping.saved_map[0], mapping.saved_map
    saved = load_map(map_file)
    assert saved.frame_id == "map"
    assert len(saved.ids) == mapping.metrics.landmarks_mapped >= 3
    assert mapping.metrics.landmarks_spurious == 0
    # the demo world's slip: every target applies
    assert mapping.scope == RunScope(mode="mapping", grid_loaded=False, slip_fraction=0.3)
    # the grid beside the landmarks, as the run's own map.yaml (both re-rendered from the same keyframes)
    grid = load_grid_map(map_file.with_suffix(".yaml"))
    assert np.array_equal(grid.occupancy, load_grid_map(mapping.out_dir / "map.yaml").occupancy)

    # localize with a copy, saved again at the end: the fixed map must come back unchanged
    relocalized_file = tmp_path / "localize" / "map.json"
    relocalized_file.parent.mkdir()
    relocalized_file.write_bytes(map_file.read_bytes())
    first = {}

    def on_progress(system, sim_time_s):
        if not first:
            first["pose"] = system.slam.slam.pose
            first["map"] = system.slam.slam.landmark_map("map", 0)

    options = DemoOptions(
        duration_s=LOCALIZE_S, out_dir=tmp_path / "localize", map_file=relocalized_file, mode="localization",
        save_map=True, start=OTHER_START, route_radius=ROUTE_RADIUS_M, progress=False,
    )  # fmt: skip
    localized = run_demo(options, on_progress)
    # slam started at the map origin and took the true start from initialpose before the robot moved
    assert (first["pose"].x, first["pose"].y, first["pose"].theta) == pytest.approx(OTHER_START, abs=1e-9)
    assert same_map(first["map"], saved)
    assert localized.saved_map is not None and localized.saved_map[0], localized.saved_map
    assert same_map(load_map(relocalized_file), saved)
    # no grid file beside the copy: slam mapped the scans, so the grid's targets apply
    assert localized.scope == RunScope(mode="localization", grid_loaded=False, slip_fraction=0.3)
    metrics = json.loads((tmp_path / "localize" / "metrics.json").read_text())
    assert metrics["landmarks_mapped"] == len(saved.ids)
    assert metrics["final_position_error_slam_m"] <= 0.03
    assert metrics["nees_pose_within_95_fraction"] >= 0.8


@pytest.mark.ros
def test_a_second_session_continues_the_map_where_the_route_stopped(mapped, tmp_path):
    """Session 2 starts on the route where session 1 stopped and maps on from its saved map: session 1's
    landmarks keep their ids (moved by less than a post's radius), the new ones take new ids, no post is
    mapped twice, the run meets the demo's targets, and the continued grid finds the walls both sessions
    saw."""
    map_file, first, first_system = mapped
    saved = load_map(map_file)
    continued_file = tmp_path / "map.json"
    for suffix in (".json", ".yaml", ".pgm"):
        continued_file.with_suffix(suffix).write_bytes(map_file.with_suffix(suffix).read_bytes())
    held = {}
    options = DemoOptions(
        duration_s=CONTINUE_S, out_dir=tmp_path / "continued", map_file=continued_file, save_map=True,
        route_start_s=first.route_time_s, progress=False,
    )  # fmt: skip
    second = run_demo(options, lambda system, _: held.setdefault("system", system))
    assert second.saved_map is not None and second.saved_map[0], second.saved_map
    assert "over the continued one" in second.saved_map[1]
    # the robot started where the route was when session 1 stopped
    T_start = held["system"].nusim.simulation.config.arena.T_world_start
    T_stop = read_tum(first.out_dir / REFERENCE_TUM).poses[-1]
    assert np.hypot(T_start.x - T_stop[0], T_start.y - T_stop[1]) <= 0.03
    final = load_map(continued_file)
    index = {int(i): k for k, i in enumerate(final.ids)}
    assert set(index) >= set(saved.ids.tolist())
    for i, xy in zip(saved.ids.tolist(), saved.xy, strict=True):
        assert np.linalg.norm(final.xy[index[i]] - xy) <= 0.02
    metrics = second.metrics
    assert len(final.ids) == len(index) == metrics.landmarks_mapped > len(saved.ids)
    assert metrics.landmarks_duplicate == metrics.landmarks_spurious == 0
    assert failed_targets(metrics, second.grid_score.rows(second.scope), second.scope) == []
    seen = np.vstack(
        [
            seen_walls(system, read_tum(run.out_dir / REFERENCE_TUM))
            for run, system in ((first, first_system), (second, held["system"]))
        ]
    )
    score = score_grid(
        load_grid_map(continued_file.with_suffix(".yaml")), world_outline(held["system"]), seen
    )
    assert score.walls_found >= WALLS_FOUND_TARGET and score.false_occupied <= FALSE_OCCUPIED_TARGET


def test_localization_and_save_map_need_a_map_file(tmp_path):
    with pytest.raises(ValueError, match="save_map needs a map_file"):
        DemoOptions(save_map=True)
    with pytest.raises(ValueError, match="localization needs an existing map_file"):
        DemoOptions(mode="localization", map_file=tmp_path / "none.json")
    with pytest.raises(ValueError, match=r"start must be 3 numbers"):
        DemoOptions(start=(0.0, 0.0))
    with pytest.raises(ValueError, match="give it or start, not both"):
        DemoOptions(route_start_s=5.0, start=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="route_start_s"):
        DemoOptions(route_start_s=-1.0)
    with pytest.raises(ValueError, match=r"motion_source must be one of"):
        DemoOptions(motion_source="imu")


@pytest.mark.ros
def test_slam_from_odom_meets_the_accuracy_targets(tmp_path):
    """The odometry node's poses as slam's motion (motion_source odom, its twist noise matched to the
    wheel slip): accurate, and its covariance consistent with its error."""
    metrics = run_demo(
        DemoOptions(duration_s=ODOM_S, out_dir=tmp_path, motion_source="odom", progress=False)
    ).metrics
    assert metrics.final_position_error_slam_m <= 0.02 and metrics.landmark_rmse_m <= 0.02
    assert metrics.landmarks_mapped >= 3 and metrics.landmarks_spurious == 0
    assert metrics.nees_pose_within_95_fraction >= 0.8
