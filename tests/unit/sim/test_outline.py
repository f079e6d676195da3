"""A world's outline: the map's occupied cells as the faces of their union, free side on each
face's left; obstacles as faces and discs; faces cut and filed in buckets for the lidar."""

from __future__ import annotations

import itertools
import math

import numpy as np

from services.sim.mapserver import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from services.sim.outline import BUCKET_M, MAX_BUCKETS, Outline, grid_faces
from services.sim.robot import BURGER
from services.sim.world_spec import ObstacleSpec, RobotSpec, World

Face = tuple[tuple[float, float], tuple[float, float]]


def grid(rows: list[str], *, origin: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> OccupancyGrid:
    """A grid drawn as text, top row first: '#' occupied, '.' free, '?' unknown; 1 m cells."""
    value = {"#": OCCUPIED, ".": FREE, "?": UNKNOWN}
    cells = np.array([[value[c] for c in row] for row in reversed(rows)], dtype=np.uint8)
    return OccupancyGrid(cells, 1.0, origin, "drawn")


def world(g: OccupancyGrid, obstacles: tuple[ObstacleSpec, ...] = ()) -> World:
    return World("w", "w", g, (RobotSpec("r1", 0.5, 0.5, model=BURGER),), obstacles=obstacles)


def rounded(faces: list[Face]) -> set[Face]:
    return {
        ((round(ax, 9) + 0.0, round(ay, 9) + 0.0), (round(bx, 9) + 0.0, round(by, 9) + 0.0))
        for (ax, ay), (bx, by) in faces
    }


def free_side_is_left(face: Face, g: OccupancyGrid) -> bool:
    """Just left of the face's middle is not occupied (or off the map), just right is."""
    (ax, ay), (bx, by) = face
    mx, my = (ax + bx) / 2.0, (ay + by) / 2.0
    length = math.hypot(bx - ax, by - ay)
    nx, ny = -(by - ay) / length * 0.01, (bx - ax) / length * 0.01
    return g.value_at(mx + nx, my + ny) != OCCUPIED and g.value_at(mx - nx, my - ny) == OCCUPIED


def test_one_occupied_cell_is_four_faces_clockwise_round_it() -> None:
    g = grid(["...", ".#.", "..."])
    faces = grid_faces(g)
    assert rounded(faces) == {
        ((2.0, 1.0), (1.0, 1.0)),  # below it, going -x: the free side (below) on the left
        ((1.0, 1.0), (1.0, 2.0)),  # its left side, going +y
        ((1.0, 2.0), (2.0, 2.0)),  # above it, going +x
        ((2.0, 2.0), (2.0, 1.0)),  # its right side, going -y
    }
    assert all(free_side_is_left(f, g) for f in faces)


def test_cells_merge_into_the_faces_of_their_union_and_inner_edges_vanish() -> None:
    # an L of five cells: six faces, each as long as the union's side; no face between cells
    g = grid(
        [
            ".....",
            ".#...",
            ".#...",
            ".###.",
            ".....",
        ]
    )
    faces = grid_faces(g)
    assert len(faces) == 6
    assert sorted(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in faces) == [1, 1, 2, 2, 3, 3]
    assert all(free_side_is_left(f, g) for f in faces)


def test_unknown_cells_and_the_maps_edge_are_not_walls() -> None:
    # a cell on the map's edge gets its face there too; an unknown cell is no wall
    g = grid(["#?", ".."])
    assert rounded(grid_faces(g)) == {
        ((1.0, 1.0), (0.0, 1.0)),
        ((0.0, 1.0), (0.0, 2.0)),
        ((0.0, 2.0), (1.0, 2.0)),
        ((1.0, 2.0), (1.0, 1.0)),
    }


def test_two_cells_touching_at_a_corner_keep_all_eight_faces() -> None:
    g = grid(["#.", ".#"])
    faces = grid_faces(g)
    assert len(faces) == 8 and all(free_side_is_left(f, g) for f in faces)


def test_a_turned_map_turns_its_faces_with_it() -> None:
    rows = ["....", ".##.", ".#..", "...."]
    flat, turned = grid(rows), grid(rows, origin=(5.0, -2.0, 0.7))
    c, s = math.cos(0.7), math.sin(0.7)

    def turn(p: tuple[float, float]) -> tuple[float, float]:
        return 5.0 + c * p[0] - s * p[1], -2.0 + s * p[0] + c * p[1]

    assert rounded(grid_faces(turned)) == rounded([(turn(a), turn(b)) for a, b in grid_faces(flat)])
    assert all(free_side_is_left(f, turned) for f in grid_faces(turned))


def test_obstacles_are_faces_outwards_and_discs_with_their_heights() -> None:
    box = ObstacleSpec("crate", "box", 3.0, 3.0, yaw=0.4, size=(0.8, 0.4, 0.25))
    can = ObstacleSpec("bin", "cylinder", 1.0, 4.0, size=(0.3, 0.3, 0.5))
    outline = Outline.of(world(grid(["......"] * 6), (box, can)))
    assert len(outline.a) == 4 and outline.face_top.tolist() == [0.25] * 4
    for a, b in zip(outline.a, outline.b, strict=True):
        # the box's centre is on each face's right, 0.2 or 0.4 m from its line
        ex, ey = b - a
        across = (ex * (3.0 - a[1]) - ey * (3.0 - a[0])) / math.hypot(ex, ey)
        assert round(-across, 9) in (0.2, 0.4)
    assert outline.centre.tolist() == [[1.0, 4.0]]
    assert outline.radius.tolist() == [0.15] and outline.disc_top.tolist() == [0.5]


def test_long_faces_are_cut_into_pieces_no_longer_than_a_bucket() -> None:
    # a 3.5 m wall: its two long faces in four pieces each, end to end
    g = OccupancyGrid(np.full((1, 70), OCCUPIED, dtype=np.uint8), 0.05, (0.0, 0.0, 0.0), "x")
    outline = Outline.of(world(g))
    length = np.hypot(*(outline.b - outline.a).T)
    assert length.max() <= BUCKET_M + 1e-12 and len(length) == 2 * 4 + 2
    assert math.isclose(length.sum(), 2 * 3.5 + 2 * 0.05)
    bottom = sorted(
        (tuple(a), tuple(b))
        for a, b in zip(outline.a, outline.b, strict=True)
        if a[1] == b[1] == 0.0
    )
    # going -x, the free side below on the left, each piece starting where the next ends
    assert bottom[0] == ((0.875, 0.0), (0.0, 0.0)) and bottom[-1] == ((3.5, 0.0), (2.625, 0.0))
    assert all(later[1] == earlier[0] for earlier, later in itertools.pairwise(bottom))


def test_near_finds_every_face_within_reach() -> None:
    # specks, and long walls whose pieces are a bucket long: a piece's midpoint may lie
    # farther than the reach while its end is within it
    rng = np.random.default_rng(3)
    cells = np.where(rng.random((120, 160)) < 0.02, OCCUPIED, FREE).astype(np.uint8)
    cells[10:12, 5:150] = cells[20:110, 70:72] = OCCUPIED
    g = OccupancyGrid(cells, 0.05, (-1.0, 2.0, 0.3), "noise")
    outline = Outline.of(world(g))
    points = rng.uniform(-3.0, 9.0, size=(400, 2))
    reach = rng.uniform(0.05, 3.0, size=400)
    k, f = outline.near(points, reach)
    found = set(zip(k.tolist(), f.tolist(), strict=True))
    assert len(found) == len(k)  # each face once per point
    # the distance from each point to each face, the long way
    e = outline.b - outline.a
    rel = points[:, None, :] - outline.a[None]
    t = np.clip(np.sum(rel * e, axis=2) / np.sum(e * e, axis=1), 0.0, 1.0)
    gap = np.hypot(*np.moveaxis(rel - t[..., None] * e, 2, 0))
    want = set(zip(*np.nonzero(gap <= reach[:, None]), strict=True))
    assert want <= found and len(want) > 1000
    assert len(found) < 0.5 * 400 * len(outline.a)  # and not every face: the buckets work


def test_a_world_reaching_far_off_the_map_keeps_its_buckets_few() -> None:
    # a crate 100 km away and a 50 km wall: wider buckets and longer pieces, not millions
    far = ObstacleSpec("far", "box", 1e5, -1e5, size=(1.0, 1.0, 1.0))
    wall = ObstacleSpec("wall", "box", 0.0, 3.0, size=(5e4, 0.2, 1.0))
    outline = Outline.of(world(grid(["......"] * 6), (far, wall)))
    assert outline.columns <= MAX_BUCKETS + 1 and outline.rows <= MAX_BUCKETS + 1
    length = np.hypot(*(outline.b - outline.a).T)
    assert length.max() <= outline.side + 1e-9 and len(length) < 1000
    # and every face is still found within reach
    k, f = outline.near(np.array([[0.0, 2.5], [1e5 - 1.0, -1e5]]), np.array([1.0, 1.0]))
    names = {(int(i), tuple(np.round(outline.a[j], 3))) for i, j in zip(k, f, strict=True)}
    assert any(i == 0 and a[1] == 2.9 for i, a in names)  # the wall's near face
    assert any(i == 1 and a[0] == 1e5 - 0.5 for i, a in names)  # the crate's west face
