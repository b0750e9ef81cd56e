"""colcon builds all five ament_python packages, and the install is what `ros2 run` expects.

The build runs colcon from PyPI (same venv as the ROS wheels) into a temporary folder; then, with the
install's setup.bash sourced over the venv underlay, `ament_index_python` must find every package, its
share/<pkg>/package.xml, and each node executable in install/<pkg>/lib/<pkg>/.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ["turtlelib", "nusim", "nuturtle_control", "nuslam", "nuturtle_description"]
EXECUTABLES = {
    "nusim": ["nusim"],
    "nuturtle_control": ["turtle_control", "odometry", "circle"],
    "nuslam": ["landmarks", "slam", "demo"],
}

PROBE = """
import json, os
from ament_index_python.packages import get_package_share_directory, get_package_prefix
out = {}
for pkg in %r:
    share = get_package_share_directory(pkg)
    prefix = get_package_prefix(pkg)
    lib = os.path.join(prefix, "lib", pkg)
    out[pkg] = {
        "package_xml": os.path.isfile(os.path.join(share, "package.xml")),
        "executables": sorted(os.listdir(lib)) if os.path.isdir(lib) else [],
        "share": sorted(os.listdir(share)),
    }
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def colcon_install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    colcon = Path(sys.executable).with_name("colcon")
    if not colcon.exists():
        pytest.fail(f"colcon is not installed next to {sys.executable}: run ./dev.sh setup")
    work = tmp_path_factory.mktemp("colcon")
    # colcon discovers packages under the base path; copy the five folders so nothing lands in the tree.
    src = work / "src"
    for pkg in PACKAGES:
        shutil.copytree(ROOT / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    env = dict(os.environ, COLCON_LOG_PATH=str(work / "log"))
    result = subprocess.run(
        [str(colcon), "build", "--base-paths", str(src), "--build-base", str(work / "build"),
         "--install-base", str(work / "install"), "--event-handlers", "console_direct-"],
        cwd=work, env=env, capture_output=True, text=True, timeout=600,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return work / "install"


def test_colcon_builds_every_package(colcon_install: Path) -> None:
    for pkg in PACKAGES:
        assert (colcon_install / pkg / "share" / pkg / "package.xml").is_file(), pkg


def test_ament_index_finds_packages_and_executables(colcon_install: Path) -> None:
    venv = Path(sys.prefix)
    script = (
        "set +u; "
        f"export AMENT_PREFIX_PATH={venv}; "
        f". {colcon_install}/setup.bash; "
        f"{sys.executable} -c {shlex.quote(PROBE % (PACKAGES,))}"
    )
    result = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    found = json.loads(result.stdout.strip().splitlines()[-1])
    for pkg in PACKAGES:
        assert found[pkg]["package_xml"], pkg
        for executable in EXECUTABLES.get(pkg, []):
            assert executable in found[pkg]["executables"], (pkg, found[pkg]["executables"])
    assert "diff_params.yaml" in os.listdir(colcon_install / "nuturtle_description" / "share" / "nuturtle_description" / "config")
