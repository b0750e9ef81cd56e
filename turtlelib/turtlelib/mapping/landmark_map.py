"""A landmark map with its joint covariance, and its file format (JSON, ``nuturtle_slam_map`` version 1).

The map
-------
:class:`LandmarkMap` holds ``n`` point landmarks in a map frame: their ids (distinct integers >= 0), their
positions ``m_i = [m_ix, m_iy]`` (m) and the JOINT covariance ``P_mm`` (2n, 2n) (m^2) of
``[m_0x, m_0y, m_1x, m_1y, ...]`` in the order of the ids: cross-covariances included, so that a filter
that loads the map (:meth:`turtlelib.estimation.ekf_slam.EkfSlam.load_map`) knows how the landmarks' errors
are correlated (after SLAM they are strongly: they share the robot's errors).

The file
--------
One UTF-8 JSON object (written with ``indent=2``; every key is required, no other key is allowed)::

    {
      "format": "nuturtle_slam_map",
      "version": 1,
      "frame_id": "map",
      "stamp_ns": 1700000000000000000,
      "landmarks": [
        {"id": 0, "x": 1.2, "y": -0.5},
        {"id": 3, "x": 0.25, "y": 1.75}
      ],
      "covariance": [
        [1e-4, 2e-6, 5e-5, 1e-6],
        [2e-6, 1e-4, 1e-6, 5e-5],
        [5e-5, 1e-6, 2e-4, 3e-6],
        [1e-6, 5e-5, 3e-6, 2e-4]
      ],
      "parameters": {"linearization": "fej", "range_std": 0.02}
    }

Field by field:

* ``format`` (string): always ``"nuturtle_slam_map"``; anything else is not a map of this kind.
* ``version`` (integer): the version of this layout, ``1``. A reader refuses versions it does not support
  (it says which one it found and which it supports) rather than guess.
* ``frame_id`` (non-empty string): the frame the positions are in (the SLAM node's map frame).
* ``stamp_ns`` (integer >= 0): when the map was made (ns since the epoch of the clock that made it).
* ``landmarks`` (array of ``n`` objects): per landmark ``id`` (integer >= 0, distinct), ``x`` and ``y``
  (numbers, m, in ``frame_id``). Their order is the order of ``covariance``'s rows (ascending ids when
  written by :func:`save_map` from :meth:`EkfSlam.landmark_map`, but any order is valid).
* ``covariance`` (array of ``2n`` arrays of ``2n`` numbers, m^2): the joint covariance of
  ``[x_0, y_0, x_1, y_1, ...]`` in the order of ``landmarks``; symmetric (to 1e-9 of its largest entry)
  and positive semi-definite (smallest eigenvalue >= -1e-9 times its largest entry), the rule of
  :func:`turtlelib.util.validation.covariance`. ``[]`` for ``n = 0``.
* ``parameters`` (object): the parameters that made the map (e.g. the SLAM node's), for the record; each
  value a boolean, an integer, a finite number or a string. ``{}`` if none.

Numbers are finite: ``NaN`` and ``Infinity`` (which Python's json would accept) are refused, and so is a
literal too large for a float64. Floats are written as Python's ``repr`` (the shortest decimal that reads
back to the same float64), so a saved map loads back bit for bit.

:func:`save_map` replaces the file atomically (a temporary file in the same directory, flushed and
fsynced, then renamed onto the path): a reader sees the old map or the new one, never half a file.
:func:`load_map` refuses anything that is not such a document with a ValueError that starts with the path
and says what is wrong.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from numbers import Integral, Real
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..util.validation import covariance, finite_array, integer, landmark_ids, names
from .atomic_files import replace_files

MAP_FORMAT = "nuturtle_slam_map"
MAP_FORMAT_VERSION = 1
_KEYS = ("format", "version", "frame_id", "stamp_ns", "landmarks", "covariance", "parameters")
_LANDMARK_KEYS = ("id", "x", "y")

Parameter = bool | int | float | str


@dataclass(frozen=True, eq=False)
class LandmarkMap:
    """``n`` landmarks: ``ids`` (n,) int64 distinct >= 0, positions ``xy`` (n, 2) float64 finite (m, in
    ``frame_id``), their joint ``covariance`` (2n, 2n) float64 (m^2) of ``[m_0x, m_0y, m_1x, ...]`` in the
    order of ``ids`` (finite, symmetric, positive semi-definite), made at ``stamp_ns`` (integer ns >= 0)
    with ``parameters`` (names to booleans, integers, finite floats or strings).

    The arrays are stored as read-only float64 / int64 copies; ``covariance`` exactly symmetric (entries
    that differ from their transpose within the tolerance are replaced by their mean). ValueError naming
    the field for anything else. ``==`` (and :meth:`equals`) compares bit for bit.
    """

    frame_id: str
    stamp_ns: int
    ids: NDArray[np.int64]
    xy: NDArray[np.float64]
    covariance: NDArray[np.float64]
    parameters: dict[str, Parameter] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names("string", frame_id=self.frame_id)
        object.__setattr__(self, "stamp_ns", integer("stamp_ns", self.stamp_ns, minimum=0))
        ids = landmark_ids("ids", self.ids)
        n = len(ids)
        xy = finite_array("xy", self.xy, (n, 2))
        P = covariance("covariance", self.covariance, (2 * n, 2 * n), definite=False)
        for name, array in (("ids", ids), ("xy", xy), ("covariance", P)):
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        object.__setattr__(self, "parameters", _parameters(self.parameters))

    @property
    def n_landmarks(self) -> int:
        return len(self.ids)

    def equals(self, other: object) -> bool:
        """Whether ``other`` is a LandmarkMap with the same fields, bit for bit: equal frame, stamp, arrays
        (``np.array_equal``) and parameters (of the same types)."""
        if not isinstance(other, LandmarkMap):
            return False
        return (
            self.frame_id == other.frame_id
            and self.stamp_ns == other.stamp_ns
            and np.array_equal(self.ids, other.ids)
            and np.array_equal(self.xy, other.xy)
            and np.array_equal(self.covariance, other.covariance)
            and _typed(self.parameters) == _typed(other.parameters)
        )

    def __eq__(self, other: object) -> bool:
        return self.equals(other) if isinstance(other, LandmarkMap) else NotImplemented

    __hash__ = None  # mutable-looking fields (arrays, a dict): not hashable


def save_map(path: str | os.PathLike, landmark_map: LandmarkMap) -> None:
    """Write ``landmark_map`` to ``path`` as the JSON document of the module docstring, atomically.

    Missing parent directories are created. The document goes to a temporary file ``.<name>.*.tmp`` in the
    same directory, is flushed and fsynced, then renamed onto ``path`` (:func:`turtlelib.mapping.atomic_files.
    replace_files`): an existing file is replaced whole or left as it was. On any error the temporary file
    is removed and the error raised.
    """
    if not isinstance(landmark_map, LandmarkMap):
        raise ValueError(f"landmark_map must be a LandmarkMap, got {type(landmark_map).__name__}")
    path = Path(path)
    document = {
        "format": MAP_FORMAT,
        "version": MAP_FORMAT_VERSION,
        "frame_id": landmark_map.frame_id,
        "stamp_ns": landmark_map.stamp_ns,
        "landmarks": [
            {"id": landmark_id, "x": x, "y": y}
            for landmark_id, (x, y) in zip(landmark_map.ids.tolist(), landmark_map.xy.tolist(), strict=True)
        ],
        "covariance": landmark_map.covariance.tolist(),
        "parameters": dict(landmark_map.parameters),
    }
    text = json.dumps(document, indent=2, allow_nan=False) + "\n"
    replace_files({path: text.encode("utf-8")})


def load_map(path: str | os.PathLike) -> LandmarkMap:
    """The map in the file ``path`` (the JSON document of the module docstring).

    ValueError, its message starting with the path, for a missing or unreadable file, a file that is not
    JSON (e.g. truncated), another ``format``, a missing or unsupported ``version``, missing or unknown
    keys, values of the wrong type, non-finite numbers, and whatever :class:`LandmarkMap` refuses (the
    covariance's shape, symmetry and positive semi-definiteness, duplicate or negative ids, ...).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: cannot read the map file: {error}") from None
    try:
        document = json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not a JSON document (truncated?): {error}") from None
    except ValueError as error:  # from _refuse_constant
        raise ValueError(f"{path}: {error}") from None
    try:
        return _from_document(document)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


# --- helpers -------------------------------------------------------------------------------------------


def _from_document(document: object) -> LandmarkMap:
    """The LandmarkMap of a parsed document: its layout is checked here, its values by LandmarkMap."""
    if not isinstance(document, dict):
        raise ValueError(f"the document must be a JSON object, got {_json_type(document)}")
    if document.get("format") != MAP_FORMAT:
        raise ValueError(f"format must be {MAP_FORMAT!r}, got {document.get('format')!r}")
    if "version" not in document:
        raise ValueError(f"no version (this reader supports version {MAP_FORMAT_VERSION})")
    version = document["version"]
    if type(version) is not int or version != MAP_FORMAT_VERSION:
        raise ValueError(
            f"version {version!r} is not supported (this reader supports version {MAP_FORMAT_VERSION} only)"
        )
    _check_keys("the document", document, _KEYS)
    landmarks = document["landmarks"]
    if not isinstance(landmarks, list):
        raise ValueError(f"landmarks must be a JSON array, got {_json_type(landmarks)}")
    for index, landmark in enumerate(landmarks):
        if not isinstance(landmark, dict):
            raise ValueError(f"landmarks[{index}] must be a JSON object, got {_json_type(landmark)}")
        _check_keys(f"landmarks[{index}]", landmark, _LANDMARK_KEYS)
        for key in _LANDMARK_KEYS:
            if not _is_number(landmark[key]):
                raise ValueError(f"landmarks[{index}].{key} must be a number, got {landmark[key]!r}")
    rows = document["covariance"]
    if not (isinstance(rows, list) and all(isinstance(row, list) for row in rows)):
        raise ValueError("covariance must be a JSON array of arrays (its rows)")
    if not all(_is_number(value) for row in rows for value in row):
        raise ValueError("covariance must hold numbers only")
    if not isinstance(document["parameters"], dict):
        raise ValueError(f"parameters must be a JSON object, got {_json_type(document['parameters'])}")
    n = len(landmarks)
    return LandmarkMap(
        frame_id=document["frame_id"],
        stamp_ns=document["stamp_ns"],
        ids=np.array([landmark["id"] for landmark in landmarks], dtype=object).reshape(n),
        xy=[[landmark["x"], landmark["y"]] for landmark in landmarks],
        covariance=rows,
        parameters=document["parameters"],
    )


def _check_keys(what: str, document: dict, keys: tuple[str, ...]) -> None:
    missing = [key for key in keys if key not in document]
    if missing:
        raise ValueError(f"{what} lacks the key(s) {missing}")
    unknown = sorted(set(document) - set(keys))
    if unknown:
        raise ValueError(f"{what} has unknown key(s) {unknown} (allowed: {list(keys)})")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _json_type(value: object) -> str:
    kinds = {dict: "an object", list: "an array", str: "a string", bool: "a boolean", type(None): "null"}
    return kinds.get(type(value), "a number")


def _refuse_constant(constant: str) -> float:
    raise ValueError(f"non-finite number {constant} (map files hold finite numbers only)")


def _parameters(parameters: object) -> dict[str, Parameter]:
    """A copy of ``parameters``: ValueError unless a dict of non-empty string names to booleans,
    integers, finite floats or strings (numpy scalars become the Python ones)."""
    if not isinstance(parameters, dict):
        raise ValueError(f"parameters must be a dict, got {type(parameters).__name__}")
    result: dict[str, Parameter] = {}
    for name, value in parameters.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"parameters' names must be non-empty strings, got {name!r}")
        if isinstance(value, (bool, np.bool_)):
            result[name] = bool(value)
        elif isinstance(value, Integral):
            result[name] = int(value)
        elif isinstance(value, Real) and math.isfinite(value):
            result[name] = float(value)
        elif isinstance(value, str):
            result[name] = value
        else:
            raise ValueError(
                f"parameters[{name!r}] must be a boolean, an integer, a finite float or a string, "
                f"got {value!r}"
            )
    return result


def _typed(parameters: dict[str, Parameter]) -> dict[str, tuple[type, Parameter]]:
    """``parameters`` with each value's type (``True == 1 == 1.0`` in Python, not bit for bit)."""
    return {name: (type(value), value) for name, value in parameters.items()}
