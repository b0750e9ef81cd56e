"""ros_files: a package's share folder (ament index or source tree) and ROS parameter files."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from nuturtle_ros_common.ros_files import flatten, load_ros_parameters, load_ros_yaml, nest, share_file

ROOT = Path(__file__).resolve().parents[2]


def test_share_file_finds_a_package_s_config_in_its_source_folder():
    # the pip editable install: no ament index, the source folder next to the import package
    assert share_file("nuturtle_description", "config", "models.yaml") == (
        ROOT / "nuturtle_description" / "config" / "models.yaml"
    )
    with pytest.raises(LookupError, match="no_such_package"):
        share_file("no_such_package", "config")


def test_load_ros_yaml_reads_the_wildcard_or_first_node_entry(tmp_path):
    wildcard = tmp_path / "wildcard.yaml"
    wildcard.write_text("/**:\n  ros__parameters:\n    a: 1\n    b: [1.0, 2.0]\n")
    assert load_ros_yaml(wildcard) == {"a": 1, "b": [1.0, 2.0]}
    named = tmp_path / "named.yaml"
    named.write_text("odometry:\n  ros__parameters:\n    body_id: base\n")
    assert load_ros_yaml(named) == {"body_id": "base"}
    for text in ("", "odometry:\n  other: 1\n"):
        empty = tmp_path / "empty.yaml"
        empty.write_text(text)
        with pytest.raises(ValueError, match="no ros__parameters"):
            load_ros_yaml(empty)


names = st.text("abc", min_size=1, max_size=3)
trees = st.recursive(
    st.integers(-5, 5) | st.floats(-1, 1) | st.lists(st.floats(-1, 1), max_size=3),
    lambda children: st.dictionaries(names, children, min_size=1, max_size=3),
    max_leaves=8,
)


@given(st.dictionaries(names, trees, min_size=1, max_size=3))
def test_nest_inverts_flatten(tree):
    assert nest(flatten(tree)) == tree


def test_load_ros_parameters_gives_dotted_names(tmp_path):
    nested = tmp_path / "nested.yaml"
    nested.write_text("nusim:\n  ros__parameters:\n    rate: 5.0\n    obstacles:\n      x: [1.0]\n")
    assert load_ros_parameters(nested) == {"rate": 5.0, "obstacles.x": [1.0]}
