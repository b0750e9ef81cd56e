"""Loop closure's pose graph file (turtlelib.smoothing.graph_file): round trips, the archive's arrays as
the format defines them (read with numpy's own reader), and refused files."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from turtlelib.smoothing.graph_file import GRAPH_FORMAT_VERSION, SavedGraph, load_graph, save_graph

finite = st.floats(-1e6, 1e6, allow_nan=False)


@st.composite
def saved_graphs(draw) -> SavedGraph:
    """Graphs of 0-6 keyframes with 0-8 points each and 0-8 edges between distinct keyframes."""
    K = draw(st.integers(0, 6))
    counts = draw(st.lists(st.integers(0, 8), min_size=K, max_size=K))
    E = draw(st.integers(0, 8)) if K >= 2 else 0
    keyframe = st.integers(0, max(K - 1, 0))
    pairs = draw(
        st.lists(st.tuples(keyframe, keyframe).filter(lambda p: p[0] != p[1]), min_size=E, max_size=E)
    )
    # covariances L L^T + eps I: positive definite
    L = draw(hnp.arrays(np.float64, (E, 3, 3), elements=st.floats(-1.0, 1.0)))
    return SavedGraph(
        t_ns=draw(hnp.arrays(np.int64, (K,), elements=st.integers(-(2**62), 2**62))),
        T_map_keyframe=draw(hnp.arrays(np.float64, (K, 3), elements=finite)),
        points=tuple(draw(hnp.arrays(np.float64, (n, 2), elements=finite)) for n in counts),
        path_m=draw(hnp.arrays(np.float64, (K,), elements=st.floats(0.0, 1e6))),
        edge_i=np.array([i for i, _ in pairs], dtype=np.int64),
        edge_j=np.array([j for _, j in pairs], dtype=np.int64),
        edge_Z=draw(hnp.arrays(np.float64, (E, 3), elements=finite)),
        edge_S=L @ np.swapaxes(L, 1, 2) + 1e-3 * np.eye(3),
        edge_loop=draw(hnp.arrays(np.bool_, (E,))),
    )


@settings(max_examples=60, deadline=None)
@given(saved_graphs())
def test_a_saved_graph_loads_back_bit_for_bit(tmp_path_factory, graph):
    path = tmp_path_factory.mktemp("graph") / "map.graph.npz"
    save_graph(path, graph)
    assert load_graph(path).equals(graph)
    # the archive as the format defines it: exactly its arrays, points in keyframe order
    with np.load(path, allow_pickle=False) as archive:
        assert sorted(archive.files) == sorted(
            ["version", "t_ns", "T_map_keyframe", "point_counts", "points", "path_m"]
            + ["edge_i", "edge_j", "edge_Z", "edge_S", "edge_loop"]
        )
        assert int(archive["version"]) == GRAPH_FORMAT_VERSION
        assert archive["t_ns"].dtype == np.int64 and archive["edge_loop"].dtype == np.bool_
        np.testing.assert_array_equal(archive["point_counts"], [len(p) for p in graph.points])
        np.testing.assert_array_equal(
            archive["points"].reshape(-1, 2), np.concatenate((np.zeros((0, 2)),) + graph.points)
        )


def two_keyframes(**changes) -> dict[str, np.ndarray]:
    """The arrays of a valid file of two keyframes and one edge, with ``changes``."""
    arrays = {
        "version": np.int64(GRAPH_FORMAT_VERSION),
        "t_ns": np.array([10, 20], dtype=np.int64),
        "T_map_keyframe": np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.1]]),
        "point_counts": np.array([2, 1], dtype=np.int64),
        "points": np.array([[1.0, 0.0], [0.0, 1.0], [2.0, 2.0]]),
        "path_m": np.array([0.0, 1.0]),
        "edge_i": np.array([0], dtype=np.int64),
        "edge_j": np.array([1], dtype=np.int64),
        "edge_Z": np.array([[1.0, 0.0, 0.1]]),
        "edge_S": np.array([np.diag([0.01, 0.01, 0.001])]),
        "edge_loop": np.array([False]),
    }
    arrays.update(changes)
    return {name: value for name, value in arrays.items() if value is not None}


def test_the_hand_made_file_loads_with_its_points_split_by_keyframe(tmp_path):
    path = tmp_path / "g.npz"
    np.savez(path, **two_keyframes())
    graph = load_graph(path)
    assert (graph.n_keyframes, graph.n_edges) == (2, 1)
    np.testing.assert_array_equal(graph.points[0], [[1.0, 0.0], [0.0, 1.0]])
    np.testing.assert_array_equal(graph.points[1], [[2.0, 2.0]])


@pytest.mark.parametrize(
    ("changes", "reason"),
    [
        ({"version": None}, "no version"),
        ({"version": np.int64(2)}, "version 2 is not supported"),
        ({"path_m": None}, r"missing: \['path_m'\]"),
        ({"extra": np.zeros(2)}, r"unknown: \['extra'\]"),
        ({"t_ns": np.array([10.0, 20.0])}, "t_ns must hold integers"),
        ({"point_counts": np.array([2, 2])}, "points must be"),
        (
            {"T_map_keyframe": np.array([[0.0, 0.0, np.nan], [1.0, 0.0, 0.1]])},
            "T_map_keyframe must be finite",
        ),
        ({"path_m": np.array([0.0, -1.0])}, "path_m must be >= 0"),
        ({"edge_j": np.array([2])}, "must name keyframes 0..1"),
        ({"edge_j": np.array([0])}, "two distinct keyframes"),
        ({"edge_S": np.zeros((1, 3, 3))}, "edge_S"),
        ({"edge_loop": np.array([1])}, "edge_loop must be"),
        ({"points": np.array(["a", "b", "c"], dtype=object)}, "not a pose graph archive"),
    ],
)
def test_a_malformed_file_is_refused_naming_it_and_the_problem(tmp_path, changes, reason):
    path = tmp_path / "g.npz"
    np.savez(path, **two_keyframes(**changes))
    with pytest.raises(ValueError, match=reason) as error:
        load_graph(path)
    assert str(error.value).startswith(str(path))


def test_a_missing_or_truncated_file_is_refused(tmp_path):
    with pytest.raises(ValueError, match="no such file"):
        load_graph(tmp_path / "none.npz")
    path = tmp_path / "g.npz"
    np.savez(path, **two_keyframes())
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match="not a pose graph archive"):
        load_graph(path)
