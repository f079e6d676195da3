"""The fleet's batched lidar cast against each robot's own cast: the same ranges, bit for
bit, with robots crowded together and against walls, so that many beams meet other robots."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
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
from services.sim.world import load_world
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


def per_robot(
    scene: Scene, lidars: Sequence[Lidar], poses: Sequence[Pose], scanning: Sequence[int]
) -> list[Cast]:
    """Today's reference: one cast per robot, its own body lowered."""
    return [scene.cast_from(i, *lidars[i].rays(*poses[i])) for i in scanning]


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


@pytest.fixture
def scene(make_world: MakeWorld) -> Iterator[Scene]:
    robots = [{"id": f"r{i}", "x": 0.5 + 0.4 * i, "y": 5.5} for i in range(ROBOTS)]
    world = load_world(make_world(6.0, 6.0, WALLS, robots=robots, obstacles=OBSTACLES))
    scene = Scene(world)
    yield scene
    scene.close()


def static_fraction(scene: Scene, lidar: Lidar, pose: Pose) -> np.ndarray:
    """The beams' fractions with every robot out of the way."""
    scene.hide(range(len(scene.robot_bodies)))
    try:
        return scene.cast(*lidar.rays(*pose))[1]
    finally:
        scene.show(range(len(scene.robot_bodies)))


def test_batched_cast_equals_each_robots_own_cast_bit_for_bit(scene: Scene) -> None:
    lidar = Lidar(BURGER.lidar)
    rng = np.random.default_rng(11)
    seen_robots = 0
    for _ in range(12):
        poses = crowd(rng, ROBOTS)
        for i, pose in enumerate(poses):
            scene.place(i, *pose)
        subsets = [list(range(ROBOTS)), [0, 1], [3], list(range(0, ROBOTS, 3))]
        for scanning in subsets:
            got = cast_fleet(scene, [lidar] * len(poses), poses, scanning)
            assert not scene.hidden
            want = per_robot(scene, [lidar] * len(poses), poses, scanning)
            for i, (hit, fraction), (want_hit, want_fraction) in zip(
                scanning, got, want, strict=True
            ):
                np.testing.assert_array_equal(hit, want_hit, err_msg=f"robot {i}")
                # bit for bit: equal as floats, and the same bytes
                assert fraction.tobytes() == want_fraction.tobytes(), f"robot {i}"
        # the scene really crowds: beams met other robots, nearer than the walls
        for i, pose in enumerate(poses):
            _, want_fraction = per_robot(scene, [lidar] * len(poses), poses, [i])[0]
            seen_robots += int(np.sum(want_fraction < static_fraction(scene, lidar, pose)))
    assert ROBOTS * 360 > RAY_BATCH
    assert seen_robots > 12 * ROBOTS * 20


def test_robots_are_back_in_place_after_the_cast(scene: Scene) -> None:
    lidar = Lidar(BURGER.lidar)
    poses = crowd(np.random.default_rng(3), ROBOTS)
    for i, pose in enumerate(poses):
        scene.place(i, *pose)
    before = [
        p.getBasePositionAndOrientation(b, physicsClientId=scene.client) for b in scene.robot_bodies
    ]
    cast_fleet(scene, [lidar] * len(poses), poses, list(range(0, ROBOTS, 2)))
    after = [
        p.getBasePositionAndOrientation(b, physicsClientId=scene.client) for b in scene.robot_bodies
    ]
    assert after == before and not scene.hidden


def test_a_crowded_run_scans_as_with_one_cast_per_robot(
    make_world: MakeWorld, monkeypatch: pytest.MonkeyPatch
) -> None:
    # robots a robot's width apart driving circles into each other and the walls, at 20 Hz:
    # several scan in the same step; every scan message, noise included, must be the same
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
    monkeypatch.setattr(sim_module, "cast_fleet", per_robot)
    alone = run()
    assert len(batched) == 12 * 40
    assert [robot for robot, _ in batched] == [robot for robot, _ in alone]
    for (_, got), (_, want) in zip(batched, alone, strict=True):
        assert np.array(got).tobytes() == np.array(want).tobytes()


def test_a_fleet_of_mixed_models_casts_as_each_robot_alone(make_world: MakeWorld) -> None:
    # Jackals (270-degree, 720-beam lidar, 0.22 m bodies), Burgers and a narrow 90-degree
    # lidar whose field of view starts behind the robot, crowded: the beams of one model meet
    # the bodies of the others, and the partial fields of view must find exactly the robots
    # within them, across beam 0's direction too
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
    scene = Scene(world)
    try:
        shared: dict[object, Lidar] = {}
        lidars = [shared.setdefault(m.lidar, Lidar(m.lidar)) for m in world.models]
        rng = np.random.default_rng(5)
        met = 0
        for _ in range(8):
            poses: list[Pose] = []
            while len(poses) < len(robots):
                x, y = rng.uniform(0.35, 2.75), rng.uniform(0.35, 2.75)
                if all(math.hypot(x - px, y - py) >= 0.441 for px, py, _ in poses):
                    poses.append((x, y, float(rng.uniform(-math.pi, math.pi))))
            for i, pose in enumerate(poses):
                scene.place(i, *pose)
            for scanning in (list(range(len(robots))), [0, 2, 4], [2]):
                got = cast_fleet(scene, lidars, poses, scanning)
                want = per_robot(scene, lidars, poses, scanning)
                for i, (hit, fraction), (want_hit, want_fraction) in zip(
                    scanning, got, want, strict=True
                ):
                    assert len(hit) == world.models[i].lidar.beams
                    np.testing.assert_array_equal(hit, want_hit, err_msg=f"robot {i}")
                    assert fraction.tobytes() == want_fraction.tobytes(), f"robot {i}"
            for i, pose in enumerate(poses):
                _, want_fraction = per_robot(scene, lidars, poses, [i])[0]
                met += int(np.sum(want_fraction < static_fraction(scene, lidars[i], pose)))
        assert met > 100  # beams really met other robots
    finally:
        scene.close()
