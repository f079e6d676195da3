"""ROS map_server maps: the YAML description, the PGM image, and the occupancy grid they make.

A map is a YAML file such as::

    image: warehouse.pgm          # relative to the YAML file
    resolution: 0.05              # metres per cell
    origin: [0.0, 0.0, 0.0]       # world pose of the lower-left pixel: x, y, yaw
    occupied_thresh: 0.65
    free_thresh: 0.196
    negate: 0
    mode: trinary                 # optional; the only mode supported

and a PGM image (P5 binary or P2 ascii). With the 'trinary' semantics of map_server, a pixel
of value ``v`` (scaled to 0-255) has occupancy ``p = (255 - v) / 255`` (``v / 255`` when
``negate``): occupied if ``p > occupied_thresh``, free if ``p < free_thresh``, else unknown.

PGM row 0 is the *top* of the image, while the grid the contract publishes has row 0 at the
*bottom* (at ``origin_y``), so the image is flipped on load. PIL is not needed: PGM is a
header and a block of bytes, read and written here.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from common import yamldoc
from common.errors import WorldError

FREE = 0
OCCUPIED = 100
UNKNOWN = 255

REQUIRED_KEYS = ("image", "resolution", "origin", "occupied_thresh", "free_thresh", "negate")
# what map_server's YAML may hold besides: any other key is refused, naming the closest one
KNOWN_KEYS = (*REQUIRED_KEYS, "mode")


# -- PGM -------------------------------------------------------------------------------------
def _header_tokens(data: bytes, count: int) -> tuple[list[bytes], int]:
    """The first ``count`` whitespace-separated header tokens (skipping # comments) and the
    offset just past the last one."""
    tokens: list[bytes] = []
    pos = 0
    n = len(data)
    while len(tokens) < count:
        while pos < n and data[pos : pos + 1].isspace():
            pos += 1
        if pos >= n:
            raise ValueError("truncated PGM header")
        if data[pos : pos + 1] == b"#":
            while pos < n and data[pos : pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < n and not data[pos : pos + 1].isspace() and data[pos : pos + 1] != b"#":
            pos += 1
        tokens.append(data[start:pos])
    return tokens, pos


def parse_pgm(data: bytes) -> npt.NDArray[np.uint8]:
    """Pixels of a P5 or P2 PGM, shape (rows, cols), row 0 at the top, scaled to 0-255.

    Raises ValueError on anything that is not a well-formed PGM.
    """
    tokens, pos = _header_tokens(data, 4)
    magic = tokens[0]
    if magic not in (b"P5", b"P2"):
        raise ValueError(f"not a PGM image (magic {magic[:2]!r}, expected P5 or P2)")
    try:
        width, height, maxval = (int(t) for t in tokens[1:4])
    except ValueError:
        raise ValueError("PGM header has a non-numeric width, height or maxval") from None
    if width <= 0 or height <= 0 or not 0 < maxval < 65536:
        raise ValueError(f"bad PGM header: width={width} height={height} maxval={maxval}")
    count = width * height
    if magic == b"P5":
        pos += 1  # exactly one whitespace byte separates the header from the raster
        dtype = np.dtype(np.uint8) if maxval < 256 else np.dtype(">u2")
        raw = data[pos : pos + count * dtype.itemsize]
        if len(raw) < count * dtype.itemsize:
            raise ValueError(f"PGM raster too short: {len(raw)} bytes for {width}x{height}")
        values = np.frombuffer(raw, dtype=dtype).astype(np.int64)
    else:
        body = data[pos:].split()
        # comments may also appear in the ascii raster
        words = [w for w in body if not w.startswith(b"#")]
        if len(words) < count:
            raise ValueError(f"PGM raster too short: {len(words)} values for {width}x{height}")
        try:
            values = np.array([int(w) for w in words[:count]], dtype=np.int64)
        except ValueError:
            raise ValueError("PGM ascii raster has a non-numeric value") from None
    if values.size and (values.min() < 0 or values.max() > maxval):
        raise ValueError(f"PGM value outside 0..{maxval}")
    if maxval != 255:
        # map_server reads 8-bit pixels; rescale other depths to 0-255 the same way
        values = (values * 255 + maxval // 2) // maxval
    return values.astype(np.uint8).reshape(height, width)


def read_pgm(path: Path) -> npt.NDArray[np.uint8]:
    return parse_pgm(path.read_bytes())


def encode_pgm(pixels: npt.NDArray[np.uint8], *, binary: bool = True) -> bytes:
    """A PGM (P5, or P2 when not ``binary``) of ``pixels``, shape (rows, cols), row 0 on top."""
    arr = np.asarray(pixels, dtype=np.uint8)
    height, width = arr.shape
    if binary:
        return f"P5\n{width} {height}\n255\n".encode() + arr.tobytes()
    lines = [f"P2\n{width} {height}\n255"]
    lines += [" ".join(str(int(v)) for v in row) for row in arr]
    return ("\n".join(lines) + "\n").encode()


def write_pgm(path: Path, pixels: npt.NDArray[np.uint8], *, binary: bool = True) -> None:
    path.write_bytes(encode_pgm(pixels, binary=binary))


def map_yaml(image: str, resolution: float, origin_x: float, origin_y: float) -> str:
    """The map_server YAML of a trinary map whose pixels are map_saver's 0 / 205 / 254."""
    return (
        f"image: {image}\nresolution: {resolution}\norigin: [{origin_x}, {origin_y}, 0.0]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n"
    )


# -- the grid ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class OccupancyGrid:
    """A ROS-style occupancy grid: ``cells[row, col]``, row 0 at the bottom (``origin_y``)."""

    cells: npt.NDArray[np.uint8]  # FREE, OCCUPIED or UNKNOWN
    resolution: float
    origin: tuple[float, float, float]
    source: str

    @property
    def width(self) -> int:
        return int(self.cells.shape[1])

    @property
    def height(self) -> int:
        return int(self.cells.shape[0])

    def to_bytes(self) -> bytes:
        """Row-major bytes, row 0 at the bottom: the contract's ``map.grid``."""
        return self.cells.tobytes()

    def cell_to_world(self, col: float, row: float) -> tuple[float, float]:
        """World position of grid coordinates (cell centres are at +0.5)."""
        ox, oy, oyaw = self.origin
        lx, ly = col * self.resolution, row * self.resolution
        c, s = math.cos(oyaw), math.sin(oyaw)
        return ox + c * lx - s * ly, oy + s * lx + c * ly

    def world_to_cell(self, x: float, y: float) -> tuple[float, float]:
        """Fractional (col, row) of a world position; floor them to index ``cells``."""
        ox, oy, oyaw = self.origin
        dx, dy = x - ox, y - oy
        c, s = math.cos(oyaw), math.sin(oyaw)
        return (c * dx + s * dy) / self.resolution, (-s * dx + c * dy) / self.resolution

    def contains(self, x: float, y: float) -> bool:
        col, row = self.world_to_cell(x, y)
        return 0.0 <= col < self.width and 0.0 <= row < self.height

    def value_at(self, x: float, y: float) -> int | None:
        """The cell value under a world position, None outside the map."""
        if not self.contains(x, y):
            return None
        col, row = self.world_to_cell(x, y)
        return int(self.cells[int(row), int(col)])

    def occupied_near(self, x: float, y: float, radius: float) -> bool:
        """Whether any occupied cell overlaps the disc of ``radius`` around (x, y)."""
        col, row = self.world_to_cell(x, y)
        r_cells = radius / self.resolution
        c0, c1 = max(0, int(col - r_cells) - 1), min(self.width, int(col + r_cells) + 2)
        r0, r1 = max(0, int(row - r_cells) - 1), min(self.height, int(row + r_cells) + 2)
        if c0 >= c1 or r0 >= r1:
            return False
        window = self.cells[r0:r1, c0:c1]
        rows, cols = np.nonzero(window == OCCUPIED)
        if rows.size == 0:
            return False
        # distance from the disc centre to each occupied cell's square, in cells
        cx = np.clip(col, cols + c0, cols + c0 + 1) - col
        cy = np.clip(row, rows + r0, rows + r0 + 1) - row
        return bool(np.any(cx * cx + cy * cy < r_cells * r_cells))

    def occupied_rectangles(self) -> list[tuple[int, int, int, int]]:
        """Occupied cells merged into few rectangles ``(col0, row0, col1, row1)``, ends
        exclusive: runs per row first, then identical runs of consecutive rows are stacked.
        This keeps the pybullet body count to tens instead of thousands."""
        done: list[tuple[int, int, int, int]] = []
        open_rects: dict[tuple[int, int], int] = {}  # (col0, col1) -> row0
        for row in range(self.height + 1):
            runs = set(_runs(self.cells[row] == OCCUPIED)) if row < self.height else set()
            for span in list(open_rects):
                if span not in runs:
                    done.append((span[0], open_rects.pop(span), span[1], row))
            for span in runs:
                open_rects.setdefault(span, row)
        done.sort(key=lambda r: (r[1], r[0]))
        return done


def _runs(mask: npt.NDArray[np.bool_]) -> Iterator[tuple[int, int]]:
    """(start, end) of each run of True in a 1-D mask, end exclusive."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    for start, end in zip(edges[0::2], edges[1::2], strict=True):
        yield int(start), int(end)


def classify(
    pixels: npt.NDArray[np.uint8], occupied_thresh: float, free_thresh: float, negate: bool
) -> npt.NDArray[np.uint8]:
    """map_server 'trinary' semantics; returns cells in image order (row 0 on top)."""
    value = pixels.astype(np.float64)
    p = value / 255.0 if negate else (255.0 - value) / 255.0
    cells = np.full(pixels.shape, UNKNOWN, dtype=np.uint8)
    cells[p > occupied_thresh] = OCCUPIED
    cells[p < free_thresh] = FREE
    return cells


def _number(doc: dict[str, Any], key: str, where: Path) -> float:
    value = doc[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise WorldError(f"{where}: '{key}' must be a finite number, got {value!r}")
    return float(value)


def load_map(path: str | Path) -> OccupancyGrid:
    """Load a map_server YAML and its image; WorldError names the file and the problem."""
    path = Path(path)
    doc = _read_yaml(path)
    resolution = _number(doc, "resolution", path)
    if resolution <= 0:
        raise WorldError(f"{path}: resolution must be positive, got {resolution}")
    origin = _origin(doc, path)
    occupied, free, negate = _thresholds(doc, path)
    pixels = _image(doc, path)
    cells = classify(pixels, occupied, free, negate)
    return OccupancyGrid(
        cells=np.ascontiguousarray(np.flipud(cells)),
        resolution=resolution,
        origin=origin,
        source=str(path),
    )


def _read_yaml(path: Path) -> dict[str, Any]:
    try:
        doc = yamldoc.load(path.read_text())
    except FileNotFoundError:
        raise WorldError(f"{path}: map file not found") from None
    except (OSError, yaml.YAMLError) as exc:
        raise WorldError(f"{path}: cannot read map YAML: {exc}") from None
    if not isinstance(doc, dict):
        raise WorldError(f"{path}: a map YAML must be a mapping with keys {REQUIRED_KEYS}")
    missing = [k for k in REQUIRED_KEYS if k not in doc]
    if missing:
        raise WorldError(f"{path}: missing required key(s) {', '.join(missing)}")
    key = yamldoc.unknown_key(doc, KNOWN_KEYS)
    if key is not None:
        raise WorldError(f"{path}: {yamldoc.unknown_key_problem(key, KNOWN_KEYS)}")
    return doc


def _origin(doc: dict[str, Any], path: Path) -> tuple[float, float, float]:
    origin = doc["origin"]
    if (
        not isinstance(origin, list | tuple)
        or len(origin) != 3
        or not all(isinstance(v, int | float) and math.isfinite(v) for v in origin)
    ):
        raise WorldError(f"{path}: origin must be [x, y, yaw] numbers, got {origin!r}")
    return float(origin[0]), float(origin[1]), float(origin[2])


def _thresholds(doc: dict[str, Any], path: Path) -> tuple[float, float, bool]:
    """``(occupied_thresh, free_thresh, negate)``, checked; only the trinary mode is read."""
    occupied = _number(doc, "occupied_thresh", path)
    free = _number(doc, "free_thresh", path)
    for key, value in (("occupied_thresh", occupied), ("free_thresh", free)):
        if not 0.0 <= value <= 1.0:
            raise WorldError(f"{path}: {key} must be within [0, 1], got {value}")
    if free >= occupied:
        raise WorldError(f"{path}: free_thresh ({free}) must be below occupied_thresh ({occupied})")
    negate = doc["negate"]
    if negate not in (0, 1, True, False):
        raise WorldError(f"{path}: negate must be 0 or 1, got {negate!r}")
    mode = doc.get("mode", "trinary")
    if mode != "trinary":
        raise WorldError(f"{path}: mode {mode!r} is not supported (only 'trinary')")
    return occupied, free, bool(negate)


def _image(doc: dict[str, Any], path: Path) -> npt.NDArray[np.uint8]:
    image = doc["image"]
    if not isinstance(image, str) or not image:
        raise WorldError(f"{path}: image must be a file name, got {image!r}")
    image_path = path.parent / image
    if not image_path.is_file():
        raise WorldError(f"{path}: image {image_path} not found")
    try:
        return read_pgm(image_path)
    except (OSError, ValueError) as exc:
        raise WorldError(f"{path}: image {image_path}: {exc} (only PGM P5/P2 is read)") from None
