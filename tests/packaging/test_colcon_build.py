"""colcon builds the workspace once, and each package's executables run from that install with only the
packages its package.xml declares.

colcon from PyPI (same venv as the ROS wheels) builds every package into a temporary folder, each into its
own prefix install/<pkg>/ (colcon's default isolated layout). With the install's setup.bash sourced over the
venv underlay, `ament_index_python` must find every package, its share/<pkg>/package.xml and each node
executable in install/<pkg>/lib/<pkg>/ (what `ros2 run` runs).

Each package's executables are then started from that install with only the package's own prefix and its
package.xml exec_depends in the workspace, transitively, on PYTHONPATH and AMENT_PREFIX_PATH (the venv
underlay behind them), and with the project's pip (editable) install hidden from Python, so an import or a
share file that package.xml does not declare fails here as it would on a robot.
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

from workspace import console_scripts, packages, workspace_graph

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = sorted(packages())
COLCON = Path(sys.executable).with_name("colcon")
# Where colcon installs an ament_python package's modules inside its prefix
SITE_PACKAGES = Path("lib", f"python{sys.version_info.major}.{sys.version_info.minor}", "site-packages")
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

# Runs a Python file with the project's editable install taken out of the import system, so only what
# colcon installed (PYTHONPATH) and the venv's third-party packages are seen.
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

# Run under HIDE_EDITABLE: which of the workspace's import packages Python finds
IMPORTABLE = """
import importlib.util, json, sys
print(json.dumps(sorted(name for name in sys.argv[1:] if importlib.util.find_spec(name) is not None)))
"""


def dependency_closure(package: str) -> set[str]:
    """``package`` and the workspace packages its package.xml exec_depends on, transitively."""
    graph = workspace_graph()
    needed = {package}
    while more := {dep for name in needed for dep in graph[name]} - needed:
        needed |= more
    return needed


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the packages in ``src/`` (colcon discovers packages under the base path: nothing lands in
    the tree)."""
    if not COLCON.exists():
        pytest.fail(f"colcon is not installed next to {sys.executable}: run ./dev.sh setup")
    work = tmp_path_factory.mktemp("colcon")
    for pkg in PACKAGES:
        shutil.copytree(
            ROOT / pkg, work / "src" / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info")
        )
    return work


@pytest.fixture(scope="module")
def install(workspace: Path) -> Path:
    """The install of one ``colcon build`` of every package of the workspace."""
    command = [
        str(COLCON), "build", "--base-paths", "src", "--build-base", "build", "--install-base", "install",
        "--event-handlers", "console_direct-",
    ]  # fmt: skip
    env = dict(os.environ, COLCON_LOG_PATH=str(workspace / "log"))
    result = subprocess.run(command, cwd=workspace, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return workspace / "install"


def sourced(install: Path, command: str) -> list[str]:
    """``bash -c`` running ``command`` with ``install/setup.bash`` sourced over the venv underlay."""
    return ["bash", "-c", f"set +u; export AMENT_PREFIX_PATH={sys.prefix}; . {install}/setup.bash; {command}"]


def test_ament_index_finds_every_package_and_executable(install: Path) -> None:
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


def isolated_environment(install: Path, package: str) -> dict[str, str]:
    """The environment of ``package`` alone on a robot: its prefix and its dependency closure's on
    PYTHONPATH and AMENT_PREFIX_PATH (the venv underlay last), nothing else of the install."""
    prefixes = [install / name for name in sorted(dependency_closure(package))]
    for prefix in prefixes:
        assert (prefix / SITE_PACKAGES).is_dir(), prefix / SITE_PACKAGES
    return dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(str(prefix / SITE_PACKAGES) for prefix in prefixes),
        AMENT_PREFIX_PATH=os.pathsep.join([*map(str, prefixes), sys.prefix]),
    )


def hidden_editable(script: Path, *arguments: str) -> list[str]:
    """The command running the Python file ``script`` with ``arguments`` under HIDE_EDITABLE (``-P``: the
    working folder is not on sys.path)."""
    return [sys.executable, "-P", "-c", HIDE_EDITABLE, str(script), *arguments]


def start_executable(install: Path, package: str, executable: str, workdir: Path) -> subprocess.Popen:
    """Start ``executable`` of ``package`` from ``install`` in ``package``'s isolated environment (a node on
    sim time, a tool with its TOOLS arguments), its output piped."""
    path = install / package / "lib" / package / executable
    assert path.is_file(), path
    arguments = TOOLS.get((package, executable), ["--ros-args", "-p", "use_sim_time:=true"])
    arguments += NODE_ARGUMENTS.get((package, executable), [])
    return subprocess.Popen(
        hidden_editable(path, *arguments), cwd=workdir, env=isolated_environment(install, package), text=True,
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
        while (
            nodes
            and time.monotonic() < deadline
            and all(process.poll() is None for process in nodes.values())
        ):
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
def test_each_package_runs_its_executables_with_only_its_dependencies(
    workspace: Path, install: Path, package: str, tmp_path: Path
) -> None:
    needed = dependency_closure(package)
    # colcon's own reading of the package.xml files: what `colcon build --packages-up-to` would build
    listed = subprocess.run(
        [str(COLCON), "list", "--base-paths", "src", "--packages-up-to", package, "--names-only"],
        cwd=workspace, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert listed.returncode == 0, listed.stderr[-3000:]
    assert sorted(listed.stdout.split()) == sorted(needed)
    # the isolation holds: of the workspace, exactly the closure is importable
    probe = tmp_path / "importable.py"
    probe.write_text(IMPORTABLE)
    found = subprocess.run(
        hidden_editable(probe, *PACKAGES), cwd=tmp_path, env=isolated_environment(install, package),
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert found.returncode == 0, found.stderr[-3000:]
    assert json.loads(found.stdout.strip().splitlines()[-1]) == sorted(needed)
    run_executables(install, package, sorted(console_scripts(packages()[package])), tmp_path)
