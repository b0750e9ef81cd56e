"""colcon builds the packages, alone or together, and each package's executables run from its install.

colcon from PyPI (same venv as the ROS wheels) builds into a temporary folder. With the install's
setup.bash sourced over the venv underlay, `ament_index_python` must find every package, its
share/<pkg>/package.xml and each node executable in install/<pkg>/lib/<pkg>/ (what `ros2 run` runs).

`colcon build --packages-up-to X` then builds X and only what its package.xml declares; X's executables
are started from that install with the project's pip (editable) install hidden from Python, so an import
that package.xml does not declare fails here as it would on a robot.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from workspace import console_scripts, packages

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = sorted(packages())
# How long a node must keep running after start-up to count as started (s)
NODE_ALIVE_S = 4.0
# Executables that are command-line tools, not nodes: run with these arguments, must exit 0
TOOLS = {
    ("nuturtle_demo", "demo"): ["--help"],
    ("nuturtle_tools", "replay"): ["--help"],
    ("nuturtle_eval", "datasets"): ["--help"],
}
# Arguments a node needs beside the others: the relay on any free port, not one a running demo may hold
NODE_ARGUMENTS = {("nuturtle_tools", "foxglove_relay"): ["-p", "port:=0"]}

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

# Runs an installed executable with the project's editable install taken out of the import system, so
# only what colcon installed (PYTHONPATH from setup.bash) and the venv's third-party packages are seen.
HIDE_EDITABLE = """
import runpy, sys
editable = lambda hook: getattr(hook, "__module__", "").startswith("__editable__")
sys.meta_path[:] = [finder for finder in sys.meta_path if not editable(finder)]
sys.path_hooks[:] = [hook for hook in sys.path_hooks if not editable(hook)]
sys.path_importer_cache.clear()
script = sys.argv[1]
sys.argv = sys.argv[1:]
runpy.run_path(script, run_name="__main__")
"""


def colcon_build(work: Path, *selection: str) -> Path:
    """Build the workspace's packages (all, or ``--packages-up-to`` one) under ``work``; the install."""
    colcon = Path(sys.executable).with_name("colcon")
    if not colcon.exists():
        pytest.fail(f"colcon is not installed next to {sys.executable}: run ./dev.sh setup")
    src = work / "src"
    if not src.exists():  # colcon discovers packages under the base path: copy so nothing lands in the tree
        for pkg in PACKAGES:
            shutil.copytree(ROOT / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    name = "_".join(selection) or "all"
    command = [
        str(colcon), "build", "--base-paths", str(src), "--build-base", str(work / f"build_{name}"),
        "--install-base", str(work / f"install_{name}"), "--event-handlers", "console_direct-",
        *(["--packages-up-to", *selection] if selection else []),
    ]  # fmt: skip
    env = dict(os.environ, COLCON_LOG_PATH=str(work / "log"))
    result = subprocess.run(command, cwd=work, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return work / f"install_{name}"


def sourced(install: Path, command: str) -> list[str]:
    """``bash -c`` running ``command`` with ``install/setup.bash`` sourced over the venv underlay."""
    return ["bash", "-c", f"set +u; export AMENT_PREFIX_PATH={sys.prefix}; . {install}/setup.bash; {command}"]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("colcon")


def test_ament_index_finds_every_package_and_executable(workspace: Path) -> None:
    install = colcon_build(workspace)
    probe = f"{sys.executable} -c {shlex.quote(PROBE % (PACKAGES,))}"
    result = subprocess.run(sourced(install, probe), capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    found = json.loads(result.stdout.strip().splitlines()[-1])
    for pkg in PACKAGES:
        assert found[pkg]["package_xml"], pkg
        assert sorted(found[pkg]["executables"]) == sorted(console_scripts(packages()[pkg])), pkg
    for package, folder, name in (
        ("nuturtle_description", "config", "diff_params.yaml"),
        ("nuslam", "rviz", "slam.rviz"),
        ("nuturtle_tools", "config", "foxglove_layout.json"),
    ):
        assert name in os.listdir(install / package / "share" / package / folder), (package, name)


def start_executable(install: Path, package: str, executable: str, workdir: Path) -> subprocess.Popen:
    """Start ``executable`` of ``package`` from ``install`` (a node on sim time, a tool with its TOOLS
    arguments), its output piped."""
    path = install / package / "lib" / package / executable
    assert path.is_file(), path
    arguments = TOOLS.get((package, executable), ["--ros-args", "-p", "use_sim_time:=true"])
    arguments += NODE_ARGUMENTS.get((package, executable), [])
    command = shlex.join([sys.executable, "-c", HIDE_EDITABLE, str(path), *arguments])
    return subprocess.Popen(
        sourced(install, f"exec {command}"), cwd=workdir, text=True,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
    )  # fmt: skip


def run_executables(install: Path, package: str, executables: list[str], workdir: Path) -> None:
    """Start every executable of ``package`` from ``install`` at once: a tool must exit 0, a node must
    still be running after NODE_ALIVE_S and stop cleanly on SIGINT; none may print a traceback."""
    processes = {name: start_executable(install, package, name, workdir) for name in executables}
    try:
        outputs = {}
        for name, process in processes.items():
            if (package, name) in TOOLS:
                outputs[name], _ = process.communicate(timeout=120)
                assert process.returncode == 0, outputs[name][-3000:]
        deadline = time.monotonic() + NODE_ALIVE_S
        nodes = {name: process for name, process in processes.items() if (package, name) not in TOOLS}
        while time.monotonic() < deadline and all(process.poll() is None for process in nodes.values()):
            time.sleep(0.1)
        for name, process in nodes.items():
            assert process.poll() is None, f"{package} {name} stopped:\n{process.communicate()[0][-3000:]}"
        for process in nodes.values():
            process.send_signal(signal.SIGINT)
        for name, process in nodes.items():
            outputs[name], _ = process.communicate(timeout=30)
            assert process.returncode == 0, outputs[name][-3000:]
        for name, output in outputs.items():
            assert "Traceback" not in output, f"{package} {name}:\n{output[-3000:]}"
    finally:
        for process in processes.values():
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


@pytest.mark.parametrize("package", PACKAGES)
def test_each_package_built_alone_runs_its_executables(workspace: Path, package: str, tmp_path: Path) -> None:
    install = colcon_build(workspace, package)
    built = sorted(path.name for path in install.iterdir() if (path / "share" / path.name).is_dir())
    needed = {package}
    while True:  # package.xml's workspace dependencies, transitively
        more = {dep for name in needed for dep in packages()[name].exec_depends if dep in packages()}
        if more <= needed:
            break
        needed |= more
    assert built == sorted(needed)
    run_executables(install, package, sorted(console_scripts(packages()[package])), tmp_path)
