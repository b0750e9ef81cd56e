"""Two `python -m nuturtle_demo` at once on one machine, from one shell (the same ROS_DOMAIN_ID and discovery
range): each run lives in its own DDS world (nuturtle_ros_common.dds_domain), so both finish and each bag
holds its own simulation only: one /clock that only moves forward and one ground truth, starting from that
run's own start pose and never jumping to the other's. Before the private worlds both runs failed on
time going backwards, with both simulations in each bag (docs/demo.md)."""

import json
import subprocess
import sys
from itertools import pairwise

import pytest

from bag_reading import read_bag
from nuturtle_ros_common.conversions import stamp_nanoseconds

DURATION_S = 4.0
# (seed, true start pose x y theta) of each run
RUNS = {"a": ("1", ["0.0", "0.0", "0.0"]), "b": ("2", ["0.3", "-0.4", "1.0"])}
# the robot moves < 0.25 m/s: 12.5 mm between two ground truth messages at 20 Hz
MAX_TRUTH_STEP_M = 0.05


def demo_command(out, seed, start):
    return [
        sys.executable, "-m", "nuturtle_demo", "--duration", str(DURATION_S), "--seed", seed,
        "--start", *start, "--out", str(out), "--no-progress",
    ]  # fmt: skip


@pytest.mark.slow
@pytest.mark.ros
def test_two_demos_at_once_each_record_only_their_own_simulation(tmp_path):
    processes = {
        name: subprocess.Popen(
            demo_command(tmp_path / name, seed, start),
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for name, (seed, start) in RUNS.items()
    }
    try:
        outputs = {name: process.communicate(timeout=180)[0] for name, process in processes.items()}
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.kill()
                process.wait()
    for name, process in processes.items():
        assert process.returncode == 0, outputs[name]
    for name, (_, start) in RUNS.items():
        metrics = json.loads((tmp_path / name / "metrics.json").read_text())
        assert metrics["sim_seconds"] == pytest.approx(DURATION_S, abs=0.05)
        bag = read_bag(tmp_path / name / "run")
        clock_ns = [stamp_nanoseconds(msg.clock) for msg in bag.decoded("/clock")]
        assert all(later > earlier for earlier, later in pairwise(clock_ns)), name
        # one per physics step at 100 Hz, of one simulation (the last few may miss the recording)
        assert 0.95 * DURATION_S * 100 <= len(clock_ns) <= DURATION_S * 100, name
        truth = [msg.pose.pose.position for msg in bag.decoded("/nusim/ground_truth")]
        assert (truth[0].x, truth[0].y) == pytest.approx((float(start[0]), float(start[1])), abs=0.02), name
        steps = [abs(q.x - p.x) + abs(q.y - p.y) for p, q in pairwise(truth)]
        assert max(steps) < MAX_TRUTH_STEP_M, name
