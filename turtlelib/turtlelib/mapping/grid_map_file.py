"""Occupancy grids in map_server's files: ``<name>.yaml`` (metadata) beside ``<name>.pgm`` (the image).

The format is nav2_map_server's (``map_io.cpp``: ``loadMapYaml``, ``loadMapFromFile``,
``tryWriteMapToFile``), the one nav2's map_server loads, map_saver writes and every TurtleBot3 tutorial
uses. The yaml is a flat mapping:

* ``image`` (string): the image file, relative to the yaml's folder unless absolute;
* ``resolution`` (m per pixel, > 0);
* ``origin`` ``[x, y, yaw]`` (m, m, rad): the pose in the map frame of the image's lower-left pixel's
  lower-left corner (``OccupancyGrid.info.origin``);
* ``negate`` (0 or 1, or a boolean): whether white means occupied;
* ``occupied_thresh``, ``free_thresh`` (in [0, 1]); ``mode`` (``trinary``, the default when absent,
  ``scale`` or ``raw``).

A pixel's ``shade`` is its grey value over the image's largest value (0 black, 1 white) and its
occupancy ``occ = shade`` if ``negate`` else ``1 - shade``. Then per mode (map_io's loader):

* trinary: 100 if ``occ > occupied_thresh``, 0 if ``occ < free_thresh``, else -1 (unknown);
* scale: the same, and in between ``rint(100 (occ - free_thresh) / (occupied_thresh - free_thresh))``
  (scale mode's transparent pixels are unknown; a PGM has no transparency);
* raw: ``round(255 shade)`` if it is 0..100, else -1 (raw mode ignores ``negate``).

Image row 0 is the TOP of the map: grid row ``r`` (along +y, row 0 at the origin) is image row
``height - 1 - r``.

Writing (:func:`save_grid_map`) follows map_saver in trinary mode: unknown cells (and any value outside
0..100) are grey 205, cells ``<= rint(100 free_thresh)`` white 254, cells ``>= rint(100 occupied_thresh)``
black 0, the rest grey 205; the image is an 8-bit binary PGM (P5). ``occupied_thresh`` defaults to
map_saver's 0.65, but ``free_thresh`` to ROS 1 map_saver's 0.196, not nav2's 0.25: with 0.25 the grey 205
of an unknown cell (``occ = 50 / 255 = 0.196``) reads back as FREE, so a planner would drive into
unexplored space (slam_toolbox issue 587); with 0.196 it reads back as unknown and 254 as free. The yaml
also carries a comment ``# image_sha256: <hex>``, the SHA-256 of the image's bytes (map_server ignores
comments), which :func:`load_grid_map` checks when present (delete that line after editing the image by
hand, e.g. to erase noise, as map users do).

Reading (:func:`load_grid_map`): the yaml subset map_server files use (``key: value`` lines, ``#``
comments, plain, single- or double-quoted scalars, ``[a, b, c]`` flow lists; nothing nested); PGM images
P5 (binary) and P2 (text), largest value 1..255, comments in the header. Anything else - a missing or
duplicated key, a value of the wrong type, a malformed or truncated image, an image that does not match
the hash the yaml recorded - raises ValueError starting with the file's path and naming the key.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Transform2D
from ..util.validation import in_range
from .atomic_files import replace_files
from .occupancy_grid import UNKNOWN, GridMap

MODES = ("trinary", "scale", "raw")
OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196
# map_saver's trinary pixels
OCCUPIED_PIXEL, FREE_PIXEL, UNKNOWN_PIXEL = 0, 254, 205
_HASH_COMMENT = "image_sha256"
_REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
# a plain YAML number (decimal, optional fraction and exponent) and YAML 1.1 / 1.2 booleans
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
_BOOLEANS = {"true": True, "false": False, "True": True, "False": False, "TRUE": True, "FALSE": False}


def save_grid_map(
    yaml_path: str | os.PathLike,
    grid_map: GridMap,
    *,
    occupied_thresh: float = OCCUPIED_THRESH,
    free_thresh: float = FREE_THRESH,
) -> Path:
    """Write ``grid_map`` as ``<name>.pgm`` and ``yaml_path`` (``<name>.yaml``) in trinary mode (module
    docstring); returns the image's path.

    Atomic per file (:func:`turtlelib.mapping.atomic_files.replace_files`): each is written to a temporary
    file in its folder, flushed and fsynced, then renamed onto its path; the image first, then the yaml. Until
    both temporary files are complete nothing is replaced (an error removes them and leaves the old files
    as they were). If the process dies between the two renames the folder holds the new image with the
    old yaml: the yaml's ``image_sha256`` then does not match and :func:`load_grid_map` refuses the pair
    rather than load the image with another save's resolution and origin. ValueError for thresholds not
    ``0 <= free_thresh < occupied_thresh <= 1``.
    """
    if not isinstance(grid_map, GridMap):
        raise ValueError(f"grid_map must be a GridMap, got {type(grid_map).__name__}")
    occupied_thresh = in_range("occupied_thresh", occupied_thresh, 0.0, 1.0)
    free_thresh = in_range("free_thresh", free_thresh, 0.0, 1.0)
    if not free_thresh < occupied_thresh:
        raise ValueError(f"need free_thresh < occupied_thresh, got {free_thresh}, {occupied_thresh}")
    yaml_path = Path(yaml_path)
    if yaml_path.suffix != ".yaml":
        raise ValueError(f"{yaml_path}: the map's metadata file must end in .yaml")
    image_path = yaml_path.with_suffix(".pgm")
    cells = grid_map.occupancy
    pixels = np.full(cells.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    pixels[(cells >= 0) & (cells <= round(100.0 * free_thresh))] = FREE_PIXEL
    pixels[(cells >= round(100.0 * occupied_thresh)) & (cells <= 100)] = OCCUPIED_PIXEL
    comment = f"# nuturtle occupancy grid, {grid_map.resolution_m!r} m/pixel"
    header = f"P5\n{comment}\n{cells.shape[1]} {cells.shape[0]}\n255\n"
    image = header.encode("ascii") + pixels[::-1].tobytes()
    origin = grid_map.origin
    metadata = (
        f"image: {image_path.name}\n"
        "mode: trinary\n"
        f"resolution: {grid_map.resolution_m!r}\n"
        f"origin: [{origin.x!r}, {origin.y!r}, {origin.theta!r}]\n"
        "negate: 0\n"
        f"occupied_thresh: {occupied_thresh!r}\n"
        f"free_thresh: {free_thresh!r}\n"
        f"# {_HASH_COMMENT}: {hashlib.sha256(image).hexdigest()}\n"
    )
    replace_files({image_path: image, yaml_path: metadata.encode("utf-8")})
    return image_path


def load_grid_map(yaml_path: str | os.PathLike) -> GridMap:
    """The grid of a map_server ``.yaml`` and its image, as map_server would publish it (module
    docstring); ValueError starting with the offending file's path for anything malformed."""
    yaml_path = Path(yaml_path)
    try:
        text = _read(yaml_path).decode("utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(f"{yaml_path}: not UTF-8 text: {error}") from None
    try:
        fields, image_hash = _parse_yaml(text)
        metadata = _metadata(fields)
    except ValueError as error:
        raise ValueError(f"{yaml_path}: {error}") from None
    image_path = Path(metadata["image"])
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path
    data = _read(image_path)
    if image_hash is not None and hashlib.sha256(data).hexdigest() != image_hash:
        raise ValueError(
            f"{yaml_path}: {image_path.name} is not the image this yaml was saved with ({_HASH_COMMENT} "
            "differs: a save interrupted between its two files? If the image was edited on purpose, delete "
            f"the '# {_HASH_COMMENT}' line)"
        )
    try:
        values, maxval = _parse_pgm(data)
    except ValueError as error:
        raise ValueError(f"{image_path}: {error}") from None
    shade = values[::-1].astype(np.float64) / maxval
    occupancy = _occupancy(shade, metadata)
    x, y, yaw = metadata["origin"]
    try:
        return GridMap(occupancy, metadata["resolution"], Transform2D(x, y, yaw))
    except ValueError as error:
        raise ValueError(f"{yaml_path}: {error}") from None


# --- helpers -------------------------------------------------------------------------------------------


def _occupancy(shade: NDArray[np.float64], metadata: dict) -> NDArray[np.int8]:
    """map_io's loader, per mode (module docstring)."""
    occupied, free = metadata["occupied_thresh"], metadata["free_thresh"]
    if metadata["mode"] == "raw":
        # std::round: halves away from zero
        value = np.floor(255.0 * shade + 0.5)
        return np.where(value <= 100.0, value, UNKNOWN).astype(np.int8)
    occ = shade if metadata["negate"] else 1.0 - shade
    if metadata["mode"] == "scale":
        with np.errstate(divide="ignore", invalid="ignore"):
            between = np.rint(100.0 * (occ - free) / (occupied - free))
        middle = np.clip(np.nan_to_num(between, nan=UNKNOWN), UNKNOWN, 100)
    else:
        middle = np.full(shade.shape, UNKNOWN)
    return np.where(occ > occupied, 100, np.where(occ < free, 0, middle)).astype(np.int8)


def _metadata(fields: dict[str, str | list[str]]) -> dict:
    """The yaml's fields checked and converted: ValueError naming the key."""
    missing = [key for key in _REQUIRED if key not in fields]
    if missing:
        raise ValueError(f"lacks the key(s) {missing}")
    image = fields["image"]
    if not isinstance(image, str) or not image:
        raise ValueError(f"image must be a file name, got {image!r}")
    resolution = _number("resolution", fields["resolution"])
    if not resolution > 0.0:
        raise ValueError(f"resolution must be > 0, got {resolution!r}")
    origin = fields["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise ValueError(f"origin must be a list [x, y, yaw], got {origin!r}")
    negate = fields["negate"]
    if negate in _BOOLEANS:
        negate = _BOOLEANS[negate]
    elif negate in ("0", "1"):
        negate = negate == "1"
    else:
        raise ValueError(f"negate must be 0, 1, true or false, got {negate!r}")
    thresholds = {key: _number(key, fields[key]) for key in ("occupied_thresh", "free_thresh")}
    for key, value in thresholds.items():
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"{key} must be in [0, 1], got {value!r}")
    mode = fields.get("mode", "trinary")
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    return {
        "image": image,
        "resolution": resolution,
        "origin": [_number(f"origin[{k}]", value) for k, value in enumerate(origin)],
        "negate": negate,
        "mode": mode,
        **thresholds,
    }


def _number(key: str, value: str | list[str]) -> float:
    if not isinstance(value, str) or not _NUMBER.fullmatch(value) or not math.isfinite(float(value)):
        raise ValueError(f"{key} must be a finite number, got {value!r}")
    return float(value)


def _parse_yaml(text: str) -> tuple[dict[str, str | list[str]], str | None]:
    """``({key: scalar or [scalars]}, image_sha256 or None)`` of the flat yaml subset (module docstring)."""
    fields: dict[str, str | list[str]] = {}
    image_hash = None
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped.startswith("#"):
            key, _, value = stripped[1:].partition(":")
            if key.strip() == _HASH_COMMENT:
                image_hash = value.strip()
            continue
        if not stripped or stripped in ("---", "..."):
            continue
        if line[0].isspace() or ":" not in line:
            raise ValueError(f"line {number}: expected 'key: value' at the start of the line, got {line!r}")
        key, _, value = line.partition(":")
        key = key.strip()
        if not key or key in fields:
            raise ValueError(f"line {number}: {'duplicate key ' + repr(key) if key else 'empty key'}")
        value = _strip_comment(value).strip()
        if value.startswith("["):
            if not value.endswith("]"):
                raise ValueError(f"line {number}: {key}: a list must end on its line with ']', got {value!r}")
            inner = value[1:-1].strip()
            fields[key] = [_scalar(item.strip(), key, number) for item in inner.split(",")] if inner else []
        else:
            fields[key] = _scalar(value, key, number)
    return fields, image_hash


def _strip_comment(value: str) -> str:
    """``value`` without a trailing `` # comment`` (a ``#`` after whitespace, outside quotes)."""
    quote = None
    for k, char in enumerate(value):
        if quote:
            if char == quote:
                quote = None
        elif char in "'\"":
            quote = char
        elif char == "#" and (k == 0 or value[k - 1].isspace()):
            return value[:k]
    return value


def _scalar(value: str, key: str, number: int) -> str:
    if not value:
        raise ValueError(f"line {number}: {key} has no value")
    if value[0] in "'\"":
        if len(value) < 2 or value[-1] != value[0]:
            raise ValueError(f"line {number}: {key}: unterminated quoted string {value!r}")
        return value[1:-1]
    if value[0] in "{[]}&*!|>%@`":
        raise ValueError(f"line {number}: {key}: unsupported yaml value {value!r}")
    return value


def _parse_pgm(data: bytes) -> tuple[NDArray[np.int64], int]:
    """``(values (height, width) in image order, maxval)`` of a P5 or P2 PGM; ValueError if malformed."""
    if data[:2] not in (b"P5", b"P2"):
        raise ValueError(f"not a PGM image (magic {data[:2]!r}, expected b'P5' or b'P2')")
    numbers: list[int] = []
    position = 2
    while len(numbers) < 3:
        if position >= len(data):
            raise ValueError("truncated header")
        char = data[position : position + 1]
        if char == b"#":
            end = data.find(b"\n", position)
            position = len(data) if end < 0 else end + 1
        elif char.isspace():
            position += 1
        else:
            match = re.compile(rb"\d+").match(data, position)
            if match is None or (
                match.end() < len(data) and not data[match.end() : match.end() + 1].isspace()
            ):
                raise ValueError(f"malformed header at byte {position}")
            numbers.append(int(match.group()))
            position = match.end()
    width, height, maxval = numbers
    if width < 1 or height < 1:
        raise ValueError(f"empty image ({width} x {height})")
    if not 1 <= maxval <= 255:
        raise ValueError(f"maxval must be 1..255 (8-bit), got {maxval}")
    if data[:2] == b"P5":
        raster = data[position + 1 : position + 1 + width * height]  # one whitespace byte ends the header
        if len(raster) != width * height:
            raise ValueError(f"truncated: {len(raster)} of {width * height} pixels")
        values = np.frombuffer(raster, dtype=np.uint8).astype(np.int64)
    else:
        tokens = re.sub(rb"#[^\n]*", b" ", data[position:]).split()
        if len(tokens) != width * height or not all(token.isdigit() for token in tokens):
            raise ValueError(f"expected {width * height} pixel values, got {len(tokens)} tokens")
        values = np.array([int(token) for token in tokens], dtype=np.int64)
    if values.max() > maxval:
        raise ValueError(f"a pixel value {values.max()} exceeds maxval {maxval}")
    return values.reshape(height, width), maxval


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as error:
        raise ValueError(f"{path}: cannot read: {error}") from None
