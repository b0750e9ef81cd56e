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
        ("nuturtle_description", "config", "models.yaml"),
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


def isolated_run(
    install: Path, workspace: Path, work: Path, processes: dict[tuple[str, str], subprocess.Popen]
) -> dict[str, list[str]]:
    """Every package's checks from ``install``, all started at once (independent processes): colcon's list
    of what ``--packages-up-to`` builds, the workspace's import packages its isolated environment can import
    (as JSON lines), and each executable, started into ``processes``: a tool must exit 0, a node must still
    be running NODE_ALIVE_S after the probes ended and stop cleanly on SIGINT; none may print a traceback.
    Returns per package its two probe outputs and then the failures of its executables."""
    probe = work / "importable.py"
    probe.write_text(IMPORTABLE)
    probes = {}
    for package in PACKAGES:
        listed = subprocess.Popen(
            [str(COLCON), "list", "--base-paths", "src", "--packages-up-to", package, "--names-only"],
            cwd=workspace, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        )  # fmt: skip
        found = subprocess.Popen(
            hidden_editable(probe, *PACKAGES), cwd=work, env=isolated_environment(install, package),
            text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        )  # fmt: skip
        probes[package] = (listed, found)
        for name in sorted(console_scripts(packages()[package])):
            processes[package, name] = start_executable(install, package, name, work)
    results = {
        package: [" ".join(listed.communicate(timeout=120)[0].split()), found.communicate(timeout=120)[0]]
        for package, (listed, found) in probes.items()
    }
    outputs = {}
    for (package, name), process in processes.items():
        if (package, name) in TOOLS:
            outputs[package, name] = process.communicate(timeout=120)[0]
            if process.returncode != 0:
                results[package].append(
                    f"{name} exited {process.returncode}:\n{outputs[package, name][-3000:]}"
                )
    # the nodes started with the probes: NODE_ALIVE_S more after those, however loaded the machine
    nodes = {key: process for key, process in processes.items() if key not in TOOLS}
    time.sleep(NODE_ALIVE_S)
    running = {key: process for key, process in nodes.items() if process.poll() is None}
    for process in running.values():
        process.send_signal(signal.SIGINT)
    for (package, name), process in nodes.items():
        outputs[package, name] = process.communicate(timeout=30)[0]
        if (package, name) not in running:
            results[package].append(f"{name} stopped:\n{outputs[package, name][-3000:]}")
        elif process.returncode != 0:
            results[package].append(
                f"{name} exited {process.returncode} on SIGINT:\n{outputs[package, name][-3000:]}"
            )
    for (package, name), output in outputs.items():
        if "Traceback" in output:
            results[package].append(f"{name} printed a traceback:\n{output[-3000:]}")
    return results


@pytest.fixture(scope="module")
def isolated_runs(
    workspace: Path, install: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, list[str]]:
    """:func:`isolated_run` of every package; no process outlives it."""
    processes: dict[tuple[str, str], subprocess.Popen] = {}
    try:
        return isolated_run(install, workspace, tmp_path_factory.mktemp("isolated"), processes)
    finally:
        for process in processes.values():
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


@pytest.mark.parametrize("package", PACKAGES)
def test_each_package_runs_its_executables_with_only_its_dependencies(
    isolated_runs: dict[str, list[str]], package: str
) -> None:
    needed = sorted(dependency_closure(package))
    listed, importable, *failures = isolated_runs[package]
    # colcon's own reading of the package.xml files: what `colcon build --packages-up-to` would build
    assert sorted(listed.split()) == needed, listed
    # the isolation holds: of the workspace, exactly the closure is importable
    assert json.loads(importable.strip().splitlines()[-1]) == needed, importable[-3000:]
    assert failures == [], "\n".join(failures)
