"""nuturtle_eval runs where ROS is not installed: in a Python whose ROS modules (rclpy, ament_index_python,
launch, every ``*_msgs`` / ``*_srvs`` / ``*_interfaces``, rosbags, foxglove) and the workspace's ROS packages
cannot be imported, every module of nuturtle_eval imports and ``python -m nuturtle_eval.datasets`` runs EKF
SLAM on the MRCLAM excerpt, figures included (matplotlib, tqdm and yaml are imported lazily, so only a run
reaches them)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from workspace import ROOT, ROS_MODULE_SUFFIXES, ROS_MODULES, packages

MRCLAM_EXCERPT = ROOT / "tests" / "nuturtle_eval" / "datasets" / "data" / "mrclam7_robot1_60s"
# every workspace package but turtlelib and nuturtle_eval needs ROS
BLOCKED = sorted(ROS_MODULES | {"rosbags", "foxglove"} | (packages().keys() - {"turtlelib", "nuturtle_eval"}))

# Refuses the blocked modules, imports every module of nuturtle_eval, then runs ``argv`` as
# ``python -m nuturtle_eval.datasets``; prints the names of the modules it imported.
WITHOUT_ROS = """
import importlib, importlib.abc, pkgutil, runpy, sys
blocked, suffixes, argv = set(sys.argv[1].split(",")), tuple(sys.argv[2].split(",")), sys.argv[3:]

class NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        top = name.split(".")[0]
        if top in blocked or top.endswith(suffixes):
            raise ModuleNotFoundError(f"{name} is blocked: nuturtle_eval must not need it", name=name)
        return None

sys.meta_path.insert(0, NoRos())
import nuturtle_eval
names = [info.name for info in pkgutil.walk_packages(nuturtle_eval.__path__, "nuturtle_eval.")]
for name in names:
    importlib.import_module(name)
print(",".join(names))
sys.argv = ["nuturtle_eval.datasets", *argv]
try:
    runpy.run_module("nuturtle_eval.datasets", run_name="__main__", alter_sys=True)
except SystemExit as exit:
    sys.exit(exit.code)
"""


def run_without_ros(*argv: str) -> subprocess.CompletedProcess:
    command = [
        sys.executable, "-P", "-c", WITHOUT_ROS, ",".join(BLOCKED), ",".join(ROS_MODULE_SUFFIXES), *argv,
    ]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, timeout=300)


def test_the_blocker_refuses_rclpy():
    result = subprocess.run(
        [sys.executable, "-P", "-c", WITHOUT_ROS.replace("import nuturtle_eval\n", "import rclpy\n"),
         ",".join(BLOCKED), ",".join(ROS_MODULE_SUFFIXES)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert result.returncode != 0 and "rclpy is blocked" in result.stderr, result.stderr[-2000:]


def test_nuturtle_eval_imports_and_runs_a_dataset_without_ros(tmp_path: Path):
    out = tmp_path / "mrclam"
    result = run_without_ros(
        "mrclam", "--data", str(MRCLAM_EXCERPT), "--robot", "1", "--out", str(out), "--no-progress"
    )
    assert result.returncode == 0, result.stderr[-3000:]
    imported = result.stdout.splitlines()[0].split(",")
    assert {"nuturtle_eval.metrics", "nuturtle_eval.plots", "nuturtle_eval.datasets.calibration"} <= set(
        imported
    )
    assert json.loads((out / "metrics.json").read_text())["run"]
    assert {"trajectory.png", "errors.png", "nees.png"} <= {path.name for path in out.iterdir()}
