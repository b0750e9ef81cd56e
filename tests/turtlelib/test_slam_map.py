"""LandmarkMap's checks and the map file (turtlelib.mapping.landmark_map): bit-for-bit round trips, refused
files, atomic saves."""

import json
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import LandmarkMap, load_map, save_map
from turtlelib.mapping.landmark_map import MAP_FORMAT, MAP_FORMAT_VERSION


def small_map(n: int = 3, seed: int = 0) -> LandmarkMap:
    rng = np.random.default_rng(seed)
    A = rng.normal(0.0, 0.01, (2 * n, 2 * n))
    return LandmarkMap(
        frame_id="map",
        stamp_ns=1_700_000_000_123_456_789,
        ids=np.arange(n) * 2 + 1,
        xy=rng.normal(0.0, 2.0, (n, 2)),
        covariance=A @ A.T,
        parameters={"linearization": "fej", "range_std": 0.02, "confirm_count": 5, "known": True},
    )


def written(tmp_path, document: object | str) -> str:
    path = tmp_path / "map.json"
    path.write_text(document if isinstance(document, str) else json.dumps(document), encoding="utf-8")
    return str(path)


def document_of(landmark_map: LandmarkMap, tmp_path) -> dict:
    path = tmp_path / "source.json"
    save_map(path, landmark_map)
    return json.loads(path.read_text(encoding="utf-8"))


# --- LandmarkMap -------------------------------------------------------------------------------------------


def test_landmark_map_normalises_and_freezes_its_arrays():
    landmark_map = LandmarkMap("map", 0, [4, 1], [[1, 2], [3, 4]], np.eye(4).tolist())
    assert landmark_map.ids.dtype == np.int64 and landmark_map.xy.dtype == np.float64
    assert landmark_map.covariance.dtype == np.float64 and landmark_map.n_landmarks == 2
    assert landmark_map.parameters == {}
    with pytest.raises(ValueError):
        landmark_map.xy[0, 0] = 5.0
    empty = LandmarkMap("map", 0, [], [], [])
    assert empty.xy.shape == (0, 2) and empty.covariance.shape == (0, 0) and empty.n_landmarks == 0


def test_landmark_map_symmetrises_within_the_tolerance_and_keeps_exact_entries():
    P = np.array([[2.0, 0.5], [0.5 + 1e-12, 1.0]])
    landmark_map = LandmarkMap("map", 0, [0], [[0.0, 0.0]], P)
    assert landmark_map.covariance[0, 1] == landmark_map.covariance[1, 0]
    assert landmark_map.covariance[0, 0] == 2.0 and landmark_map.covariance[1, 1] == 1.0


@pytest.mark.parametrize(
    ("smallest", "valid"), [(0.0, True), (-1e-12, True), (-0.5e-9, True), (-1e-8, False)]
)
def test_positive_semi_definiteness_is_judged_to_1e_9_of_the_scale(smallest, valid):
    # eigenvalues 2 and 2 smallest; the largest entry (the scale) is 2 * 0.64 = 1.28
    rotation = np.array([[0.6, -0.8], [0.8, 0.6]])
    P = rotation @ np.diag([2.0, 2.0 * smallest]) @ rotation.T
    P = 0.5 * (P + P.T)
    if valid:
        assert LandmarkMap("map", 0, [0], [[0.0, 0.0]], P).covariance[0, 0] == P[0, 0]
    else:
        with pytest.raises(ValueError, match="smallest eigenvalue -2e-08"):
            LandmarkMap("map", 0, [0], [[0.0, 0.0]], P)


def test_equals_is_bit_for_bit():
    a, b = small_map(), small_map()
    assert a.equals(b) and a == b
    assert not a.equals(LandmarkMap(a.frame_id, a.stamp_ns, a.ids, a.xy + 1e-15, a.covariance, a.parameters))
    assert not a.equals(
        LandmarkMap(a.frame_id, a.stamp_ns, a.ids, a.xy, a.covariance, {**a.parameters, "known": 1})
    )
    assert a != "a map" and not a.equals(None)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"frame_id": ""}, "frame_id"),
        ({"frame_id": 3}, "frame_id"),
        ({"stamp_ns": -1}, "stamp_ns"),
        ({"stamp_ns": 1.5}, "stamp_ns"),
        ({"ids": [0, 0]}, "ids must be distinct"),
        ({"ids": [0, -1]}, "ids must be >= 0"),
        ({"ids": [0.0, 1.0]}, "ids must be integers"),
        ({"ids": [True, False]}, "ids must be integers"),
        ({"xy": [[0.0, 0.0]]}, "xy must have shape"),
        ({"xy": [[0.0, math.nan], [1.0, 1.0]]}, "xy must be finite"),
        ({"xy": [["a", "b"], ["c", "d"]]}, "xy must be"),
        ({"covariance": np.eye(3)}, "covariance must have shape"),
        ({"covariance": np.diag([1.0, 1.0, 1.0, math.inf])}, "covariance must be finite"),
        ({"covariance": np.eye(4) + np.triu(np.ones((4, 4)), 1) * 1e-3}, "covariance must be symmetric"),
        ({"covariance": np.diag([1.0, 1.0, 1.0, -1e-3])}, "covariance must be positive semi-definite"),
        ({"parameters": {"a": [1, 2]}}, r"parameters\['a'\]"),
        ({"parameters": {"a": math.nan}}, r"parameters\['a'\]"),
        ({"parameters": {3: 1}}, "parameters' names"),
        ({"parameters": [("a", 1)]}, "parameters must be a dict"),
    ],
)
def test_landmark_map_refuses_invalid_fields(changes, message):
    fields = {
        "frame_id": "map",
        "stamp_ns": 0,
        "ids": [0, 1],
        "xy": np.zeros((2, 2)),
        "covariance": np.eye(4),
    }
    with pytest.raises(ValueError, match=message):
        LandmarkMap(**{**fields, **changes})


# --- round trips -------------------------------------------------------------------------------------------


@st.composite
def landmark_maps(draw) -> LandmarkMap:
    """Random valid maps: distinct ids, positions of any magnitude, PSD covariances A A^T."""
    n = draw(st.integers(0, 6))
    ids = draw(st.lists(st.integers(0, 2**63 - 1), min_size=n, max_size=n, unique=True))
    magnitude = st.sampled_from([1e-300, 1e-12, 1e-3, 1.0, 1e3, 1e12, 1e300])
    xy = [[draw(magnitude) * draw(st.floats(-1.0, 1.0, allow_nan=False)) for _ in range(2)] for _ in range(n)]
    seed = draw(st.integers(0, 2**32 - 1))
    scale = draw(st.sampled_from([1e-12, 1e-6, 1e-2, 1.0, 1e6]))
    rank = draw(st.integers(0, 2 * n))
    A = np.random.default_rng(seed).normal(0.0, scale, (2 * n, rank))
    parameters = draw(
        st.dictionaries(
            st.text(min_size=1, max_size=8),
            st.one_of(
                st.booleans(), st.integers(), st.floats(allow_nan=False, allow_infinity=False), st.text()
            ),
            max_size=4,
        )
    )
    return LandmarkMap(
        frame_id=draw(st.text(min_size=1, max_size=10)),
        stamp_ns=draw(st.integers(0, 2**64)),
        ids=np.array(ids, dtype=np.int64),
        xy=np.array(xy, dtype=np.float64).reshape(n, 2),
        covariance=A @ A.T,
        parameters=parameters,
    )


@settings(max_examples=80, deadline=None)
@given(landmark_maps())
def test_save_then_load_is_bit_for_bit(tmp_path_factory, landmark_map):
    path = tmp_path_factory.mktemp("maps") / "map.json"
    save_map(path, landmark_map)
    loaded = load_map(path)
    assert loaded.equals(landmark_map)
    assert loaded.xy.tobytes() == landmark_map.xy.tobytes()
    assert loaded.covariance.tobytes() == landmark_map.covariance.tobytes()
    document = json.loads(path.read_text(encoding="utf-8"))
    assert document["format"] == MAP_FORMAT and document["version"] == 1 == MAP_FORMAT_VERSION
    assert [landmark["id"] for landmark in document["landmarks"]] == landmark_map.ids.tolist()


@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_json_floats_round_trip_exactly(value):
    assert json.loads(json.dumps(value)) == value
    assert math.copysign(1.0, json.loads(json.dumps(value))) == math.copysign(1.0, value)


def test_saved_file_is_readable_json_with_the_documented_layout(tmp_path):
    landmark_map = small_map(2)
    path = tmp_path / "deep" / "er" / "map.json"  # missing parents are created
    save_map(path, landmark_map)
    text = path.read_text(encoding="utf-8")
    document = json.loads(text)
    assert list(document) == [
        "format",
        "version",
        "frame_id",
        "stamp_ns",
        "landmarks",
        "covariance",
        "parameters",
    ]
    assert document["landmarks"][1] == {
        "id": 3,
        "x": landmark_map.xy[1, 0],
        "y": landmark_map.xy[1, 1],
    }
    assert np.array(document["covariance"]).shape == (4, 4)
    assert document["parameters"] == landmark_map.parameters
    assert text.startswith('{\n  "format"')  # indent 2: human-readable
    assert sorted(os.listdir(path.parent)) == ["map.json"]


# --- refused files -----------------------------------------------------------------------------------------


def test_missing_file_is_a_value_error_naming_the_path(tmp_path):
    path = tmp_path / "nothing.json"
    with pytest.raises(ValueError, match=f"^{path}: no such file"):
        load_map(path)


def test_truncated_file_is_refused(tmp_path):
    path = tmp_path / "map.json"
    save_map(path, small_map())
    text = path.read_text(encoding="utf-8")
    path.write_text(text[: len(text) // 2], encoding="utf-8")
    with pytest.raises(ValueError, match=f"^{path}: not a JSON document"):
        load_map(path)


def test_empty_and_binary_files_are_refused(tmp_path):
    with pytest.raises(ValueError, match="not a JSON document"):
        load_map(written(tmp_path, ""))
    binary = tmp_path / "binary.json"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ValueError, match="cannot read"):
        load_map(binary)


def test_other_versions_are_refused_saying_which(tmp_path):
    document = document_of(small_map(), tmp_path)
    with pytest.raises(ValueError, match=r"version 2 is not supported \(this reader supports version 1 only"):
        load_map(written(tmp_path, {**document, "version": 2}))
    with pytest.raises(ValueError, match="version True is not supported"):
        load_map(written(tmp_path, {**document, "version": True}))
    del document["version"]
    with pytest.raises(ValueError, match=r"no version \(this reader supports version 1\)"):
        load_map(written(tmp_path, document))


@pytest.mark.parametrize("value", ["nuturtle_slam_mop", None, 1])
def test_wrong_format_is_refused(tmp_path, value):
    document = document_of(small_map(), tmp_path)
    with pytest.raises(ValueError, match="format must be 'nuturtle_slam_map'"):
        load_map(written(tmp_path, {**document, "format": value}))


def test_a_json_array_is_not_a_map(tmp_path):
    with pytest.raises(ValueError, match="must be a JSON object, got an array"):
        load_map(written(tmp_path, [1, 2]))


@pytest.mark.parametrize("key", ["frame_id", "stamp_ns", "landmarks", "covariance", "parameters"])
def test_missing_key_is_refused(tmp_path, key):
    document = document_of(small_map(), tmp_path)
    del document[key]
    with pytest.raises(ValueError, match=rf"lacks the key\(s\) \['{key}'\]"):
        load_map(written(tmp_path, document))


def test_unknown_keys_and_missing_landmark_keys_are_refused(tmp_path):
    document = document_of(small_map(), tmp_path)
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['colour'\]"):
        load_map(written(tmp_path, {**document, "colour": "red"}))
    del document["landmarks"][1]["y"]
    with pytest.raises(ValueError, match=r"landmarks\[1\] lacks the key\(s\) \['y'\]"):
        load_map(written(tmp_path, document))


def test_nan_in_xy_is_refused(tmp_path):
    text = json.dumps(document_of(small_map(), tmp_path))
    document = json.loads(text)
    document["landmarks"][0]["x"] = math.nan
    path = written(tmp_path, json.dumps(document))  # json writes the literal NaN
    assert "NaN" in open(path, encoding="utf-8").read()
    with pytest.raises(ValueError, match="non-finite number NaN"):
        load_map(path)


def test_infinity_in_covariance_is_refused(tmp_path):
    document = document_of(small_map(), tmp_path)
    document["covariance"][0][0] = math.inf
    with pytest.raises(ValueError, match="non-finite number Infinity"):
        load_map(written(tmp_path, json.dumps(document)))
    document["covariance"][0][0] = 1.0
    text = json.dumps(document).replace('"covariance": [[1.0', '"covariance": [[1e999', 1)
    with pytest.raises(ValueError, match="covariance must be finite"):
        load_map(written(tmp_path, text))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: d["covariance"][0].__setitem__(1, d["covariance"][0][1] + 1.0), "must be symmetric"),
        (lambda d: d.__setitem__("covariance", (-np.eye(6)).tolist()), "must be positive semi-definite"),
        (lambda d: d.__setitem__("covariance", np.eye(5).tolist()), r"must have shape \(6, 6\)"),
        (lambda d: d["covariance"].pop(), "must have shape"),
        (lambda d: d["covariance"][2].pop(), "covariance must be"),
        (lambda d: d["covariance"][2].__setitem__(0, "0.1"), "covariance must hold numbers only"),
        (lambda d: d["landmarks"][2].__setitem__("id", 1), r"ids must be distinct, got duplicates \[1\]"),
        (lambda d: d["landmarks"][2].__setitem__("id", -4), r"ids must be >= 0, got \[-4\]"),
        (lambda d: d["landmarks"][2].__setitem__("id", 2.0), "ids must be integers"),
        (lambda d: d["landmarks"][2].__setitem__("x", "1.0"), r"landmarks\[2\].x must be a number"),
        (lambda d: d["landmarks"][2].__setitem__("y", True), r"landmarks\[2\].y must be a number"),
        (lambda d: d.__setitem__("landmarks", {}), "landmarks must be a JSON array"),
        (lambda d: d["landmarks"].__setitem__(0, [1, 2, 3]), r"landmarks\[0\] must be a JSON object"),
        (lambda d: d.__setitem__("stamp_ns", "now"), "stamp_ns must be an integer"),
        (lambda d: d.__setitem__("stamp_ns", -5), "stamp_ns must be >= 0"),
        (lambda d: d.__setitem__("frame_id", ""), "frame_id must be a non-empty string"),
        (lambda d: d.__setitem__("parameters", [1]), "parameters must be a JSON object"),
        (lambda d: d["parameters"].__setitem__("gains", [1, 2]), r"parameters\['gains'\]"),
        (lambda d: d["parameters"].__setitem__("none", None), r"parameters\['none'\]"),
    ],
)
def test_invalid_content_is_refused_with_the_path(tmp_path, change, message):
    document = document_of(small_map(), tmp_path)
    change(document)
    path = written(tmp_path, document)
    with pytest.raises(ValueError, match=message) as error:
        load_map(path)
    assert str(error.value).startswith(f"{path}: ")


# --- atomic saves ------------------------------------------------------------------------------------------


def test_failed_save_keeps_the_old_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "map.json"
    save_map(path, small_map(2))
    before = path.read_bytes()

    def disk_full(fd):  # the written data does not reach the disk: ENOSPC shows at fsync
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", disk_full)
    with pytest.raises(OSError, match="disk full"):
        save_map(path, small_map(3, seed=1))
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["map.json"]


def test_failed_rename_keeps_the_old_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "map.json"
    save_map(path, small_map(2))
    before = path.read_bytes()

    def refuse(source, target):
        raise PermissionError("read-only")

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(PermissionError):
        save_map(path, small_map(3, seed=1))
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["map.json"]


def test_unserialisable_content_fails_before_touching_the_file(tmp_path):
    path = tmp_path / "map.json"
    save_map(path, small_map(2))
    before = path.read_bytes()
    broken = small_map(2)
    object.__setattr__(broken, "parameters", {"callback": object()})  # past LandmarkMap's checks
    with pytest.raises(TypeError):
        save_map(path, broken)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["map.json"]


def test_save_keeps_an_existing_files_mode_and_refuses_non_maps(tmp_path):
    path = tmp_path / "map.json"
    save_map(path, small_map(1))
    assert path.stat().st_mode & 0o777 == 0o644
    path.chmod(0o600)
    save_map(path, small_map(2))
    assert path.stat().st_mode & 0o777 == 0o600
    with pytest.raises(ValueError, match="must be a LandmarkMap"):
        save_map(path, {"ids": []})
