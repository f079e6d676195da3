"""Draw the shipped maps: ``python worlds/make_worlds.py`` writes worlds/maps/*.pgm and *.yaml.

The maps are ROS map_server maps (0.05 m cells; 0 black = occupied, 254 white = free,
205 grey = unknown, as map_saver writes them). Shapes are given in world metres with the room's
inner lower-left corner at (0, 0); a grey band outside the walls plays the part of the unseen
space around a real SLAM map. The world files beside this script (open_room.yaml...) place
robots, charging stations and unmapped obstacles in these maps; they are written by hand.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from services.sim.mapserver import map_yaml, write_pgm

RES = 0.05
WALL = 0.10  # wall thickness, m
MARGIN = 0.10  # unknown band outside the walls, m
FREE, OCCUPIED, UNKNOWN = 254, 0, 205


class Canvas:
    """A map being drawn, in world metres; ``pixels[row, col]`` with row 0 at the bottom."""

    def __init__(self, inner_w: float, inner_h: float) -> None:
        self.offset = WALL + MARGIN  # world (0, 0) sits this far inside the image corner
        w = round((inner_w + 2 * self.offset) / RES)
        h = round((inner_h + 2 * self.offset) / RES)
        self.pixels: npt.NDArray[np.uint8] = np.full((h, w), UNKNOWN, dtype=np.uint8)
        # walls all round, free inside
        self.rect(-WALL, -WALL, inner_w + WALL, inner_h + WALL, OCCUPIED)
        self.rect(0.0, 0.0, inner_w, inner_h, FREE)

    def _cell(self, v: float) -> int:
        return round((v + self.offset) / RES)

    def rect(self, x0: float, y0: float, x1: float, y1: float, value: int = OCCUPIED) -> None:
        self.pixels[self._cell(y0) : self._cell(y1), self._cell(x0) : self._cell(x1)] = value

    def disc(self, cx: float, cy: float, r: float, value: int = OCCUPIED) -> None:
        rows, cols = np.indices(self.pixels.shape)
        x = (cols + 0.5) * RES - self.offset
        y = (rows + 0.5) * RES - self.offset
        self.pixels[(x - cx) ** 2 + (y - cy) ** 2 <= r * r] = value

    def save(self, out: Path, name: str) -> None:
        out.mkdir(parents=True, exist_ok=True)
        # PGM row 0 is the top of the image: flip the bottom-up canvas
        write_pgm(out / f"{name}.pgm", np.flipud(self.pixels))
        origin = -self.offset
        (out / f"{name}.yaml").write_text(map_yaml(f"{name}.pgm", RES, origin, origin))


def open_room() -> Canvas:
    """5 x 5 m, nothing inside."""
    return Canvas(5.0, 5.0)


def cluttered_room() -> Canvas:
    """6 x 6 m with pillars, a table, a partition and a round column."""
    c = Canvas(6.0, 6.0)
    for x, y in ((1.5, 1.5), (4.5, 1.5), (1.5, 4.5), (4.5, 4.5)):
        c.rect(x - 0.15, y - 0.15, x + 0.15, y + 0.15)  # pillars
    c.rect(2.4, 2.7, 3.6, 3.3)  # a table in the middle
    c.rect(0.0, 3.0, 1.0, 3.1)  # a partition from the west wall
    c.rect(5.0, 2.0, 6.0, 2.1)  # and one from the east wall
    c.disc(3.0, 5.0, 0.2)  # a round column near the north wall
    return c


def warehouse() -> Canvas:
    """10 x 8 m: three double racks of shelves (1.0 x 1.9 m each half) with 1.2 m aisles
    between them, a 1.0 m cross aisle through the middle, a free staging area on the west
    side (where the chargers are) and a wide lane on the east side."""
    c = Canvas(10.0, 8.0)
    for x0 in (2.0, 4.2, 6.4):
        for y0, y1 in ((1.5, 3.4), (4.4, 6.3)):
            c.rect(x0, y0, x0 + 1.0, y1)
    c.rect(9.0, 7.0, 10.0, 8.0)  # a walled-off office corner (north-east)
    c.rect(8.55, 3.85, 8.85, 4.15)  # a structural column in the east lane
    return c


def main() -> None:
    out = Path(__file__).resolve().parent / "maps"
    for name, draw in (
        ("open_room", open_room),
        ("cluttered_room", cluttered_room),
        ("warehouse", warehouse),
    ):
        canvas = draw()
        canvas.save(out, name)
        h, w = canvas.pixels.shape
        print(f"{name}: {w}x{h} cells, {w * RES:.2f} x {h * RES:.2f} m")


if __name__ == "__main__":
    main()
