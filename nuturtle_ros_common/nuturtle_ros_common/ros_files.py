"""Files of ROS packages: a package's share folder, and the parameters of a ROS parameter file (nested
YAML groups are dotted parameter names: ``obstacles: {x: [...]}`` is ``obstacles.x``).

No rclpy here: these are read by launch files, command-line tools and nodes alike.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml


def share_file(package: str, *parts: str) -> Path:
    """``share/<package>/<parts...>``: from the ament index (a colcon install) when it holds the file,
    else from the package's source folder (a pip editable install, where the import package
    ``<package>/<package>/`` sits next to ``config/``, ``launch/``). The path may not exist."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:  # no ament_index_python: never installed by colcon
        pass
    else:
        try:
            candidate = Path(get_package_share_directory(package)).joinpath(*parts)
            if candidate.exists():
                return candidate
        except (PackageNotFoundError, OSError):
            pass  # not installed, or no ament index at all (AMENT_PREFIX_PATH unset: OSError)
    spec = importlib.util.find_spec(package)
    if spec is None or spec.origin is None:
        raise LookupError(f"package {package!r} is neither in the ament index nor importable")
    return Path(spec.origin).resolve().parents[1].joinpath(*parts)


def load_ros_yaml(path: Path) -> dict:
    """The ``ros__parameters`` of a ROS parameter file (wildcard ``/**`` or the first node entry)."""
    with open(path, encoding="utf-8") as stream:
        document = yaml.safe_load(stream) or {}
    for entry in document.values():
        if isinstance(entry, dict) and "ros__parameters" in entry:
            return dict(entry["ros__parameters"])
    raise ValueError(f"{path} holds no ros__parameters")


def load_ros_parameters(path: Path) -> dict[str, Any]:
    """The parameters of a ROS parameter file by their dotted names (:func:`load_ros_yaml`, flattened)."""
    return flatten(load_ros_yaml(path))


def flatten(nested: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{'obstacles': {'x': [...]}}`` -> ``{'obstacles.x': [...]}`` (ROS parameter names)."""
    flat: dict[str, Any] = {}
    for key, value in nested.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten(value, prefix=f"{name}."))
        else:
            flat[name] = value
    return flat


def nest(flat: Mapping[str, Any]) -> dict[str, Any]:
    """The inverse of :func:`flatten`: dotted names become nested mappings."""
    nested: dict[str, Any] = {}
    for name, value in sorted(flat.items()):
        *groups, leaf = name.split(".")
        level = nested
        for group in groups:
            level = level.setdefault(group, {})
        level[leaf] = value
    return nested
