"""Pictures of a world: the map, the reference path, a driven trajectory and its collisions.

Colours (also in docs/NAVBENCH.md): occupied cells dark grey; free cells the robot's centre
cannot reach (within the footprint plus margin of an obstacle) light grey; free white; the
reference path green; the driven trajectory blue; the start a green disc of the robot's size;
the goal an orange dot inside an orange ring of the goal tolerance; each collision a red
cross in a red ring; the world's unmapped obstacles (in the world file, not on the map: only the
lidar sees them) purple, their true shape; each moving obstacle's track (services/sim/mover.py)
a light band as wide as its body along its path, the path itself dark pink, and its body where
it is at sim time 0 dark pink too. North (+y) is up. A legend strip under the picture
names every colour (pnav/bench/nav/legend.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

from pnav.bench.nav.generator import ORIGIN, GeneratedWorld
from pnav.bench.nav.legend import with_legend
from pnav.bench.nav.png import encode_png
from pnav.bench.nav.search import BoolGrid, Point, inflate
from pnav.bench.nav.worldfile import BenchmarkWorld, occupied_cells
from services.sim.mover import MoverSpec
from services.sim.world_spec import ObstacleSpec

Colour = tuple[int, int, int]
Image = npt.NDArray[np.uint8]

FREE: Colour = (255, 255, 255)
UNREACHABLE: Colour = (226, 226, 226)
OCCUPIED: Colour = (45, 45, 45)
REFERENCE: Colour = (20, 160, 60)
TRAJECTORY: Colour = (30, 100, 235)
COLLISION: Colour = (225, 20, 20)
START: Colour = (20, 160, 60)
GOAL: Colour = (240, 130, 0)
UNMAPPED: Colour = (150, 60, 200)
MOVER: Colour = (200, 30, 120)
MOVER_BAND: Colour = (245, 200, 225)


class Canvas:
    """An RGB image of a grid map, ``scale`` image pixels per map cell, drawn in metres."""

    def __init__(
        self,
        occupied: BoolGrid,
        resolution: float,
        origin: Point,
        *,
        scale: int = 4,
        inflation_m: float | None = None,
    ) -> None:
        if scale < 1:
            raise ValueError(f"scale must be at least 1, got {scale}")
        self.resolution, self.origin, self.scale = resolution, origin, scale
        cells = np.empty((*occupied.shape, 3), dtype=np.uint8)
        cells[...] = FREE
        if inflation_m:
            cells[inflate(occupied, resolution, inflation_m)] = UNREACHABLE
        cells[occupied] = OCCUPIED
        # image row 0 is the top: flip the bottom-up grid, then blow every cell up
        self.image: Image = np.repeat(np.repeat(cells[::-1], scale, axis=0), scale, axis=1)

    def to_px(self, points: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], ...]:
        """Image (rows, cols), fractional, of world points of shape (n, 2)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        per_m = self.scale / self.resolution
        cols = (pts[:, 0] - self.origin[0]) * per_m
        rows = self.image.shape[0] - (pts[:, 1] - self.origin[1]) * per_m
        return rows, cols

    def stamp(
        self,
        rows: npt.NDArray[np.float64],
        cols: npt.NDArray[np.float64],
        radius_px: float,
        colour: Colour,
    ) -> None:
        """A filled disc of ``radius_px`` at every image position given."""
        reach = max(0, math.floor(radius_px))
        dy, dx = np.mgrid[-reach : reach + 1, -reach : reach + 1]
        keep = dy * dy + dx * dx <= max(radius_px, 0.5) ** 2
        rr = (np.floor(rows).astype(np.int64)[:, None] + dy[keep][None, :]).ravel()
        cc = (np.floor(cols).astype(np.int64)[:, None] + dx[keep][None, :]).ravel()
        height, width = self.image.shape[:2]
        inside = (rr >= 0) & (rr < height) & (cc >= 0) & (cc < width)
        self.image[rr[inside], cc[inside]] = colour

    def polyline(self, points: Sequence[Point], colour: Colour, width_px: float = 2.0) -> None:
        if len(points) == 0:
            return
        rows, cols = self.to_px(points)
        if len(rows) == 1:
            self.stamp(rows, cols, width_px / 2.0, colour)
            return
        # half-pixel samples along every segment leave no gaps
        seg = np.hypot(np.diff(rows), np.diff(cols))
        along = np.concatenate(([0.0], np.cumsum(seg)))
        s = np.linspace(0.0, along[-1], max(2, math.ceil(along[-1] * 2.0) + 1))
        self.stamp(np.interp(s, along, rows), np.interp(s, along, cols), width_px / 2.0, colour)

    def disc(self, centre: Point, radius_m: float, colour: Colour) -> None:
        rows, cols = self.to_px([centre])
        self.stamp(rows, cols, radius_m / self.resolution * self.scale, colour)

    def obstacle(self, ob: ObstacleSpec, colour: Colour) -> None:
        """Fill the pixels whose centre lies inside an obstacle's footprint (a box turned by
        its yaw, or a cylinder's disc); at least its centre pixel, however small it is."""
        sx, sy, _ = ob.size
        reach = math.hypot(sx, sy) / 2.0
        rows, cols = self.to_px([(ob.x - reach, ob.y + reach), (ob.x + reach, ob.y - reach)])
        height, width = self.image.shape[:2]
        r0, r1 = max(0, math.floor(rows[0])), min(height, math.ceil(rows[1]) + 1)
        c0, c1 = max(0, math.floor(cols[0])), min(width, math.ceil(cols[1]) + 1)
        if r0 < r1 and c0 < c1:
            per_m = self.scale / self.resolution
            rr, cc = np.mgrid[r0:r1, c0:c1]
            dx = self.origin[0] + (cc + 0.5) / per_m - ob.x
            dy = self.origin[1] + (height - (rr + 0.5)) / per_m - ob.y
            if ob.shape == "cylinder":
                inside = np.hypot(dx, dy) <= sx / 2.0
            else:
                c, s = math.cos(-ob.yaw), math.sin(-ob.yaw)
                inside = (np.abs(c * dx - s * dy) <= sx / 2.0) & (
                    np.abs(s * dx + c * dy) <= sy / 2.0
                )
            self.image[rr[inside], cc[inside]] = colour
        centre_rows, centre_cols = self.to_px([(ob.x, ob.y)])
        self.stamp(centre_rows, centre_cols, 0.5, colour)

    def mover(self, mover: MoverSpec) -> None:
        """A mover's track: the band its body sweeps, its path, and its body at sim time 0."""
        track = [*mover.path, mover.path[0]] if mover.mode == "loop" else list(mover.path)
        across = mover.size[1] if mover.shape == "box" else mover.size[0]
        self.polyline(track, MOVER_BAND, across / self.resolution * self.scale)
        self.polyline(track, MOVER, 2.0)
        x, y, heading = mover.pose_at(0.0)
        sx, sy, sz = mover.size
        self.obstacle(ObstacleSpec(mover.name, mover.shape, x, y, heading, (sx, sy, sz)), MOVER)

    def ring(self, centre: Point, radius_m: float, colour: Colour, width_px: float = 2.0) -> None:
        n = max(16, math.ceil(2 * math.pi * radius_m / self.resolution * self.scale * 2))
        t = np.linspace(0.0, 2.0 * math.pi, n + 1)
        circle = [
            (centre[0] + radius_m * math.cos(a), centre[1] + radius_m * math.sin(a)) for a in t
        ]
        self.polyline(circle, colour, width_px)

    def cross(self, centre: Point, half_m: float, colour: Colour, width_px: float = 2.0) -> None:
        x, y = centre
        self.polyline([(x - half_m, y - half_m), (x + half_m, y + half_m)], colour, width_px)
        self.polyline([(x - half_m, y + half_m), (x + half_m, y - half_m)], colour, width_px)


def draw_world(
    occupied: BoolGrid,
    resolution: float,
    origin: Point,
    *,
    reference_path: Sequence[Point] = (),
    trajectory: Sequence[Point] = (),
    collisions: Sequence[Point] = (),
    start: Point | None = None,
    goal: Point | None = None,
    goal_tolerance_m: float = 0.3,
    footprint_radius_m: float = 0.105,
    inflation_m: float | None = None,
    obstacles: Sequence[ObstacleSpec] = (),
    movers: Sequence[MoverSpec] = (),
    scale: int = 4,
    legend: bool = False,
) -> Image:
    """The picture (height, width, 3) of a world and, optionally, of one run in it;
    ``obstacles``: the world's unmapped ones; ``movers``: its moving obstacles, drawn as
    their tracks; ``legend``: add the colour key under it."""
    canvas = Canvas(occupied, resolution, origin, scale=scale, inflation_m=inflation_m)
    for ob in obstacles:
        canvas.obstacle(ob, UNMAPPED)
    for mover in movers:
        canvas.mover(mover)
    canvas.polyline(reference_path, REFERENCE, 2.0)
    canvas.polyline(trajectory, TRAJECTORY, 2.0)
    if start is not None:
        canvas.disc(start, footprint_radius_m, START)
    if goal is not None:
        canvas.ring(goal, goal_tolerance_m, GOAL, 2.0)
        canvas.disc(goal, 0.04, GOAL)
    for point in collisions:  # last, so nothing hides them
        canvas.ring(point, 0.12, COLLISION, 2.0)
        canvas.cross(point, 0.08, COLLISION, 2.0)
    if not legend:
        return canvas.image
    key = _key(inflation_m, bool(obstacles), bool(collisions), bool(movers))
    return with_legend(canvas.image, key)


def _key(
    inflation: float | None, unmapped: bool, collisions: bool, movers: bool = False
) -> list[tuple[Colour, str]]:
    """The legend's entries: every colour the picture may show (the optional ones when used)."""
    key = [(OCCUPIED, "map obstacle")]
    if unmapped:
        key.append((UNMAPPED, "unmapped obstacle"))
    if movers:
        key += [(MOVER, "mover"), (MOVER_BAND, "mover track")]
    if inflation:
        key.append((UNREACHABLE, "too close"))
    key += [(REFERENCE, "reference"), (TRAJECTORY, "driven"), (GOAL, "goal")]
    if collisions:
        key.append((COLLISION, "collision"))
    return key


def write_world_png(path: Path, image: Image) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(encode_png(image))
    return path


def draw_generated(world: GeneratedWorld, *, scale: int = 4) -> Image:
    """A freshly generated world: map, reference path, start and goal."""
    return draw_world(
        world.occupied,
        world.layout.resolution_m,
        ORIGIN,
        reference_path=world.reference.points,
        start=world.start[:2],
        goal=world.goal,
        footprint_radius_m=world.layout.footprint_radius_m,
        inflation_m=world.layout.inflation_m,
        scale=scale,
    )


def draw_run(
    world: BenchmarkWorld,
    *,
    trajectory: Sequence[Point] = (),
    collisions: Sequence[Point] = (),
    scale: int = 4,
) -> Image:
    """A benchmark world from its files, with one run's trajectory and collisions."""
    grid = world.grid()
    return draw_world(
        occupied_cells(grid),
        grid.resolution,
        (grid.origin[0], grid.origin[1]),
        reference_path=world.reference_path,
        trajectory=trajectory,
        collisions=collisions,
        start=world.start[:2],
        goal=world.goal,
        goal_tolerance_m=world.goal_tolerance_m,
        footprint_radius_m=world.footprint_radius_m,
        inflation_m=world.inflation_m,
        obstacles=world.obstacles,
        movers=world.movers,
        scale=scale,
        legend=True,
    )


def render_run(
    path: Path,
    world: BenchmarkWorld,
    *,
    trajectory: Sequence[Point] = (),
    collisions: Sequence[Point] = (),
    scale: int = 4,
) -> Path:
    """Write ``draw_run`` as a PNG at ``path`` (folders made as needed); returns ``path``."""
    image = draw_run(world, trajectory=trajectory, collisions=collisions, scale=scale)
    return write_world_png(path, image)
