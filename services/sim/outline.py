"""A world's walls and obstacles as a 2-D lidar sees them: faces and discs, each with the
height it rises to.

Everything static in a world stands on the floor and rises straight up: the map's occupied
cells as prisms ``wall_height_m`` tall, box obstacles (turned by their yaw) and cylinder
obstacles. A lidar's beams are horizontal, so a beam at height z meets a body only if z is
within the body's height, and where it meets it is a question in the plane: the first face
of a polygon's outline it crosses, or where it enters a disc.

The map's occupied cells become the outline of their union, not a prism per cell or per
rectangle: only the edges between an occupied cell and a free (or unknown, or off-map) one,
joined into the longest straight runs. A face is stored with its free side on its left
(going from ``a`` to ``b``), so a beam from a point on the free side can meet it only if that
point is on its left: the faces turned away from a lidar are left out before any beam is
tested (a lidar never stands inside a wall or an obstacle: robots are kept out of them).

Faces are cut into pieces at most ``BUCKET_M`` long and filed in square buckets of that side
by their midpoints (larger pieces and buckets in a world so wide that there would be more
than MAX_BUCKETS a side), so that a lidar looks only at the faces of the buckets its reach
covers: a map of tens of thousands of faces (a noisy scan of a building) costs each cast its
neighbourhood, not the whole map.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from services.sim.mapserver import OCCUPIED, OccupancyGrid
from services.sim.world_spec import World

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

# the longest piece of a face, and the side of a bucket, m; in a world wider than
# MAX_BUCKETS of them (an obstacle placed far off the map) the buckets grow to keep their
# number bounded
BUCKET_M = 1.0
MAX_BUCKETS = 512


@dataclass(frozen=True)
class Outline:
    """Faces ``a[i] -> b[i]`` (free side on the left) rising to ``face_top[i]``, and discs
    centred at ``centre[j]`` of radius ``radius[j]`` rising to ``disc_top[j]``; metres. The
    faces are in bucket order: bucket q (row-major from ``corner``, ``columns`` wide) holds
    faces ``first[q]`` to ``first[q + 1]``."""

    a: FloatArray  # (faces, 2)
    b: FloatArray  # (faces, 2)
    face_top: FloatArray  # (faces,)
    centre: FloatArray  # (discs, 2)
    radius: FloatArray  # (discs,)
    disc_top: FloatArray  # (discs,)
    corner: tuple[float, float]
    side: float  # of a bucket, and the longest piece of a face, m
    columns: int
    rows: int
    first: IntArray  # (buckets + 1,)

    @classmethod
    def of(cls, world: World) -> Outline:
        faces = [(a, b, world.wall_height_m) for a, b in grid_faces(world.grid)]
        discs: list[tuple[float, float, float, float]] = []
        for ob in world.obstacles:
            sx, sy, sz = ob.size
            if ob.shape == "cylinder":
                discs.append((ob.x, ob.y, sx / 2.0, sz))
                continue
            c, s = math.cos(ob.yaw), math.sin(ob.yaw)
            # the corners clockwise, so that the outside is on each face's left
            local = ((sx, sy), (sx, -sy), (-sx, -sy), (-sx, sy))
            corners = [
                (ob.x + (c * u - s * v) / 2.0, ob.y + (s * u + c * v) / 2.0) for u, v in local
            ]
            faces += [(corners[k], corners[(k + 1) % 4], sz) for k in range(4)]
        a = np.array([f[0] for f in faces], dtype=np.float64).reshape(-1, 2)
        b = np.array([f[1] for f in faces], dtype=np.float64).reshape(-1, 2)
        ends = np.concatenate([a, b])
        extent = float((ends.max(axis=0) - ends.min(axis=0)).max()) if len(ends) else 0.0
        side = max(BUCKET_M, extent / MAX_BUCKETS)
        a, b, top = _cut(a, b, np.array([f[2] for f in faces], dtype=np.float64), side)
        d = np.array(discs, dtype=np.float64).reshape(-1, 4)
        middle = (a + b) / 2.0
        corner = middle.min(axis=0) if len(middle) else np.zeros(2)
        cell = np.floor((middle - corner) / side).astype(np.intp)
        columns, rows = (cell.max(axis=0) + 1).tolist() if len(cell) else (1, 1)
        bucket = cell[:, 1] * columns + cell[:, 0]
        order = np.argsort(bucket, kind="stable")
        first = np.searchsorted(bucket[order], np.arange(columns * rows + 1))
        return cls(
            a[order],
            b[order],
            top[order],
            d[:, :2],
            d[:, 2],
            d[:, 3],
            (float(corner[0]), float(corner[1])),
            side,
            int(columns),
            int(rows),
            first,
        )

    def near(self, xy: FloatArray, reach: FloatArray) -> tuple[IntArray, IntArray]:
        """(k, face) for every face that may lie within ``reach[k]`` of point ``xy[k]``: the
        faces of every bucket within reach (a superset; the caller tests each exactly)."""
        # a piece is at most a bucket's side long: its points are within half that of its
        # midpoint
        span = reach + self.side / 2.0
        low = np.floor((xy - span[:, None] - self.corner) / self.side).astype(np.intp)
        high = np.floor((xy + span[:, None] - self.corner) / self.side).astype(np.intp)
        c0, c1 = np.maximum(low[:, 0], 0), np.minimum(high[:, 0], self.columns - 1)
        r0, r1 = np.maximum(low[:, 1], 0), np.minimum(high[:, 1], self.rows - 1)
        # one run of buckets per (point, bucket row): a row's buckets c0..c1 are contiguous
        k, row = spans(r0, np.maximum(r1 - r0 + 1, 0) * (c1 >= c0))
        start = self.first[row * self.columns + c0[k]]
        end = self.first[row * self.columns + c1[k] + 1]
        run, face = spans(start, end - start)
        return k[run], face


Point = tuple[float, float]


def grid_faces(grid: OccupancyGrid) -> list[tuple[Point, Point]]:
    """The outline of the grid's occupied cells, free side on each face's left: every edge
    between an occupied cell and one that is not (or the map's border), joined into maximal
    straight runs, in world coordinates."""
    solid = np.zeros((grid.height + 2, grid.width + 2), dtype=bool)  # a free border round it
    solid[1:-1, 1:-1] = grid.cells == OCCUPIED
    faces: list[tuple[Point, Point]] = []
    # between rows r - 1 and r (grid row lines), and between columns c - 1 and c
    rows = solid[1:, 1:-1].astype(np.int8) - solid[:-1, 1:-1]  # +1: solid above the line
    cols = solid[1:-1, 1:].astype(np.int8) - solid[1:-1, :-1]  # +1: solid right of it
    for line, edge in enumerate(rows):
        for start, end, sign in _runs(edge):
            # solid below (sign -1): free above, on the left going +x
            ends = ((start, line), (end, line)) if sign < 0 else ((end, line), (start, line))
            faces.append(_world(grid, *ends))
    for line, edge in enumerate(cols.T):
        for start, end, sign in _runs(edge):
            # solid left of the line (sign -1): free to the right, on the left going -y
            ends = ((line, end), (line, start)) if sign < 0 else ((line, start), (line, end))
            faces.append(_world(grid, *ends))
    return faces


def spans(lo: IntArray, count: IntArray) -> tuple[IntArray, IntArray]:
    """Every (i, lo[i] + m) for m in range(count[i]), flattened: which span, and the value."""
    which = np.repeat(np.arange(len(count)), count)
    return which, lo[which] + np.arange(len(which)) - np.repeat(np.cumsum(count) - count, count)


def _cut(
    a: FloatArray, b: FloatArray, top: FloatArray, side: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The faces cut into equal pieces at most ``side`` long."""
    pieces = np.maximum(np.ceil(np.hypot(*(b - a).T) / side).astype(np.intp), 1)
    face, m = spans(np.zeros(len(pieces), dtype=np.intp), pieces)
    step = (b - a)[face] / pieces[face, None]
    start = a[face] + step * m[:, None]
    # each last piece ends exactly where its face does
    end = np.where((m == pieces[face] - 1)[:, None], b[face], start + step)
    return start, end, top[face]


def _runs(edge: npt.NDArray[np.int8]) -> list[tuple[int, int, int]]:
    """(start, end, sign) of each run of equal non-zero values, end exclusive."""
    change = np.flatnonzero(np.diff(np.concatenate(([0], edge, [0]))))
    return [
        (int(start), int(end), int(edge[start]))
        for start, end in itertools.pairwise(change.tolist())
        if edge[start] != 0
    ]


def _world(grid: OccupancyGrid, a: tuple[int, int], b: tuple[int, int]) -> tuple[Point, Point]:
    return grid.cell_to_world(*a), grid.cell_to_world(*b)
