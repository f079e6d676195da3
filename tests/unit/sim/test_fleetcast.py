"""The fleet's lidar cast: the static scene exactly as Bullet casts it, and the other robots
as the upright cylinders they are, met where each beam enters one, with robots crowded
together and against walls so that many beams meet other robots."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pybullet as p
import pytest

import services.sim.sim as sim_module
from services.sim.fleetcast import Cast, Pose, cast_fleet
from services.sim.lidar import Lidar
from services.sim.physics import RAY_BATCH, Scene
from services.sim.robot import BURGER
from services.sim.sim import SimConfig, Simulation
from services.sim.world import World, load_world
from tests.unit.sim.conftest import MakeWorld

pytestmark = pytest.mark.timeout(60)

# a 6 x 6 m map: a wall along x = 3, a pillar, and the map's edge walls
WALLS = [(3.0, 0.0, 3.1, 4.0), (1.0, 4.0, 1.3, 4.3), (0.0, 0.0, 6.0, 0.1), (0.0, 0.0, 0.1, 6.0)]
OBSTACLES = [
    {"name": "crate", "type": "box", "x": 4.5, "y": 1.0, "size": [0.4, 0.3, 0.4]},
    {"name": "bin", "type": "cylinder", "x": 2.0, "y": 5.0, "radius": 0.15, "height": 0.5},
]
ROBOTS = 12  # 12 x 360 beams: more than one rayTestBatch call holds
RADIUS = 0.105
# Bullet's convex cast against a cylinder is approximate near its edge: beams passing more
# than this outside or inside a body's edge get the same hit or miss from it as the exact
# cylinder, and a range within BULLET_RANGE_M (measured: up to 6 mm)
GRAZE_M = 0.001
BULLET_RANGE_M = 0.01


def static_cast(scene: Scene, lidar: Lidar, pose: Pose) -> Cast:
    """A robot's beams through the static scene: Bullet's cast with every robot lowered."""
    scene.hide(range(len(scene.robot_bodies)))
    try:
        return scene.cast(*lidar.rays(*pose))
    finally:
        scene.show(range(len(scene.robot_bodies)))


def reference(scene: Scene, lidars: Sequence[Lidar], poses: Sequence[Pose], i: int) -> Cast:
    """Robot i's beams as the lidar is defined, written out another way than the fleet cast:
    the static scene's hit, unless a beam's ray, projected on each other robot's centre,
    enters that robot's disc first (a body whose top reaches the beams' height)."""
    lidar = lidars[i]
    hit, fraction = static_cast(scene, lidar, poses[i])
    starts, ends = lidar.rays(*poses[i])
    length = lidar.params.range_max_m
    ux, uy = (ends[:, 0] - starts[:, 0]) / length, (ends[:, 1] - starts[:, 1]) / length
    x0, y0, _ = poses[i]
    for j, (x, y, _) in enumerate(poses):
        body = scene.robot_bodies[j]
        if j == i or scene.height[body] < lidar.height:
            continue
        r = scene.radius[body]
        along = (x - x0) * ux + (y - y0) * uy  # the centre's projection on the ray
        square = (x - x0) ** 2 + (y - y0) ** 2 - along**2  # its distance from the ray, squared
        enter = (along - np.sqrt(np.maximum(0.0, r * r - square))) / length
        first = (square <= r * r) & (enter >= 0.0) & (enter < fraction)
        hit = hit | first
        fraction = np.where(first, enter, fraction)
    return hit, fraction


def grazing(scene: Scene, lidar: Lidar, poses: Sequence[Pose], i: int) -> np.ndarray:
    """Robot i's beams that pass within GRAZE_M of another robot's edge, ahead of it."""
    starts, ends = lidar.rays(*poses[i])
    length = lidar.params.range_max_m
    ux, uy = (ends[:, 0] - starts[:, 0]) / length, (ends[:, 1] - starts[:, 1]) / length
    x0, y0, _ = poses[i]
    out = np.zeros(len(starts), dtype=bool)
    for j, (x, y, _) in enumerate(poses):
        if j != i:
            along = (x - x0) * ux + (y - y0) * uy
            off = np.sqrt(np.maximum(0.0, (x - x0) ** 2 + (y - y0) ** 2 - along**2))
            out |= (along > 0) & (np.abs(off - scene.radius[scene.robot_bodies[j]]) <= GRAZE_M)
    return out


def assert_cast_is_reference(got: Cast, want: Cast, bare: Cast, robot: int) -> None:
    """The fleet cast of one robot against :func:`reference`: the same beams meet something,
    a beam that meets no robot reads the static scene bit for bit, one that meets a robot
    the same entry point to rounding."""
    (hit, fraction), (want_hit, want_fraction) = got, want
    np.testing.assert_array_equal(hit, want_hit, err_msg=f"robot {robot}")
    robot_met = want_fraction < bare[1]
    np.testing.assert_array_equal(fraction < bare[1], robot_met, err_msg=f"robot {robot}")
    assert fraction[~robot_met].tobytes() == bare[1][~robot_met].tobytes(), f"robot {robot}"
    np.testing.assert_allclose(
        fraction[robot_met], want_fraction[robot_met], rtol=0, atol=1e-12, err_msg=f"robot {robot}"
    )


def crowd(rng: np.random.Generator, count: int) -> list[Pose]:
    """Robots packed at random in a 2.6 x 2.6 m corner against the walls, none overlapping
    (some touching: 1 mm apart), at any heading."""
    poses: list[Pose] = []
    while len(poses) < count:
        x, y = rng.uniform(0.25, 2.85), rng.uniform(0.25, 2.85)
        gaps = [math.hypot(x - px, y - py) for px, py, _ in poses]
        if not gaps or min(gaps) >= 2 * RADIUS + 0.001:
            poses.append((x, y, float(rng.uniform(-math.pi, math.pi))))
        if len(poses) == 1 and rng.random() < 0.5:
            # a pair touching, 1 mm apart, to graze
            x0, y0, _ = poses[0]
            poses.append((x0 + 2 * RADIUS + 0.001, y0, float(rng.uniform(-math.pi, math.pi))))
    return poses


def crowds(scene: Scene, seed: int, count: int) -> Iterator[list[Pose]]:
    """``count`` crowds (:func:`crowd`) of the scene's robots, each placed before it is
    yielded."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        poses = crowd(rng, len(scene.robot_bodies))
        for i, pose in enumerate(poses):
            scene.place(i, *pose)
        yield poses


@pytest.fixture
def world(make_world: MakeWorld) -> World:
    robots = [{"id": f"r{i}", "x": 0.5 + 0.4 * i, "y": 5.5} for i in range(ROBOTS)]
    return load_world(make_world(6.0, 6.0, WALLS, robots=robots, obstacles=OBSTACLES))


@pytest.fixture
def scene(world: World) -> Iterator[Scene]:
    scene = Scene(world)
    yield scene
    scene.close()


@pytest.fixture
def static(world: World) -> Iterator[Scene]:
    """The same walls and obstacles without the robots, as the sim's lidar casts them."""
    static = Scene(replace(world, robots=()))
    yield static
    static.close()


def test_beams_read_the_static_scene_or_the_first_robot_body_they_enter(
    scene: Scene, static: Scene
) -> None:
    lidars = [Lidar(BURGER.lidar)] * ROBOTS
    met = 0
    for poses in crowds(scene, seed=11, count=12):
        for scanning in (list(range(ROBOTS)), [0, 1], [3], list(range(0, ROBOTS, 3))):
            got = cast_fleet(scene, static, lidars, poses, scanning)
            assert not scene.hidden
            for i, cast in zip(scanning, got, strict=True):
                bare = static_cast(scene, lidars[i], poses[i])
                assert_cast_is_reference(cast, reference(scene, lidars, poses, i), bare, i)
                if len(scanning) == ROBOTS:
                    met += int(np.sum(cast[1] < bare[1]))
    assert ROBOTS * 360 > RAY_BATCH
    assert met > 12 * ROBOTS * 20  # the scene really crowds: beams met other robots


def test_robots_are_met_where_bullet_meets_them_but_for_beams_grazing_an_edge(
    scene: Scene, static: Scene
) -> None:
    # the sim's lidar against Bullet's own cast of one robot's beams with the other robots
    # in place: the closed form models the same bodies, only more exactly
    lidars = [Lidar(BURGER.lidar)] * ROBOTS
    compared = 0
    for poses in crowds(scene, seed=7, count=6):
        got = cast_fleet(scene, static, lidars, poses, list(range(ROBOTS)))
        for i, (hit, fraction) in enumerate(got):
            bullet_hit, bullet_fraction = scene.cast_from(i, *lidars[i].rays(*poses[i]))
            clear = ~grazing(scene, lidars[i], poses, i)
            np.testing.assert_array_equal(hit[clear], bullet_hit[clear], err_msg=f"robot {i}")
            gap = np.abs(fraction - bullet_fraction)[clear] * lidars[i].params.range_max_m
            assert gap.max() <= BULLET_RANGE_M, f"robot {i}"
            compared += int(np.sum(clear & (fraction < 1.0)))
    assert compared > 6 * ROBOTS * 200


def test_robots_are_back_in_place_after_the_cast(scene: Scene, static: Scene) -> None:
    lidar = Lidar(BURGER.lidar)
    poses = next(crowds(scene, seed=3, count=1))
    before = [
        p.getBasePositionAndOrientation(b, physicsClientId=scene.client) for b in scene.robot_bodies
    ]
    cast_fleet(scene, static, [lidar] * len(poses), poses, list(range(0, ROBOTS, 2)))
    after = [
        p.getBasePositionAndOrientation(b, physicsClientId=scene.client) for b in scene.robot_bodies
    ]
    assert after == before and not scene.hidden


def test_a_crowded_run_scans_as_the_reference_cast_per_robot(
    make_world: MakeWorld, monkeypatch: pytest.MonkeyPatch
) -> None:
    # robots a robot's width apart driving circles into each other and the walls, at 20 Hz:
    # several scan in the same step; every scan message, noise included, must be the
    # reference's, in the same order
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
    # cast_fleet's stand-in: the reference, one robot at a time (the static scene unused)
    monkeypatch.setattr(
        sim_module,
        "cast_fleet",
        lambda scene, _static, lidars, poses, scanning: [
            reference(scene, lidars, poses, i) for i in scanning
        ],
    )
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
    # the robot, crowded: a Burger sees Jackals, a Jackal's beams pass over Burgers, and the
    # partial fields of view must find exactly the robots within them, across beam 0's
    # direction too
    narrow = {"name": "turtlebot3_burger", "lidar": {"beams": 91, "fov_rad": math.pi / 2}}
    narrow["lidar"]["angle_min_rad"] = 3 * math.pi / 4  # type: ignore[index]
    kinds: list[Any] = ["jackal", None, narrow]
    robots = [
        {"id": f"r{i}", "x": 0.5 + 0.5 * i, "y": 5.5, "model": kinds[i % 3]} for i in range(9)
    ]
    for r in robots:
        if r["model"] is None:
            del r["model"]
    world = load_world(make_world(6.0, 6.0, WALLS, robots=robots, obstacles=OBSTACLES))
    scene, static = Scene(world), Scene(replace(world, robots=()))
    try:
        shared: dict[object, Lidar] = {}
        lidars = [shared.setdefault(m.lidar, Lidar(m.lidar)) for m in world.models]
        rng = np.random.default_rng(5)
        met = {"jackal": 0, "turtlebot3_burger": 0}
        for _ in range(8):
            poses: list[Pose] = []
            while len(poses) < len(robots):
                x, y = rng.uniform(0.35, 2.75), rng.uniform(0.35, 2.75)
                if all(math.hypot(x - px, y - py) >= 0.441 for px, py, _ in poses):
                    poses.append((x, y, float(rng.uniform(-math.pi, math.pi))))
            for i, pose in enumerate(poses):
                scene.place(i, *pose)
            for scanning in (list(range(len(robots))), [0, 2, 4], [2]):
                got = cast_fleet(scene, static, lidars, poses, scanning)
                for i, cast in zip(scanning, got, strict=True):
                    assert len(cast[0]) == world.models[i].lidar.beams
                    bare = static_cast(scene, lidars[i], poses[i])
                    assert_cast_is_reference(cast, reference(scene, lidars, poses, i), bare, i)
                    # and as Bullet sees the same bodies, heights included
                    bullet = scene.cast_from(i, *lidars[i].rays(*poses[i]))
                    clear = ~grazing(scene, lidars[i], poses, i)
                    np.testing.assert_array_equal(cast[0][clear], bullet[0][clear])
                    if len(scanning) == len(robots):
                        met[world.models[i].name] += int(np.sum(cast[1] < bare[1]))
        assert met["jackal"] > 50 and met["turtlebot3_burger"] > 50  # beams met other robots
    finally:
        scene.close()
        static.close()
