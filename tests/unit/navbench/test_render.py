"""The PNG writer makes valid PNGs, and the world picture puts things where they belong."""

from __future__ import annotations

import math
import struct
import zlib
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
import yaml

from pnav.bench.nav import render
from pnav.bench.nav.png import encode_png, write_png
from pnav.bench.nav.render import draw_run, draw_world, render_run
from pnav.bench.nav.worldfile import load_suite, read_benchmark
from services.sim.mapserver import encode_pgm, map_yaml

pytestmark = pytest.mark.timeout(20)

SUITE = Path(__file__).resolve().parents[3] / "worlds" / "barn"


def decode_png(data: bytes) -> tuple[dict[str, int], npt.NDArray[np.uint8]]:
    """Parse a PNG by the book: signature, chunks with their CRCs, IHDR, IDAT, IEND."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, chunks = 8, []
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length : pos + 12 + length])
        assert crc == zlib.crc32(kind + body), f"bad CRC in {kind!r}"
        chunks.append((kind, body))
        pos += 12 + length
    assert pos == len(data)
    kinds = [k for k, _ in chunks]
    assert kinds[0] == b"IHDR" and kinds[-1] == b"IEND" and b"IDAT" in kinds
    width, height, depth, colour, comp, filt, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
    header = {"width": width, "height": height, "depth": depth, "colour": colour}
    assert (comp, filt, interlace) == (0, 0, 0)
    raw = zlib.decompress(b"".join(body for kind, body in chunks if kind == b"IDAT"))
    assert len(raw) == height * (1 + 3 * width)
    rows = np.frombuffer(raw, dtype=np.uint8).reshape(height, 1 + 3 * width)
    assert (rows[:, 0] == 0).all(), "rows use filter type 0"
    return header, rows[:, 1:].reshape(height, width, 3)


def test_png_round_trip(tmp_path: Path) -> None:
    image = np.zeros((7, 11, 3), dtype=np.uint8)
    image[0, 0] = (255, 0, 0)  # top-left red
    image[6, 10] = (0, 0, 255)  # bottom-right blue
    image[3, :, 1] = np.arange(11) * 20
    header, pixels = decode_png(encode_png(image))
    assert header == {"width": 11, "height": 7, "depth": 8, "colour": 2}
    assert np.array_equal(pixels, image)
    write_png(tmp_path / "x.png", image)
    assert (tmp_path / "x.png").read_bytes() == encode_png(image)
    for bad in (np.zeros((4, 4), dtype=np.uint8), np.zeros((0, 4, 3), dtype=np.uint8)):
        with pytest.raises(ValueError):
            encode_png(bad)


def test_world_picture_places_things_by_world_coordinates() -> None:
    occupied = np.zeros((20, 30), dtype=bool)  # 0.1 m cells: 3 x 2 m
    occupied[0, :] = True  # the bottom row
    image = draw_world(
        occupied,
        0.1,
        (0.0, 0.0),
        reference_path=[(0.5, 1.0), (2.5, 1.0)],
        trajectory=[(0.5, 1.5), (2.5, 1.5)],
        collisions=[(2.0, 0.5)],
        start=(0.5, 0.5),
        goal=(2.5, 1.8),
        scale=5,
    )
    assert image.shape == (100, 150, 3)

    def at(x: float, y: float) -> tuple[int, ...]:
        return tuple(int(v) for v in image[int(100 - y * 50), int(x * 50)])

    assert at(1.5, 0.05) == render.OCCUPIED  # row 0 of the grid is the image's bottom
    assert at(1.5, 1.95) == render.FREE
    assert at(1.5, 1.0) == render.REFERENCE
    assert at(1.5, 1.5) == render.TRAJECTORY
    assert at(2.0, 0.5) == render.COLLISION
    assert at(0.5, 0.5) == render.START
    assert at(2.5, 1.8) == render.GOAL
    assert at(2.5 - 0.3, 1.8) == render.GOAL  # on the tolerance ring
    with pytest.raises(ValueError):
        draw_world(occupied, 0.1, (0.0, 0.0), scale=0)


def test_run_picture_of_a_shipped_world(tmp_path: Path) -> None:
    world = load_suite(SUITE)[0]
    trajectory = [world.start[:2], (world.start[0], world.start[1] + 1.0)]
    image = draw_run(world, trajectory=trajectory, collisions=[trajectory[-1]], scale=4)
    grid = world.grid()
    # the map on top, the legend strip under it
    assert image.shape[1:] == (grid.width * 4, 3) and image.shape[0] > grid.height * 4
    colours = {tuple(int(v) for v in c) for c in image[: grid.height * 4].reshape(-1, 3)}
    for colour in (render.OCCUPIED, render.UNREACHABLE, render.FREE, render.REFERENCE):
        assert colour in colours
    for colour in (render.TRAJECTORY, render.COLLISION, render.START, render.GOAL):
        assert colour in colours
    out = render_run(tmp_path / "pics" / "run.png", world, trajectory=trajectory)
    header, pixels = decode_png(out.read_bytes())
    assert header["width"] == grid.width * 4 and header["height"] > grid.height * 4
    assert render.COLLISION not in {tuple(int(v) for v in c) for c in pixels.reshape(-1, 3)}


def test_a_world_whose_obstacles_are_all_unmapped_shows_them(tmp_path: Path) -> None:
    """A shipped world's file with an empty map and a box and a cylinder in its
    ``obstacles``: the report picture shows both where they stand, in the unmapped colour,
    and the map's own cells stay free."""
    shipped = load_suite(SUITE)[0]
    doc = yaml.safe_load(shipped.world_file.read_text())
    grid = shipped.grid()
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "empty.pgm").write_bytes(
        encode_pgm(np.full((grid.height, grid.width), 254, dtype=np.uint8))
    )
    (tmp_path / "maps" / "empty.yaml").write_text(
        map_yaml("empty.pgm", grid.resolution, grid.origin[0], grid.origin[1])
    )
    sx, sy = shipped.start[:2]
    box, post = (sx + 1.5, sy), (sx + 1.5, sy + 1.0)  # clear of the start
    doc["map"] = "maps/empty.yaml"
    doc["obstacles"] = [
        {"name": "crate", "type": "box", "x": box[0], "y": box[1], "yaw": math.pi / 4,
         "size": [0.4, 0.2, 0.3]},
        {"name": "post", "type": "cylinder", "x": post[0], "y": post[1], "radius": 0.1},
    ]  # fmt: skip
    (tmp_path / "w.yaml").write_text(yaml.safe_dump(doc))
    world = read_benchmark(tmp_path / "w.yaml")
    assert [ob.name for ob in world.obstacles] == ["crate", "post"]
    image = draw_run(world, scale=4)
    map_h = grid.height * 4
    per_m = 4 / grid.resolution

    def at(x: float, y: float) -> tuple[int, ...]:
        row = int(map_h - (y - grid.origin[1]) * per_m)
        return tuple(int(v) for v in image[row, int((x - grid.origin[0]) * per_m)])

    assert at(*box) == render.UNMAPPED  # the box's centre
    assert at(box[0] + 0.12, box[1] + 0.12) == render.UNMAPPED  # along its long side (45 deg)
    assert at(box[0] + 0.12, box[1] - 0.12) != render.UNMAPPED  # beyond its short side
    assert at(*post) == render.UNMAPPED and at(post[0] + 0.08, post[1]) == render.UNMAPPED
    assert at(post[0] + 0.14, post[1]) != render.UNMAPPED  # just outside the post
    assert render.OCCUPIED not in colours_of(image[:map_h])  # nothing is on the map
    assert render.UNMAPPED in colours_of(image[map_h:])  # the legend's swatch


def test_legend_lists_unmapped_obstacles_only_when_there_are_some() -> None:
    occupied = np.zeros((10, 10), dtype=bool)
    plain = draw_world(occupied, 0.1, (0.0, 0.0), scale=4, legend=True)
    assert plain.shape[0] > 40 and render.UNMAPPED not in colours_of(plain)
    assert render.OCCUPIED in colours_of(plain[40:])  # the map-obstacle swatch


def colours_of(image: npt.NDArray[np.uint8]) -> set[tuple[int, ...]]:
    return {tuple(int(v) for v in c) for c in image.reshape(-1, 3)}
