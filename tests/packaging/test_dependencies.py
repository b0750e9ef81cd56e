"""Package boundaries: every import and launch reference declared in package.xml, no stale workspace
dependency, no cycle, turtlelib and nuturtle_eval free of ROS, launch files that name real files and
executables, console scripts that resolve, and the package picture in docs/architecture.md equal to the
package.xml files."""

from __future__ import annotations

import importlib
import tomllib
from graphlib import CycleError, TopologicalSorter

import pytest

from workspace import (
    ROOT,
    THIRD_PARTY,
    console_scripts,
    imported_modules,
    launch_references,
    mermaid_graph,
    packages,
    used_dependencies,
    workspace_graph,
)

PACKAGES = sorted(packages())


def test_the_workspace_has_the_nine_packages():
    assert PACKAGES == sorted(
        [
            "turtlelib",
            "nuturtle_eval",
            "nuturtle_ros_common",
            "nuturtle_description",
            "nusim",
            "nuturtle_control",
            "nuslam",
            "nuturtle_tools",
            "nuturtle_demo",
        ]
    )


@pytest.mark.parametrize("name", PACKAGES)
def test_every_import_and_launch_reference_is_declared(name):
    package = packages()[name]
    missing = used_dependencies(package) - package.exec_depends
    assert not missing, f"{name}/package.xml lacks <exec_depend> for {sorted(missing)}"


@pytest.mark.parametrize("name", PACKAGES)
def test_no_workspace_dependency_is_declared_without_use(name):
    package = packages()[name]
    declared = package.exec_depends & packages().keys()
    stale = declared - used_dependencies(package)
    assert not stale, f"{name} declares workspace packages it never uses: {sorted(stale)}"


def test_the_package_graph_has_no_cycle():
    try:
        order = list(TopologicalSorter(workspace_graph()).static_order())
    except CycleError as error:
        pytest.fail(f"package dependency cycle: {error.args[1]}")
    assert order[0] == "turtlelib"


def test_turtlelib_imports_numpy_scipy_and_the_standard_library_only():
    package = packages()["turtlelib"]
    keys = used_dependencies(package)
    assert keys <= {"python3-numpy", "python3-scipy"}, keys
    assert package.exec_depends == {"python3-numpy", "python3-scipy"}


def test_nuturtle_eval_declares_exactly_what_it_imports_and_no_ros_package():
    package = packages()["nuturtle_eval"]
    keys = used_dependencies(package)
    assert keys == package.exec_depends
    assert keys <= {
        "turtlelib",
        "python3-numpy",
        "python3-scipy",
        "python3-yaml",
        "python3-matplotlib",
        "python3-tqdm",
    }


def test_the_evaluation_depends_on_turtlelib_only_and_nothing_but_the_demo_and_the_tools_on_it():
    graph = workspace_graph()
    assert graph["nuturtle_eval"] == ["turtlelib"]
    users = {name for name, depends in graph.items() if "nuturtle_eval" in depends}
    assert users <= {"nuturtle_tools", "nuturtle_demo"}, users


def test_the_simulator_and_the_robot_side_do_not_depend_on_each_other():
    graph = workspace_graph()
    assert set(graph["nusim"]) <= {"turtlelib", "nuturtle_ros_common", "nuturtle_description"}
    for robot_side in ("nuturtle_control", "nuslam", "nuturtle_tools"):
        assert "nusim" not in graph[robot_side] and "nuturtle_demo" not in graph[robot_side]
    assert set(graph["nuturtle_description"]) <= {"turtlelib", "nuturtle_ros_common"}


def test_every_third_party_python_dependency_is_installed_by_pyproject():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    requirements = list(project["dependencies"])
    for extra in project["optional-dependencies"].values():
        requirements.extend(extra)
    distributions = {
        requirement.split(">")[0].split("=")[0].split("<")[0].strip().lower() for requirement in requirements
    }
    declared = set().union(*(package.exec_depends for package in packages().values()))
    for key, distribution in THIRD_PARTY.values():
        if key in declared:
            assert distribution in distributions, (
                f"{key} is declared but pyproject.toml never installs {distribution}"
            )


@pytest.mark.parametrize("name", PACKAGES)
def test_launch_files_name_existing_files_and_executables(name):
    for path in packages()[name].launch_files():
        references = launch_references(path)
        included = [parts for parts in references.shared if parts[1] == "launch"]
        assert references.nodes or included, f"{path.name} starts no node and includes no launch file"
        for package, *parts in references.shared:
            assert ROOT.joinpath(package, *parts).is_file(), (path.name, package, parts)
        for package, executable in references.nodes:
            if package in packages():
                assert executable in console_scripts(packages()[package]), (path.name, package, executable)


@pytest.mark.parametrize("name", PACKAGES)
def test_console_scripts_resolve_to_functions_of_their_own_package(name):
    for executable, target in console_scripts(packages()[name]).items():
        module_name, _, function = target.partition(":")
        assert module_name.split(".")[0] == name, (executable, target)
        assert callable(getattr(importlib.import_module(module_name), function)), (executable, target)


def test_imported_modules_sees_lazy_imports(tmp_path):
    source = tmp_path / "example.py"
    source.write_text(
        "import os.path\nfrom . import sibling\n\ndef f():\n    try:\n        import yaml\n"
        "    except ImportError:\n        from numpy import linalg\n"
    )
    assert imported_modules(source) == {"os", "yaml", "numpy"}


def test_architecture_doc_shows_the_package_graph():
    text = (ROOT / "docs" / "architecture.md").read_text()
    assert mermaid_graph() in text, (
        "docs/architecture.md is out of date: paste the output of `python tests/packaging/workspace.py`"
    )
