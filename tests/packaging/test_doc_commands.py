"""The commands the docs show run as written from the repository root: a Python command is
``.venv/bin/python -P`` (``-P``: the source folders at the root, which hold each package one level down,
must not shadow the installed packages; the interpreter with the project, not whichever ``python`` is
first on PATH), ``./dev.sh`` is given one of its subcommands, and the recordings the replay commands are
given exist from the root. The commands are read, not run."""

from __future__ import annotations

import re

import pytest

from workspace import ROOT

DOCS = sorted([ROOT / "README.md", *ROOT.glob("docs/*.md"), *ROOT.glob("*/README.md")])
# an interpreter followed by its options and then a module (-m), a program (-c) or a script
PYTHON_COMMAND = re.compile(
    r"(?<![\w/.-])(?P<python>[\w./-]*python[\d.]*)(?P<options>(?:\s+-[A-Za-z]+)*)\s+(?P<what>-m\s+\S+|-c\b|\S+\.py\b)"
)
# pip and venv are not shadowed by the source folders
ANY_PYTHON = ("pip", "venv")
DEV_SH = re.compile(r"\./dev\.sh\s+(\w+)")
DEV_SH_COMMANDS = re.compile(r"^\s+(\w+)\)", re.MULTILINE)


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_python_commands_are_the_venv_interpreter_with_dash_p(path):
    text = path.read_text(encoding="utf-8")
    for match in PYTHON_COMMAND.finditer(text):
        if match["what"].split()[-1] in ANY_PYTHON:
            continue
        line = text.count("\n", 0, match.start()) + 1
        assert match["python"] == ".venv/bin/python" and "-P" in match["options"].split(), (
            f"{path.name}:{line}: {match.group()!r} is not `.venv/bin/python -P ...`"
        )


def test_dev_sh_commands_in_the_docs_exist():
    known = set(DEV_SH_COMMANDS.findall((ROOT / "dev.sh").read_text(encoding="utf-8")))
    used = {
        (path.name, command) for path in DOCS for command in DEV_SH.findall(path.read_text(encoding="utf-8"))
    }
    assert used and {command for _, command in used} <= known, sorted(used)


# the recording a replay command of the docs is given: after the module, or after `./dev.sh replay`
REPLAYED = re.compile(r"(?:-m nuturtle_tools\.replay|\./dev\.sh replay|nuturtle-replay)\s+(?P<bag>[^\s`]+)")
# the workplace's shared datasets beside the repository (docs/real_data.md), absent from a clean clone
SHARED = ROOT.parent / "shared"


def test_the_recordings_the_docs_replay_exist_from_the_root():
    """Each replayed path is a placeholder (capitals: BAG, DIR, ROBOT.mcap), a run's output (out/...),
    or a path that exists from the repository root (the shared datasets when they are there)."""
    replayed = []
    for path in DOCS:
        for match in REPLAYED.finditer(path.read_text(encoding="utf-8")):
            bag = match["bag"]
            replayed.append(bag)
            if (
                bag[0].isupper()
                or bag.startswith("out/")
                or (bag.startswith("../shared/") and not SHARED.is_dir())
            ):
                continue
            assert (ROOT / bag).exists(), (
                f"{path.name}: {match.group()!r}: {bag} does not exist from the root"
            )
    # the docs' replay examples were found (on a clone without the shared datasets beside it, those under
    # ../shared/ are not checked: the in-repo ones still are)
    assert any(not bag[0].isupper() for bag in replayed), replayed
