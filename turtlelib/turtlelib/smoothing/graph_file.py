"""Loop closure's pose graph in a file, so that a later mapping session continues it
(:class:`turtlelib.smoothing.loop_closure.LoopClosure` built from a loaded graph).

Format
------
A NumPy ``.npz`` archive (:func:`numpy.savez`, no pickled objects) of exactly these arrays, ``K``
keyframes and ``E`` edges::

    version          ()        int     GRAPH_FORMAT_VERSION (1)
    t_ns             (K,)      int64   each keyframe's stamp (ns, on its own session's clock)
    T_map_keyframe   (K, 3)    float   each keyframe's pose [x, y, theta] in the map frame (m, m, rad)
    point_counts     (K,)      int64   how many of ``points`` are each keyframe's, in keyframe order
    points           (N, 2)    float   the keyframes' thinned points in their own body frame (m),
                                       N = sum(point_counts)
    path_m           (K,)      float   the path travelled to each keyframe (m, >= 0, over all sessions)
    edge_i, edge_j   (E,)      int64   each edge's keyframes, 0 <= i, j < K, i != j
    edge_Z           (E, 3)    float   its measured relative pose T_i^-1 T_j [x, y, theta] (frame i)
    edge_S           (E, 3, 3) float   the measurement's covariance (positive definite)
    edge_loop        (E,)      bool    a loop edge (True) or an odometry edge between consecutive keyframes

The poses are map poses ``T_map_keyframe`` (each session's odometry frame is gone with it); the edges'
relative poses and covariances are in frame ``i`` and so hold in any frame. :func:`save_graph` replaces the
file atomically (:func:`turtlelib.mapping.atomic_files.replace_files`); :func:`load_graph` refuses anything
else with a ValueError that starts with the path and says what is wrong.
"""

from __future__ import annotations

import io
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..mapping.atomic_files import replace_files
from ..util.validation import covariance, finite_array

GRAPH_FORMAT_VERSION = 1
# the SavedGraph fields stored as they are; the keyframes' points are stored as point_counts and points
_ARRAYS = ("t_ns", "T_map_keyframe", "path_m", "edge_i", "edge_j", "edge_Z", "edge_S", "edge_loop")
_KEYS = ("version", "point_counts", "points", *_ARRAYS)


def _integers(name: str, value: ArrayLike, length: int | None = None) -> NDArray[np.int64]:
    """``value`` as an int64 vector (of ``length``); ValueError unless it holds integers."""
    array = np.asarray(value)
    if array.ndim != 1 or (length is not None and len(array) != length):
        expected = "a vector" if length is None else f"shape ({length},)"
        raise ValueError(f"{name} must be {expected}, got shape {array.shape}")
    if array.size and array.dtype.kind not in "iu":
        raise ValueError(f"{name} must hold integers, got dtype {array.dtype}")
    return array.astype(np.int64)


@dataclass(frozen=True, eq=False)
class SavedGraph:
    """A pose graph as saved (module docstring's arrays; ``points`` one (n_k, 2) array per keyframe).
    Validated and converted on construction: ValueError naming the field for a wrong shape or type, a
    non-finite value, a negative path, an edge to an unknown or the same keyframe, a covariance that is
    not positive definite."""

    t_ns: NDArray[np.int64]
    T_map_keyframe: NDArray[np.float64]
    points: tuple[NDArray[np.float64], ...]
    path_m: NDArray[np.float64]
    edge_i: NDArray[np.int64]
    edge_j: NDArray[np.int64]
    edge_Z: NDArray[np.float64]
    edge_S: NDArray[np.float64]
    edge_loop: NDArray[np.bool_]

    def __post_init__(self) -> None:
        t_ns = _integers("t_ns", self.t_ns)
        K = len(t_ns)
        points = tuple(
            finite_array(f"points[{k}]", p, (len(np.asarray(p)), 2)) for k, p in enumerate(self.points)
        )
        if len(points) != K:
            raise ValueError(f"points must hold one array per keyframe ({K}), got {len(points)}")
        path_m = finite_array("path_m", self.path_m, (K,))
        if np.any(path_m < 0.0):
            raise ValueError("path_m must be >= 0 (m travelled)")
        edge_i = _integers("edge_i", self.edge_i)
        E = len(edge_i)
        edge_j = _integers("edge_j", self.edge_j, E)
        if E and (min(edge_i.min(), edge_j.min()) < 0 or max(edge_i.max(), edge_j.max()) >= K):
            raise ValueError(f"edge_i and edge_j must name keyframes 0..{K - 1}")
        if np.any(edge_i == edge_j):
            raise ValueError("an edge joins two distinct keyframes (edge_i == edge_j)")
        edge_loop = np.asarray(self.edge_loop)
        if edge_loop.shape != (E,) or (E and edge_loop.dtype != np.bool_):
            raise ValueError(f"edge_loop must be ({E},) booleans, got {edge_loop.dtype} {edge_loop.shape}")
        values = {
            "t_ns": t_ns,
            "T_map_keyframe": finite_array("T_map_keyframe", self.T_map_keyframe, (K, 3)),
            "points": points,
            "path_m": path_m,
            "edge_i": edge_i,
            "edge_j": edge_j,
            "edge_Z": finite_array("edge_Z", self.edge_Z, (E, 3)),
            "edge_S": covariance("edge_S", self.edge_S, (E, 3, 3), definite=True),
            "edge_loop": edge_loop.astype(bool),
        }
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def n_keyframes(self) -> int:
        return len(self.t_ns)

    @property
    def n_edges(self) -> int:
        return len(self.edge_i)

    def equals(self, other: SavedGraph) -> bool:
        """Whether ``other`` holds the same arrays, bit for bit."""
        same = all(np.array_equal(getattr(self, name), getattr(other, name)) for name in _ARRAYS)
        return (
            same
            and len(self.points) == len(other.points)
            and all(np.array_equal(a, b) for a, b in zip(self.points, other.points, strict=True))
        )


def save_graph(path: str | os.PathLike, graph: SavedGraph) -> None:
    """Write ``graph`` to ``path`` (module docstring's ``.npz``), atomically; missing folders are created."""
    counts = np.array([len(p) for p in graph.points], dtype=np.int64)
    buffer = io.BytesIO()
    np.savez(
        buffer,
        version=np.int64(GRAPH_FORMAT_VERSION),
        point_counts=counts,
        points=np.concatenate(graph.points) if graph.points else np.zeros((0, 2)),
        **{name: getattr(graph, name) for name in _ARRAYS},
    )
    replace_files({Path(path): buffer.getvalue()})


def load_graph(path: str | os.PathLike) -> SavedGraph:
    """The graph in the file ``path`` (module docstring). ValueError, its message starting with the path,
    for a missing or unreadable file, one that is not such an archive (truncated, pickled objects), a
    missing or unsupported ``version``, missing or unknown arrays, and whatever :class:`SavedGraph`
    refuses."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as error:
        raise ValueError(f"{path}: not a pose graph archive (.npz; truncated?): {error}") from None
    try:
        return _from_arrays(arrays)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def _from_arrays(arrays: dict[str, np.ndarray]) -> SavedGraph:
    if "version" not in arrays:
        raise ValueError(f"no version (this reader supports version {GRAPH_FORMAT_VERSION})")
    version = arrays["version"]
    if version.shape != () or version.dtype.kind not in "iu" or int(version) != GRAPH_FORMAT_VERSION:
        raise ValueError(
            f"version {version.tolist()!r} is not supported "
            f"(this reader supports version {GRAPH_FORMAT_VERSION} only)"
        )
    missing, unknown = set(_KEYS) - set(arrays), set(arrays) - set(_KEYS)
    if missing or unknown:
        raise ValueError(f"arrays missing: {sorted(missing)}, unknown: {sorted(unknown)}")
    counts = _integers("point_counts", arrays["point_counts"], len(np.atleast_1d(arrays["t_ns"])))
    points = arrays["points"]
    if np.any(counts < 0) or points.ndim != 2 or points.shape[1] != 2 or len(points) != counts.sum():
        raise ValueError(
            f"points must be (sum(point_counts), 2) = ({counts.sum()}, 2) with counts >= 0, "
            f"got {points.shape}"
        )
    return SavedGraph(
        points=tuple(np.split(points, np.cumsum(counts)[:-1])) if len(counts) else (),
        **{name: arrays[name] for name in _ARRAYS},
    )
