"""The fleet's lidar cast, in closed form: walls, obstacles and other robots met where each
beam first reaches one, against a reference written another way (every rectangle of occupied
cells and every box a box, every cylinder a disc, tested against every beam) and against
Bullet's own ray cast, with robots crowded together and against walls so that many beams meet
other robots."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pybullet as p
import pytest

import services.sim.sim as sim_module
from common.robotmodel import load_model
from services.sim.fleetcast import Cast, FleetCast, Pose
from services.sim.lidar import Lidar
from services.sim.mapserver import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from services.sim.outline import Outline
from services.sim.physics import Scene
from services.sim.robot import BURGER
from services.sim.sim import SimConfig, Simulation
from services.sim.world_spec import ObstacleSpec, RobotSpec, World, load_world
from tests.unit.sim.conftest import MakeWorld

pytestmark = pytest.mark.timeout(60)

# a 6 x 6 m map: a wall along x = 3, a pillar, and the map's edge walls
WALLS = [(3.0, 0.0, 3.1, 4.0), (1.0, 4.0, 1.3, 4.3), (0.0, 0.0, 6.0, 0.1), (0.0, 0.0, 0.1, 6.0)]
OBSTACLES = [
    {"name": "crate", "type": "box", "x": 4.5, "y": 1.0, "yaw": 0.5, "size": [0.4, 0.3, 0.4]},
    {"name": "bin", "type": "cylinder", "x": 2.0, "y": 5.0, "radius": 0.15, "height": 0.5},
    {"name": "box", "type": "box", "x": 2.2, "y": 1.4, "size": [0.3, 0.3, 0.3]},
    {"name": "can", "type": "cylinder", "x": 0.6, "y": 2.4, "radius": 0.12, "height": 0.3},
    # lower than any lidar: every beam passes over them
    {"name": "step", "type": "box", "x": 1.6, "y": 2.0, "size": [0.5, 0.5, 0.1]},
    {"name": "stool", "type": "cylinder", "x": 2.4, "y": 2.4, "radius": 0.2, "height": 0.15},
]
ROBOTS = 12
RADIUS = 0.105
# Bullet is approximate near a shape's edge: its convex cast meets a cylinder or a box up to
# a few mm outside it (and reads a cylinder 0.1 mm short at the median), its mesh test
# accepts a beam up to about 1e-4 of a face's size past the face's end. Beams passing more
# than GRAZE_M from every corner and every disc's edge get the same hit or miss from it, and
# a range within BULLET_RANGE_M (measured: up to 6 mm); a wall to WALL_RANGE_M.
GRAZE_M = 0.002
BULLET_RANGE_M = 0.01
WALL_RANGE_M = 1e-6


def rays(lidar: Lidar, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """A robot's beams as 3-D rays from its centre to its range's end, as Bullet's ray test
    takes them (the beams' directions from the lidar's ``cos`` and ``sin``, turned by the
    robot's yaw, as the sim's cast turns them)."""
    x, y, yaw = pose
    cy, sy = math.cos(yaw), math.sin(yaw)
    reach = lidar.params.range_max_m
    dx = lidar.cos * cy - lidar.sin * sy
    dy = lidar.sin * cy + lidar.cos * sy
    starts = np.column_stack(
        [np.full(len(dx), x), np.full(len(dx), y), np.full(len(dx), lidar.height)]
    )
    ends = np.column_stack([x + dx * reach, y + dy * reach, np.full(len(dx), lidar.height)])
    return starts, ends


def _slab(o: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Per ray o + s d (s in [0, 1)), the nearest s at which it enters any of the axis-aligned
    boxes [lo, hi], inf where it enters none."""
    if len(lo) == 0:
        return np.full(len(o), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo[None] - o[:, None]) / d[:, None]
        t2 = (hi[None] - o[:, None]) / d[:, None]
    near = np.max(np.minimum(t1, t2), axis=2)
    far = np.min(np.maximum(t1, t2), axis=2)
    enters = (near <= far) & (far >= 0.0) & (near < 1.0)
    entry: np.ndarray = np.where(enters, np.maximum(near, 0.0), np.inf).min(axis=1)
    return entry


def _disc(o: np.ndarray, d: np.ndarray, centre: tuple[float, float], r: float) -> np.ndarray:
    """Per ray, the s at which it enters the disc (projecting the centre on it), inf if never."""
    length = np.hypot(d[:, 0], d[:, 1])
    ux, uy = d[:, 0] / length, d[:, 1] / length
    cx, cy = centre[0] - o[:, 0], centre[1] - o[:, 1]
    along = cx * ux + cy * uy
    square = cx**2 + cy**2 - along**2  # the centre's distance from the ray, squared
    enter = (along - np.sqrt(np.maximum(0.0, r * r - square))) / length
    return np.where((square <= r * r) & (enter >= 0.0) & (enter <= 1.0), enter, np.inf)


def static_reference(world: World, lidar: Lidar, pose: Pose) -> np.ndarray:
    """Per beam, the fraction along its ray at which it first enters a wall or an obstacle as
    tall as its height (inf: none): each rectangle of occupied cells a box in the map's frame,
    each box obstacle one in its own, each cylinder a disc."""
    starts, ends = rays(lidar, pose)
    z = lidar.height
    best = np.full(len(starts), np.inf)
    g = world.grid
    if z <= world.wall_height_m:
        # the occupied cells merged into rectangles (as pybullet's scene has them)
        box = np.array(g.occupied_rectangles(), dtype=float).reshape(-1, 4)
        # the map's frame: turned by its origin's yaw, in cells
        c, s = math.cos(g.origin[2]), math.sin(g.origin[2])
        to_cells = np.array([[c, s], [-s, c]]) / g.resolution
        o = (starts[:, :2] - g.origin[:2]) @ to_cells.T
        d = (ends[:, :2] - starts[:, :2]) @ to_cells.T
        best = np.minimum(best, _slab(o, d, box[:, :2], box[:, 2:]))
    for ob in world.obstacles:
        if z > ob.size[2]:
            continue
        if ob.shape == "cylinder":
            best = np.minimum(
                best,
                _disc(starts[:, :2], ends[:, :2] - starts[:, :2], (ob.x, ob.y), ob.size[0] / 2.0),
            )
            continue
        c, s = math.cos(-ob.yaw), math.sin(-ob.yaw)
        turn = np.array([[c, -s], [s, c]])
        o = (starts[:, :2] - (ob.x, ob.y)) @ turn.T
        d = (ends[:, :2] - starts[:, :2]) @ turn.T
        half = np.array(ob.size[:2]) / 2.0
        best = np.minimum(best, _slab(o, d, -half[None], half[None]))
    return best


def reference(world: World, lidars: Sequence[Lidar], poses: Sequence[Pose], i: int) -> Cast:
    """Robot i's beams as the lidar is defined, written out another way than the fleet cast:
    the first wall or obstacle (:func:`static_reference`) or other robot's body (a body whose
    top reaches the beams' height: a disc, or the box of its footprint polygon, in its frame)
    each beam's ray enters."""
    lidar = lidars[i]
    best = static_reference(world, lidar, poses[i])
    starts, ends = rays(lidar, poses[i])
    for j, (x, y, yaw) in enumerate(poses):
        model = world.models[j]
        if j == i or model.height_m < lidar.height:
            continue
        d = ends[:, :2] - starts[:, :2]
        fp = model.footprint
        if fp.is_disc:
            best = np.minimum(best, _disc(starts[:, :2], d, (x, y), model.footprint_radius_m))
            continue
        c, s = math.cos(-yaw), math.sin(-yaw)
        turn = np.array([[c, -s], [s, c]])
        lo, hi = fp.vertices.min(axis=0), fp.vertices.max(axis=0)  # the models' are boxes
        o = (starts[:, :2] - (x, y)) @ turn.T
        best = np.minimum(best, _slab(o, d @ turn.T, lo[None], hi[None]))
    hit = best <= 1.0
    return hit, np.where(hit, best, 1.0)


def grazing(world: World, lidar: Lidar, poses: Sequence[Pose], i: int) -> np.ndarray:
    """Robot i's beams that pass within GRAZE_M of a corner of the outline, of a box, or of
    the edge of a cylinder or another robot, ahead of it."""
    starts, ends = rays(lidar, poses[i])
    length = lidar.params.range_max_m
    ux, uy = (ends[:, 0] - starts[:, 0]) / length, (ends[:, 1] - starts[:, 1]) / length
    x0, y0, _ = poses[i]
    outline = Outline.of(world)
    corners = [(x, y, 0.0) for x, y in np.concatenate([outline.a, outline.b])]
    discs = [(x, y, r) for (x, y), r in zip(outline.centre, outline.radius, strict=True)]
    for j, (x, y, yaw) in enumerate(poses):
        fp = world.models[j].footprint
        if j == i:
            continue
        if fp.is_disc:
            discs.append((x, y, fp.radius_m))
        else:
            corners += [(cx, cy, 0.0) for cx, cy in fp.at(x, y, yaw)]
    out = np.zeros(len(starts), dtype=bool)
    for x, y, r in corners + discs:
        along = (x - x0) * ux + (y - y0) * uy
        off = np.sqrt(np.maximum(0.0, (x - x0) ** 2 + (y - y0) ** 2 - along**2))
        out |= (along > -GRAZE_M) & (np.abs(off - r) <= GRAZE_M)
    return out


def bullet_cast(scene: Scene, index: int, pose: Pose, lidar: Lidar) -> Cast:
    """Robot ``index``'s beams as Bullet's ray test sees the scene, every other robot in
    place: its own body lowered out of the beams' plane for the cast (pybullet cannot leave
    a body out per ray; the beams start inside it), then put back."""
    body = scene.robot_bodies[index]
    p.resetBasePositionAndOrientation(
        body, [0.0, 0.0, -10.0], [0, 0, 0, 1], physicsClientId=scene.client
    )
    try:
        starts, ends = rays(lidar, pose)
        results = p.rayTestBatch(starts, ends, physicsClientId=scene.client)
    finally:
        scene.place(index, *pose)
    hit = np.array([r[0] >= 0 for r in results])
    return hit, np.where(hit, [r[2] for r in results], 1.0)


def assert_cast_is_reference(got: Cast, want: Cast, robot: int) -> None:
    np.testing.assert_array_equal(got[0], want[0], err_msg=f"robot {robot}")
    np.testing.assert_allclose(got[1], want[1], rtol=0, atol=1e-12, err_msg=f"robot {robot}")


def crowd(world: World, rng: np.random.Generator, count: int) -> list[Pose]:
    """Robots packed at random in a 2.6 x 2.6 m corner against the walls and among the
    obstacles, none overlapping another or a wall or an obstacle (some touching: 1 mm apart),
    at any heading."""
    poses: list[Pose] = []
    while len(poses) < count:
        x, y = rng.uniform(0.25, 2.85), rng.uniform(0.25, 2.85)
        gaps = [math.hypot(x - px, y - py) for px, py, _ in poses]
        if world.blocked(x, y, RADIUS) is None and min(gaps, default=1.0) >= 2 * RADIUS + 0.001:
            poses.append((x, y, float(rng.uniform(-math.pi, math.pi))))
        if len(poses) == 1 and rng.random() < 0.5:
            # a pair touching, 1 mm apart, to graze
            x0, y0, _ = poses[0]
            x1 = x0 + 2 * RADIUS + 0.001
            if world.blocked(x1, y0, RADIUS) is None:
                poses.append((x1, y0, float(rng.uniform(-math.pi, math.pi))))
    return poses


def crowds(world: World, scene: Scene | None, seed: int, count: int) -> Iterator[list[Pose]]:
    """``count`` crowds (:func:`crowd`) of the world's robots, each placed in ``scene`` (if
    any) before it is yielded."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        poses = crowd(world, rng, len(world.robots))
        if scene is not None:
            for i, pose in enumerate(poses):
                scene.place(i, *pose)
        yield poses


def fleet(world: World) -> tuple[FleetCast, list[Lidar]]:
    shared: dict[object, Lidar] = {}
    lidars = [shared.setdefault(m.lidar, Lidar(m.lidar)) for m in world.models]
    return FleetCast(Outline.of(world), world.models, lidars), lidars


@pytest.fixture
def world(make_world: MakeWorld) -> World:
    robots = [{"id": f"r{i}", "x": 0.5 + 0.4 * i, "y": 5.5} for i in range(ROBOTS)]
    return load_world(make_world(6.0, 6.0, WALLS, robots=robots, obstacles=OBSTACLES))


@pytest.fixture
def scene(world: World) -> Iterator[Scene]:
    scene = Scene(world)
    yield scene
    scene.close()


def test_beams_meet_the_first_wall_obstacle_or_robot_in_their_way(world: World) -> None:
    cast, lidars = fleet(world)
    met = {"robot": 0, "wall or obstacle": 0}
    for poses in crowds(world, None, seed=11, count=12):
        want = [reference(world, lidars, poses, i) for i in range(ROBOTS)]
        for scanning in (list(range(ROBOTS)), [0, 1], [3], list(range(0, ROBOTS, 3))):
            for i, got in zip(scanning, cast(poses, scanning), strict=True):
                assert_cast_is_reference(got, want[i], i)
        for i in range(ROBOTS):
            static = static_reference(world, lidars[i], poses[i])
            hit, fraction = want[i]
            met["robot"] += int(np.sum(fraction < static))
            met["wall or obstacle"] += int(np.sum(hit & (fraction == static)))
    # the scene really crowds: many beams met other robots, many the walls and obstacles
    assert met["robot"] > 12 * ROBOTS * 20 and met["wall or obstacle"] > 12 * ROBOTS * 100


def test_beams_pass_over_what_is_lower_than_the_lidar(make_world: MakeWorld) -> None:
    # Burgers (lidar at 0.17 m) in a room of 0.12 m walls, behind a 0.1 m step and a 0.15 m
    # stool: they see none of them, only the 0.4 m box and the 0.5 m post behind
    path = make_world(
        6.0,
        6.0,
        [(0.0, 0.0, 0.1, 6.0), (4.0, 0.0, 4.1, 6.0)],
        robots=[{"id": "r1", "x": 1.0, "y": 1.0}, {"id": "r2", "x": 1.0, "y": 2.0}],
        obstacles=[
            {"name": "step", "type": "box", "x": 2.0, "y": 1.0, "size": [0.4, 0.4, 0.1]},
            {"name": "box", "type": "box", "x": 3.0, "y": 1.0, "size": [0.2, 0.2, 0.4]},
            {
                "name": "stool",
                "type": "cylinder",
                "x": 2.0,
                "y": 2.0,
                "radius": 0.2,
                "height": 0.15,
            },
            {"name": "post", "type": "cylinder", "x": 3.0, "y": 2.0, "radius": 0.1, "height": 0.5},
        ],
        wall_height=0.12,
    )
    world = load_world(path)
    cast, lidars = fleet(world)
    poses = [(1.0, 1.0, 0.0), (1.0, 2.0, 0.0)]
    got = cast(poses, [0, 1])
    for i, (hit, fraction) in enumerate(got):
        # beam 0 ahead: the box's or the post's face 1.9 m away; beam 180 behind: nothing
        assert hit[0] and math.isclose(fraction[0] * 3.5, 1.9), i
        assert not hit[180] and fraction[180] == 1.0, i
        assert_cast_is_reference(got[i], reference(world, lidars, poses, i), i)


def test_the_cast_agrees_with_bullet_but_for_beams_grazing_an_edge(
    world: World, scene: Scene
) -> None:
    # the sim's lidar against Bullet's own cast of one robot's beams, everything in place
    cast, lidars = fleet(world)
    compared = walls = 0
    for poses in crowds(world, scene, seed=7, count=6):
        for i, (hit, fraction) in enumerate(cast(poses, list(range(ROBOTS)))):
            bullet_hit, bullet_fraction = bullet_cast(scene, i, poses[i], lidars[i])
            clear = ~grazing(world, lidars[i], poses, i)
            np.testing.assert_array_equal(hit[clear], bullet_hit[clear], err_msg=f"robot {i}")
            gap = np.abs(fraction - bullet_fraction) * lidars[i].params.range_max_m
            assert gap[clear].max() <= BULLET_RANGE_M, f"robot {i}"
            # a beam whose first meeting is a wall: Bullet tests the wall's mesh exactly
            bare = static_reference(replace(world, obstacles=()), lidars[i], poses[i])
            wall = clear & hit & np.isclose(fraction, bare, rtol=0.0, atol=1e-12)
            assert gap[wall].max(initial=0.0) <= WALL_RANGE_M, f"robot {i}"
            compared += int(np.sum(clear & hit))
            walls += int(np.sum(wall))
    assert compared > 6 * ROBOTS * 300 and walls > 6 * ROBOTS * 100


def test_a_crowded_run_scans_as_the_reference_cast_per_robot(
    make_world: MakeWorld, monkeypatch: pytest.MonkeyPatch
) -> None:
    # robots a robot's width apart driving circles into each other, the walls and the
    # obstacles, at 20 Hz: several scan in the same step; every scan message, noise included,
    # must be the reference's, in the same order
    robots = [
        {"id": f"r{i}", "x": 0.4 + 0.3 * (i % 6), "y": 0.4 + 0.3 * (i // 6), "yaw": 0.3 * i}
        for i in range(12)
    ]
    path = make_world(6.0, 6.0, WALLS, robots=robots, obstacles=OBSTACLES)

    def run() -> list[tuple[str, list[float]]]:
        scans: list[tuple[str, list[float]]] = []

        def sink(robot: str, topic: str, msg: dict[str, Any]) -> None:
            if topic == "scan":
                scans.append((robot, msg["ranges"]))

        sim = Simulation(load_world(path), SimConfig(scan_hz=20.0, seed=5), sink)
        try:
            for i, robot in enumerate(sim.robots):
                sim.set_command(robot.robot_id, 0.22, 0.5 + 0.2 * (i % 4))
            sim.run_for(2.0)
        finally:
            sim.close()
        return scans

    batched = run()
    loaded = load_world(path)

    class OneAtATime:
        """FleetCast's stand-in: the reference, one robot at a time."""

        def __init__(self, outline: Outline, models: object, lidars: Sequence[Lidar]) -> None:
            self.lidars = lidars

        def __call__(self, poses: Sequence[Pose], scanning: Sequence[int]) -> list[Cast]:
            return [reference(loaded, self.lidars, poses, i) for i in scanning]

    monkeypatch.setattr(sim_module, "FleetCast", OneAtATime)
    alone = run()
    assert len(batched) == 12 * 40
    assert [robot for robot, _ in batched] == [robot for robot, _ in alone]
    for (_, got), (_, want) in zip(batched, alone, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


def test_a_fleet_of_mixed_models_sees_each_body_that_reaches_its_beams(
    make_world: MakeWorld,
) -> None:
    # Jackals (270-degree, 720-beam lidar at 0.22 m, 0.25 m tall bodies), Burgers (lidar at
    # 0.17 m, 0.192 m tall) and a narrow 90-degree lidar whose field of view starts behind
    # the robot, crowded: a Burger sees Jackals, a Jackal's beams pass over Burgers (and the
    # 0.2 m tall obstacles), and the partial fields of view must find exactly the bodies and
    # faces within them, across beam 0's direction too
    narrow = {"name": "turtlebot3_burger", "lidar": {"beams": 91, "fov_rad": math.pi / 2}}
    narrow["lidar"]["angle_min_rad"] = 3 * math.pi / 4  # type: ignore[index]
    kinds: list[Any] = ["jackal", None, narrow]
    robots = [
        {"id": f"r{i}", "x": 0.5 + 0.5 * i, "y": 5.5, "model": kinds[i % 3]} for i in range(9)
    ]
    for r in robots:
        if r["model"] is None:
            del r["model"]
    obstacles = [
        *OBSTACLES,
        {"name": "low", "type": "box", "x": 1.2, "y": 1.2, "size": [0.3, 0.3, 0.2]},
    ]
    world = load_world(make_world(6.0, 6.0, WALLS, robots=robots, obstacles=obstacles))
    scene = Scene(world)
    try:
        cast, lidars = fleet(world)
        rng = np.random.default_rng(5)
        met = {"jackal": 0, "turtlebot3_burger": 0}
        for _ in range(8):
            poses: list[Pose] = []
            while len(poses) < len(robots):
                x, y = rng.uniform(0.35, 2.75), rng.uniform(0.35, 2.75)
                clear = world.blocked(x, y, 0.221) is None
                # apart by the bodies' reach (a Jackal's box reaches 0.333 m from its centre)
                if clear and all(math.hypot(x - px, y - py) >= 0.667 for px, py, _ in poses):
                    poses.append((x, y, float(rng.uniform(-math.pi, math.pi))))
            for i, pose in enumerate(poses):
                scene.place(i, *pose)
            want = [reference(world, lidars, poses, i) for i in range(len(robots))]
            for scanning in (list(range(len(robots))), [0, 2, 4], [2]):
                for i, got in zip(scanning, cast(poses, scanning), strict=True):
                    assert len(got[0]) == world.models[i].lidar.beams
                    assert_cast_is_reference(got, want[i], i)
            for i in range(len(robots)):
                # and as Bullet sees the same bodies, heights included
                bullet = bullet_cast(scene, i, poses[i], lidars[i])
                clear_beams = ~grazing(world, lidars[i], poses, i)
                np.testing.assert_array_equal(want[i][0][clear_beams], bullet[0][clear_beams])
                static = static_reference(world, lidars[i], poses[i])
                met[world.models[i].name] += int(np.sum(want[i][1] < static))
        assert met["jackal"] > 50 and met["turtlebot3_burger"] > 50  # beams met other robots
    finally:
        scene.close()


def test_a_noisy_turned_map_of_thousands_of_faces_is_cast_as_the_reference() -> None:
    # a scanned building's map: specks everywhere, the map turned and moved, faces in many
    # buckets, a long-range lidar with a partial field of view (the Jackal's) and a short
    # full-turn one (the Burger's)
    rng = np.random.default_rng(8)
    cells = np.where(rng.random((160, 200)) < 0.03, OCCUPIED, FREE).astype(np.uint8)
    grid = OccupancyGrid(cells, 0.05, (-2.0, 1.0, 0.6), "noise")
    jackal = load_model("jackal")
    specs: list[RobotSpec] = []
    while len(specs) < 8:
        x, y = grid.cell_to_world(*rng.uniform(5.0, 155.0, size=2))
        apart = all(math.hypot(x - r.x, y - r.y) > 0.6 for r in specs)
        if apart and not grid.occupied_near(x, y, 0.3):
            model = jackal if len(specs) % 2 else BURGER
            specs.append(RobotSpec(f"r{len(specs)}", x, y, float(rng.uniform(-3, 3)), model=model))
    box = ObstacleSpec("crate", "box", specs[0].x + 0.7, specs[0].y, yaw=0.2, size=(0.3, 0.3, 0.4))
    world = World("noise", "noise", grid, tuple(specs), obstacles=(box,))
    cast, lidars = fleet(world)
    outline = Outline.of(world)
    assert len(outline.a) > 3000 and outline.columns * outline.rows > 50
    poses = [(r.x, r.y, r.yaw) for r in world.robots]
    got = cast(poses, list(range(len(poses))))
    for i, one in enumerate(got):
        assert_cast_is_reference(one, reference(world, lidars, poses, i), i)
        assert np.mean(one[0]) > 0.5  # the specks are everywhere


def test_a_lidar_of_one_or_two_beams_meets_what_is_in_their_way() -> None:
    # a shape's window of candidate beams can be wider than the lidar's field of view and
    # start before its first beam: the beams within must all be tested
    grid = OccupancyGrid(np.full((40, 40), FREE, dtype=np.uint8), 0.05, (0.0, 0.0, 0.0), "e")
    one = replace(BURGER, lidar=replace(BURGER.lidar, beams=1, fov_rad=0.0, angle_min_rad=0.3))
    two = replace(BURGER, lidar=replace(BURGER.lidar, beams=2, fov_rad=0.2, angle_min_rad=-0.1))
    box = ObstacleSpec("box", "box", 1.5, 1.0, yaw=0.1, size=(0.2, 0.4, 0.3))
    robots = (
        RobotSpec("r1", 0.5, 0.5, model=one),
        RobotSpec("r2", 1.0, 0.4, model=two),
        RobotSpec("r3", 0.6, 1.5),
    )
    world = World("e", "e", grid, robots, obstacles=(box,))
    cast, lidars = fleet(world)
    rng = np.random.default_rng(1)
    met = 0
    for _ in range(300):
        poses = [(r.x, r.y, float(rng.uniform(-4.0, 4.0))) for r in robots]
        for i, got in enumerate(cast(poses, [0, 1, 2])):
            assert_cast_is_reference(got, reference(world, lidars, poses, i), i)
            met += int(np.sum(got[0])) if i < 2 else 0
    assert met > 100


def _random_world(rng: np.random.Generator) -> World:
    """A map of random specks (occupied and unknown cells) turned and moved anywhere, random
    boxes and cylinders, and robots of random bodies and lidars (1 to 800 beams, any field
    of view and first beam, any height and range) placed clear of everything."""
    rows, cols = (int(v) for v in rng.integers(10, 80, size=2))
    cells = rng.choice([FREE, OCCUPIED, UNKNOWN], p=[0.9, 0.07, 0.03], size=(rows, cols))
    origin = (float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3)), float(rng.uniform(-3.2, 3.2)))
    grid = OccupancyGrid(cells.astype(np.uint8), float(rng.choice([0.025, 0.05, 0.1])), origin, "f")
    obstacles = []
    for j in range(int(rng.integers(0, 6))):
        x, y = grid.cell_to_world(*rng.uniform(0, [cols, rows]))
        if rng.random() < 0.5:
            size = (*rng.uniform(0.05, 0.6, size=2).tolist(), float(rng.uniform(0.05, 0.5)))
            yaw = float(rng.uniform(-3, 3))
            obstacles.append(ObstacleSpec(f"b{j}", "box", x, y, yaw=yaw, size=size))
        else:
            r, h = float(rng.uniform(0.03, 0.3)), float(rng.uniform(0.05, 0.5))
            obstacles.append(ObstacleSpec(f"c{j}", "cylinder", x, y, size=(2 * r, 2 * r, h)))
    walls = float(rng.uniform(0.1, 0.5))
    world = World("f", "f", grid, (), obstacles=tuple(obstacles), wall_height_m=walls)
    robots: list[RobotSpec] = []
    wanted = int(rng.integers(1, 8))
    for _ in range(500):
        if len(robots) == wanted:
            break
        beams = int(rng.integers(1, 800))
        fov = 2 * math.pi if rng.random() < 0.4 else float(rng.uniform(0.05, 6.2))
        lidar = replace(
            BURGER.lidar,
            beams=beams,
            fov_rad=0.0 if beams == 1 and fov < 6 else fov,
            angle_min_rad=float(rng.uniform(-4, 4)),
            range_max_m=float(rng.uniform(0.5, 12)),
            height_m=float(rng.uniform(0.05, 0.4)),
        )
        radius = float(rng.uniform(0.05, 0.3))
        body = replace(
            BURGER, lidar=lidar, footprint_radius_m=radius, height_m=float(rng.uniform(0.1, 0.5))
        )
        x, y = grid.cell_to_world(*rng.uniform(0, [cols, rows]))
        clear = all(
            math.hypot(x - o.x, y - o.y) > radius + o.model.footprint_radius_m for o in robots
        )
        if clear and world.blocked(x, y, radius) is None:
            robots.append(
                RobotSpec(f"r{len(robots)}", x, y, float(rng.uniform(-3.2, 3.2)), model=body)
            )
    return replace(world, robots=tuple(robots))


def test_random_worlds_and_lidars_are_cast_as_the_reference() -> None:
    rng = np.random.default_rng(12)
    beams = 0
    for _ in range(60):
        world = _random_world(rng)
        if not world.robots:
            continue
        cast, lidars = fleet(world)
        poses = [(r.x, r.y, r.yaw) for r in world.robots]
        count = int(rng.integers(1, len(poses) + 1))
        scanning = sorted(rng.choice(len(poses), size=count, replace=False).tolist())
        for i, got in zip(scanning, cast(poses, scanning), strict=True):
            assert_cast_is_reference(got, reference(world, lidars, poses, i), i)
            beams += int(np.sum(got[0]))
    assert beams > 5000  # beams that met something
