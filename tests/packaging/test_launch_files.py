"""The launch files as ``ros2 launch --show-args`` and a user see them, read with ``ast`` (launch is not
installable here): every argument described; an argument passed to an included file is forwarded under
its own name or declared by the including file itself (so ``--show-args``, which lists each name once,
first declaration first, never offers an included argument that is then overridden); at most one RViz
starts whatever the arguments."""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import pytest

from nuslam import launch_nodes as nuslam_launch_nodes
from workspace import ROOT, packages

LAUNCH_FILES = sorted(path for package in packages().values() for path in package.launch_files())
SHARE_CALLS = ("_share", "share_file")


@cache
def parsed(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), str(path))


def calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) == name
    ]


def keyword(call: ast.Call, name: str) -> ast.expr | None:
    return next((kw.value for kw in call.keywords if kw.arg == name), None)


def configuration_name(value: ast.expr | None) -> str | None:
    """``X`` of ``LaunchConfiguration("X")``, else None."""
    if isinstance(value, ast.Call) and getattr(value.func, "id", None) == "LaunchConfiguration":
        (argument,) = value.args
        return argument.value if isinstance(argument, ast.Constant) else None
    return None


# What declares a launch argument: launch's own action and nuturtle_description.launch_arguments' helpers
DECLARING = ("DeclareLaunchArgument", "declare_argument", "switch_argument")
LAUNCH_ARGUMENTS_MODULE = ROOT / "nuturtle_description/nuturtle_description/launch_arguments.py"


def declared(path: Path) -> set[str]:
    """The argument names ``path`` declares by name (model_argument(): ``model``)."""
    arguments = (call.args[0] for name in DECLARING for call in calls(parsed(path), name) if call.args)
    names = {argument.value for argument in arguments if isinstance(argument, ast.Constant)}
    return names | ({"model"} if calls(parsed(path), "model_argument") else set())


def includes(path: Path) -> list[tuple[Path, dict[str, ast.expr]]]:
    """Each included launch file and its ``launch_arguments`` ({...}.items())."""
    found = []
    for call in calls(parsed(path), "IncludeLaunchDescription"):
        (shared,) = [
            c for c in ast.walk(call.args[0]) if getattr(getattr(c, "func", None), "id", "") in SHARE_CALLS
        ]
        package, *parts = (argument.value for argument in shared.args)
        arguments = keyword(call, "launch_arguments")
        dictionary = arguments.func.value if arguments is not None else ast.Dict(keys=[], values=[])
        found.append(
            (
                ROOT.joinpath(package, *parts),
                {k.value: v for k, v in zip(dictionary.keys, dictionary.values, strict=True)},
            )
        )
    return found


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_every_launch_argument_is_described(path):
    # declare_argument's records (LaunchArgument) refuse an empty description when they are built
    for source in [path, LAUNCH_ARGUMENTS_MODULE]:
        for call in calls(parsed(source), "DeclareLaunchArgument"):
            description = keyword(call, "description")
            name = ast.unparse(call.args[0]) if call.args else "?"
            assert description is not None, f"{source.name}: {name} has no description"
            if isinstance(description, ast.Constant):
                assert description.value.strip(), f"{source.name}: {name} has an empty description"
    for call in calls(parsed(path), "switch_argument"):
        name, _, description = call.args
        if isinstance(description, ast.Name):
            # a text of the package's launch_nodes module, which the launch file imports
            description = ast.Constant(getattr(nuslam_launch_nodes, description.id, None))
        assert isinstance(description.value, str) and description.value.strip(), (
            f"{path.name}: {ast.unparse(name)} has no description"
        )


@pytest.mark.parametrize("path", [p for p in LAUNCH_FILES if includes(p)], ids=lambda p: p.name)
def test_an_included_argument_is_forwarded_or_shadowed_by_the_including_file(path):
    own = declared(path)
    for included, arguments in includes(path):
        assert included.is_file(), included
        for name, value in arguments.items():
            assert name in declared(included), (
                f"{path.name} passes {name}, which {included.name} never declares"
            )
            assert configuration_name(value) == name or name in own, (
                f"{path.name} sets {included.name}'s {name} to {ast.unparse(value)}: --show-args offers it, "
                "and the value given is ignored"
            )


def rviz_count(path: Path, bound: dict[str, str]) -> int:
    """RViz nodes ``path`` can start when its launch configurations ``bound`` have those constants."""
    count = 0
    for node in calls(parsed(path), "Node"):
        executable = keyword(node, "executable")
        if isinstance(executable, ast.Constant) and executable.value == "rviz2":
            condition = keyword(node, "condition")
            switch = configuration_name(condition.args[0]) if isinstance(condition, ast.Call) else None
            count += bound.get(switch) != "false"
    for included, arguments in includes(path):
        child = {}
        for name, value in arguments.items():
            if isinstance(value, ast.Constant):
                child[name] = value.value
            elif (forwarded := configuration_name(value)) in bound:
                child[name] = bound[forwarded]
        count += rviz_count(included, child)
    return count


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_at_most_one_rviz_starts(path):
    assert rviz_count(path, {}) <= 1


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_use_sim_time_reaches_every_node_of_a_file_that_declares_it(path):
    starts_slam = any(
        isinstance(keyword(node, "executable"), ast.Constant) and keyword(node, "executable").value == "slam"
        for node in calls(parsed(path), "Node")
    )
    if starts_slam:
        assert "use_sim_time" in declared(path), f"{path.name} starts slam without a use_sim_time argument"
    if "use_sim_time" in declared(path):
        for node in calls(parsed(path), "Node"):
            parameters = keyword(node, "parameters")
            assert parameters is not None and "use_sim_time" in ast.unparse(parameters), (
                f"{path.name}: {ast.unparse(keyword(node, 'executable'))} does not get use_sim_time"
            )
