"""The workspace as colcon and rosdep see it: each package's package.xml, its Python imports (ast, no
import executed), what its launch files refer to, and its console scripts. Shared by the packaging tests.

Run as a script to print the package graph for docs/architecture.md:
``python tests/packaging/workspace.py``.
"""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# rosdep keys of the third-party Python modules the packages import (a module missing here fails the
# dependency test: add its key), and the pip distribution each key installs in pyproject.toml; a module
# without a rosdep key is in PIP_ONLY with its distribution, installed by the README's pip step
THIRD_PARTY = {
    "numpy": ("python3-numpy", "numpy"),
    "scipy": ("python3-scipy", "scipy"),
    "yaml": ("python3-yaml", "pyyaml"),
    "matplotlib": ("python3-matplotlib", "matplotlib"),
    "tqdm": ("python3-tqdm", "tqdm"),
    "rosbags": ("python3-rosbags-pip", "rosbags"),
}
PIP_ONLY = {"mcap": "mcap", "foxglove": "foxglove-sdk"}
# Python modules that are ROS packages of the same name (rclpy, message packages, launch)
ROS_MODULE_SUFFIXES = ("_msgs", "_srvs", "_interfaces")
ROS_MODULES = {"rclpy", "ament_index_python", "launch", "launch_ros"}
STDLIB = set(sys.stdlib_module_names) | {"__future__"}


@dataclass(frozen=True)
class Package:
    name: str
    folder: Path
    exec_depends: frozenset[str]

    def python_files(self) -> list[Path]:
        """The import package's modules and the launch files (setup.py is colcon's, not the package's)."""
        return sorted((self.folder / self.name).rglob("*.py")) + sorted(self.folder.glob("launch/*.py"))

    def launch_files(self) -> list[Path]:
        return sorted(self.folder.glob("launch/*.py"))


@cache
def packages() -> dict[str, Package]:
    """Every folder at the root with a package.xml, by package name."""
    found = {}
    for xml in sorted(ROOT.glob("*/package.xml")):
        root = ET.parse(xml).getroot()
        name = root.findtext("name")
        depends = frozenset(element.text.strip() for element in root.iter("exec_depend"))
        found[name] = Package(name, xml.parent, depends)
    return found


def imported_modules(path: Path) -> set[str]:
    """Top-level names of every absolute import in ``path``, at any depth (lazy imports inside functions
    and ``try`` blocks included)."""
    modules = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            modules.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            modules.add(node.module.split(".")[0])
    return modules


def dependency_key(module: str) -> str | None:
    """The package.xml key a module needs: a workspace or ROS package's own name, a third-party
    module's rosdep key; None for the standard library and a PIP_ONLY module; KeyError for a module
    nobody has mapped."""
    if module in STDLIB or module in PIP_ONLY:
        return None
    if module in packages() or module in ROS_MODULES or module.endswith(ROS_MODULE_SUFFIXES):
        return module
    return THIRD_PARTY[module][0]


@dataclass(frozen=True)
class LaunchReferences:
    """What a launch file names: ``(package, *parts)`` share files and ``(package, executable)`` nodes."""

    shared: frozenset[tuple[str, ...]]
    nodes: frozenset[tuple[str, str]]


def launch_references(path: Path) -> LaunchReferences:
    calls = [
        node for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))) if isinstance(node, ast.Call)
    ]
    shared = set()
    nodes = set()
    for call in calls:
        name = getattr(call.func, "id", None)
        if name in ("_share", "share_file") and all(isinstance(arg, ast.Constant) for arg in call.args):
            shared.add(tuple(arg.value for arg in call.args))
        if name == "Node":
            keywords = {kw.arg: kw.value for kw in call.keywords}
            package, executable = keywords.get("package"), keywords.get("executable")
            if isinstance(package, ast.Constant) and isinstance(executable, ast.Constant):
                nodes.add((package.value, executable.value))
    return LaunchReferences(frozenset(shared), frozenset(nodes))


def console_scripts(package: Package) -> dict[str, str]:
    """``{executable: "module:function"}`` from the package's setup.py (what ``ros2 run`` finds)."""
    scripts = {}
    for node in ast.walk(ast.parse((package.folder / "setup.py").read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and " = " in node.value:
            executable, _, target = node.value.partition(" = ")
            if ":" in target and executable.strip().isidentifier():
                scripts[executable.strip()] = target.strip()
    return scripts


def used_dependencies(package: Package) -> set[str]:
    """Every package.xml key the package's Python files and launch files need."""
    used = set()
    for path in package.python_files():
        used.update(key for module in imported_modules(path) if (key := dependency_key(module)))
    for path in package.launch_files():
        references = launch_references(path)
        used.update(shared[0] for shared in references.shared)
        used.update(node_package for node_package, _ in references.nodes)
    used.discard(package.name)
    return used


def workspace_graph() -> dict[str, list[str]]:
    """Each package's exec_depends on other workspace packages, in a fixed order."""
    names = packages()
    return {name: sorted(names[name].exec_depends & names.keys()) for name in names}


def mermaid_graph() -> str:
    """The package graph as a mermaid flowchart (an arrow: "depends on"), for docs/architecture.md."""
    lines = ["```mermaid", "flowchart BT"]
    for name, depends in workspace_graph().items():
        lines.extend(f"    {name} --> {depend}" for depend in depends)
    lines.append("```")
    return "\n".join(lines)


if __name__ == "__main__":
    print(mermaid_graph())
