"""turtlelib's subpackages import one way: each only from the layers below it (docs/architecture.md)."""

import ast
from pathlib import Path

import turtlelib

PACKAGE = Path(turtlelib.__file__).parent
# subpackage -> the subpackages it may import from
ALLOWED = {
    "util": set(),
    "geometry": {"util"},
    "motion": {"geometry", "util"},
    "sensing": {"geometry", "util"},
    "mapping": {"sensing", "geometry", "util"},
    "estimation": {"motion", "sensing", "mapping", "geometry", "util"},
    "smoothing": {"estimation", "motion", "sensing", "mapping", "geometry", "util"},
}


def imported_subpackages(path: Path) -> set[str]:
    """The turtlelib subpackages a module imports (relative ``from ..x`` and absolute ``turtlelib.x``)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level == 2 and node.module:
                found.add(node.module.split(".")[0])
            elif node.level == 0 and node.module and node.module.startswith("turtlelib."):
                found.add(node.module.split(".")[1])
    return found


def test_every_module_lives_in_a_known_subpackage():
    loose = sorted(p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    assert loose == []
    assert {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()} == set(ALLOWED)


def test_subpackages_import_only_the_layers_below_them():
    for sub, allowed in ALLOWED.items():
        for path in (PACKAGE / sub).glob("*.py"):
            assert imported_subpackages(path) - {sub} <= allowed, path.relative_to(PACKAGE)
