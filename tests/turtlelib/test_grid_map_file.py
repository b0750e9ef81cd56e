"""map_server's yaml + PGM: what the writer puts in the files (read by a reader written here from the
format's definition), what the reader makes of files written by hand, atomic saves and refused files."""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from turtlelib import Transform2D
from turtlelib.mapping.grid_map_file import load_grid_map, save_grid_map
from turtlelib.mapping.occupancy_grid import GridMap

occupancy_grids = hnp.arrays(
    np.int8, hnp.array_shapes(min_dims=2, max_dims=2, max_side=12), elements=st.integers(-1, 100)
)


def read_independently(yaml_path):
    """The yaml's keys (``key: value`` lines; lists as JSON) and the PGM's pixels in image order, from
    the formats' definitions: map_server's yaml keys and netpbm's P5 (magic, whitespace-separated width,
    height, maxval with '#' comments, one whitespace byte, then width * height bytes)."""
    metadata = {}
    for line in yaml_path.read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        key, value = line.split(": ", 1)
        metadata[key] = json.loads(value) if value.startswith("[") else value
    image = (yaml_path.parent / metadata["image"]).read_bytes()
    header = re.match(rb"P5(?:\s+|#[^\n]*\n)+(\d+)(?:\s+|#[^\n]*\n)+(\d+)(?:\s+|#[^\n]*\n)+(\d+)\s", image)
    width, height, maxval = (int(value) for value in header.groups())
    pixels = np.frombuffer(image[header.end() :], dtype=np.uint8)
    assert maxval == 255 and pixels.size == width * height
    return metadata, pixels.reshape(height, width)


@settings(max_examples=40, deadline=None)
@given(occupancy_grids, st.floats(-50, 50), st.floats(-50, 50), st.sampled_from([0.05, 0.025, 0.1]))
def test_the_files_hold_map_savers_trinary_image_and_metadata(tmp_path_factory, occupancy, x, y, resolution):
    yaml_path = tmp_path_factory.mktemp("map") / "room.yaml"
    grid_map = GridMap(occupancy, resolution, Transform2D(x, y, 0.0))
    image_path = save_grid_map(yaml_path, grid_map)
    assert image_path == yaml_path.with_name("room.pgm")
    metadata, pixels = read_independently(yaml_path)
    assert metadata == {
        "image": "room.pgm",
        "mode": "trinary",
        "resolution": repr(resolution),
        "origin": [x, y, 0.0],
        "negate": "0",
        "occupied_thresh": "0.65",
        "free_thresh": "0.196",
    }
    # image row 0 is the top of the map (the grid's last row); map_saver's trinary pixels with the
    # thresholds 0.196 -> 20 and 0.65 -> 65 (per cent)
    expected = np.where(occupancy >= 65, 0, np.where((occupancy >= 0) & (occupancy <= 20), 254, 205))
    assert np.array_equal(pixels, expected[::-1])
    # read back as map_server would: occupied 100, free 0, the rest unknown
    loaded = load_grid_map(yaml_path)
    assert np.array_equal(loaded.occupancy, np.where(expected == 0, 100, np.where(expected == 254, 0, -1)))
    assert (loaded.resolution_m, loaded.origin) == (resolution, Transform2D(x, y, 0.0))


def write(folder, yaml_text, image=None, image_name="m.pgm"):
    if image is not None:
        (folder / image_name).write_bytes(image)
    (folder / "m.yaml").write_text(yaml_text)
    return folder / "m.yaml"


YAML = (
    "image: m.pgm\nresolution: 0.1\norigin: [-1.0, 2.0, 0.5]\nnegate: 0\noccupied_thresh: 0.65\n"
    "free_thresh: 0.25\n"
)
# 3 x 2, top row first: shades 0, 50/255, 254/255 and 1/255, 128/255, 1
P5 = b"P5\n3 2\n255\n" + bytes([0, 50, 254, 1, 128, 255])


def test_a_trinary_file_written_by_hand(tmp_path):
    grid_map = load_grid_map(write(tmp_path, YAML, P5))
    # occ = 1 - shade: 1, 0.804, 0.004 (top row) and 0.996, 0.498, 0; occ > 0.65 occupied, < 0.25 free
    assert grid_map.occupancy.tolist() == [[100, -1, 0], [100, 100, 0]]
    assert grid_map.resolution_m == 0.1 and grid_map.origin == Transform2D(-1.0, 2.0, 0.5)


def test_nav2s_default_free_thresh_reads_unknown_grey_as_free(tmp_path):
    # map_saver's unknown 205 has occ = 50 / 255 = 0.196 < 0.25: free (why save_grid_map writes 0.196)
    image = b"P5 1 1 255\n" + bytes([205])
    assert load_grid_map(write(tmp_path, YAML, image)).occupancy.tolist() == [[0]]
    yaml_text = YAML.replace("free_thresh: 0.25", "free_thresh: 0.196")
    assert load_grid_map(write(tmp_path, yaml_text, image)).occupancy.tolist() == [[-1]]


def test_p2_comments_negate_quotes_and_a_maxval_below_255(tmp_path):
    yaml_text = (
        "# a map\nimage: 'm.pgm'   # quoted\nresolution: 5e-2\norigin: [0, 0, 0]\nnegate: true\n"
        'occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: "trinary"\n'
    )
    # shade = v / 15; negate: occ = shade
    image = b"P2\n# made by hand\n2 2\n# the largest value\n15\n15 0\n# rows\n7 3\n"
    grid_map = load_grid_map(write(tmp_path, yaml_text, image))
    # grid row 0 is the image's bottom row (7, 3): occ 0.467 and 0.2, both unknown (0.2 >= 0.196); the
    # top row (15, 0): occ 1 (occupied) and 0 (free)
    assert grid_map.occupancy.tolist() == [[-1, -1], [100, 0]]
    assert grid_map.resolution_m == 0.05


def test_scale_and_raw_modes(tmp_path):
    image = b"P5\n4 1\n255\n" + bytes([0, 255, 153, 40])
    scale = load_grid_map(write(tmp_path, YAML + "mode: scale\n", image))
    # occ 1 -> 100, 0 -> 0, 0.4 -> rint(100 (0.4 - 0.25) / 0.4) = 38, 0.843 -> 100
    assert scale.occupancy.tolist() == [[100, 0, 38, 100]]
    raw = load_grid_map(write(tmp_path, YAML + "mode: raw\n", image))
    # round(255 shade) = the pixel value itself, unknown above 100
    assert raw.occupancy.tolist() == [[0, -1, -1, 40]]


def test_the_image_path_may_be_absolute(tmp_path):
    (tmp_path / "images").mkdir()
    image_path = tmp_path / "images" / "m.pgm"
    image_path.write_bytes(P5)
    grid_map = load_grid_map(write(tmp_path, YAML.replace("m.pgm", str(image_path))))
    assert grid_map.occupancy.shape == (2, 3)


def grid(seed: int) -> GridMap:
    rng = np.random.default_rng(seed)
    return GridMap(rng.integers(-1, 101, (6, 9)), 0.05, Transform2D(-0.2, -0.1, 0.0))


def test_a_failed_save_keeps_the_old_files_and_leaves_no_temporary(tmp_path):
    yaml_path = tmp_path / "map.yaml"
    save_grid_map(yaml_path, grid(0))
    before = yaml_path.read_bytes(), (tmp_path / "map.pgm").read_bytes()
    # the image's rename (the first) cannot replace a folder: nothing may change
    (tmp_path / "map.pgm").unlink()
    (tmp_path / "map.pgm").mkdir()
    with pytest.raises(IsADirectoryError):
        save_grid_map(yaml_path, grid(1))
    assert yaml_path.read_bytes() == before[0]
    assert sorted(os.listdir(tmp_path)) == ["map.pgm", "map.yaml"]


def test_an_image_from_another_save_is_refused(tmp_path):
    # what a crash between the two renames leaves: the new image beside the old yaml
    save_grid_map(tmp_path / "a" / "map.yaml", grid(0))
    save_grid_map(tmp_path / "b" / "map.yaml", grid(1))
    (tmp_path / "a" / "map.pgm").write_bytes((tmp_path / "b" / "map.pgm").read_bytes())
    with pytest.raises(ValueError, match=r"map.yaml: map.pgm is not the image this yaml was saved with"):
        load_grid_map(tmp_path / "a" / "map.yaml")
    # an image edited on purpose: without the hash line the pair loads
    yaml_path = tmp_path / "a" / "map.yaml"
    yaml_path.write_text(
        "".join(line for line in yaml_path.read_text().splitlines(True) if "sha256" not in line)
    )
    assert np.array_equal(
        load_grid_map(yaml_path).occupancy, load_grid_map(tmp_path / "b" / "map.yaml").occupancy
    )


@pytest.mark.parametrize(
    ("yaml_text", "image", "message"),
    [
        (YAML.replace("negate: 0\n", ""), P5, r"m.yaml: lacks the key\(s\) \['negate'\]"),
        (YAML + "resolution: 0.2\n", P5, "m.yaml: line 7: duplicate key 'resolution'"),
        (YAML.replace("0.1", "-0.1"), P5, "m.yaml: resolution must be > 0, got -0.1"),
        (YAML.replace("0.1", ".nan"), P5, r"m.yaml: resolution must be a finite number, got '.nan'"),
        (YAML.replace("[-1.0, 2.0, 0.5]", "[-1.0, 2.0]"), P5, r"m.yaml: origin must be a list \[x, y, yaw\]"),
        (YAML.replace("[-1.0, 2.0, 0.5]", "[-1.0, 2.0"), P5, r"m.yaml: line 3: origin: a list must end"),
        (YAML.replace("negate: 0", "negate: 2"), P5, "m.yaml: negate must be 0, 1, true or false, got '2'"),
        (YAML + "mode: bogus\n", P5, r"m.yaml: mode must be one of \('trinary', 'scale', 'raw'\)"),
        (
            YAML.replace("free_thresh: 0.25", "free_thresh: 1.5"),
            P5,
            r"m.yaml: free_thresh must be in \[0, 1\]",
        ),
        (YAML + "origin2:\n", P5, "m.yaml: line 7: origin2 has no value"),
        (YAML + "  x: 1\n", P5, "m.yaml: line 7: expected 'key: value' at the start of the line"),
        (YAML.replace("image: m.pgm", "image: 'm.pgm"), P5, "m.yaml: line 1: image: unterminated quoted"),
        (YAML, None, r"m.pgm: cannot read: \[Errno 2\]"),
        (YAML, b"P6\n3 2\n255\n" + bytes(18), r"m.pgm: not a PGM image \(magic b'P6'"),
        (YAML, P5[:-1], r"m.pgm: truncated: 5 of 6 pixels"),
        (YAML, b"P5\n3 2\n65535\n" + bytes(12), r"m.pgm: maxval must be 1..255 \(8-bit\), got 65535"),
        (YAML, b"P5\n3", r"m.pgm: truncated header"),
        (YAML, b"P2\n2 1\n15\n3\n", r"m.pgm: expected 2 pixel values, got 1 tokens"),
        (YAML, b"P2\n2 1\n15\n3 16\n", r"m.pgm: a pixel value 16 exceeds maxval 15"),
    ],
)
def test_malformed_files_are_refused_with_the_file_and_the_reason(tmp_path, yaml_text, image, message):
    with pytest.raises(ValueError, match=message):
        load_grid_map(write(tmp_path, yaml_text, image))


def test_invalid_saves_are_refused(tmp_path):
    with pytest.raises(ValueError, match="need free_thresh < occupied_thresh"):
        save_grid_map(tmp_path / "m.yaml", grid(0), free_thresh=0.7)
    with pytest.raises(ValueError, match="must end in .yaml"):
        save_grid_map(tmp_path / "m.yml", grid(0))
    with pytest.raises(ValueError, match=r"occupancy values must be -1 \(unknown\) or 0..100"):
        GridMap(np.full((2, 2), 101), 0.05, Transform2D())
    assert os.listdir(tmp_path) == []
