"""The lidar against real pybullet ray casts: walls at known distances, empty space, other
robots, the beam-angle convention, and never the robot's own body."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from services.sim.sim import SimConfig, Simulation
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld

pytestmark = pytest.mark.timeout(30)

SIGMA = 0.01
# a 10 x 10 m free map: a wall whose face is at x = 3.0, and a short wall at y = 6.5 to the
# robot's left; everything else is farther than range_max from (1, 5)
WALLS = [(3.0, 0.0, 3.1, 10.0), (0.0, 6.5, 2.0, 6.6)]


def scans_of(
    make_world: MakeWorld, robots: list[dict[str, Any]], count: int = 1, **config: Any
) -> dict[str, list[np.ndarray]]:
    got: dict[str, list[np.ndarray]] = {}

    def sink(robot: str, topic: str, msg: dict[str, Any]) -> None:
        if topic == "scan":
            got.setdefault(robot, []).append(np.array(msg["ranges"]))

    world = load_world(make_world(10.0, 10.0, WALLS, robots=robots))
    sim = Simulation(world, SimConfig(**config), sink)
    try:
        # each robot scans on its own phase: wait for every robot's scans
        while min(len(got.get(r["id"], [])) for r in robots) < count:
            sim.step()
    finally:
        sim.close()
    return got


def test_beam_toward_a_wall_reads_its_distance(make_world: MakeWorld) -> None:
    ranges = scans_of(make_world, [{"id": "r1", "x": 1.0, "y": 5.0, "yaw": 0.0}])["r1"][0]
    assert len(ranges) == 360
    # beam 0 is straight ahead (+x): the wall face is 2.0 m away
    assert abs(ranges[0] - 2.0) < 3 * SIGMA
    # beams at +-30 degrees meet the same wall at 2 / cos(30 deg)
    for beam in (30, 330):
        assert abs(ranges[beam] - 2.0 / math.cos(math.radians(30))) < 3 * SIGMA
    # beam 90 (counter-clockwise: the robot's left, +y) meets the short wall 1.5 m away
    assert abs(ranges[90] - 1.5) < 3 * SIGMA
    # behind and to the right there is nothing within 3.5 m
    assert math.isinf(ranges[180]) and math.isinf(ranges[270])
    assert all(isinstance(v, float) for v in ranges.tolist())


def test_beams_turn_with_the_robot(make_world: MakeWorld) -> None:
    # facing +y, the wall at +x is to the right: beam 270
    ranges = scans_of(make_world, [{"id": "r1", "x": 1.0, "y": 5.0, "yaw": math.pi / 2}])["r1"][0]
    assert abs(ranges[270] - 2.0) < 3 * SIGMA
    assert abs(ranges[0] - 1.5) < 3 * SIGMA
    assert math.isinf(ranges[90])


def test_alone_in_open_space_every_beam_is_inf(make_world: MakeWorld) -> None:
    # (6.5, 5) is 3.4 m from the wall's back face at 3.1 and 3.5+ from the map's edges,
    # where there are no walls: only the robot's own body could be hit, and it must not be
    ranges = scans_of(make_world, [{"id": "r1", "x": 7.0, "y": 5.0}])["r1"][0]
    assert np.all(np.isinf(ranges))


def test_robots_see_each_other_but_not_themselves(make_world: MakeWorld) -> None:
    robots = [{"id": "r1", "x": 7.0, "y": 5.0}, {"id": "r2", "x": 8.0, "y": 5.0}]
    got = scans_of(make_world, robots)
    gap = 1.0 - 0.105  # centre to the other robot's surface
    r1, r2 = got["r1"][0], got["r2"][0]
    assert abs(r1[0] - gap) < 3 * SIGMA and abs(r2[180] - gap) < 3 * SIGMA
    assert np.isinf(r1[180]) and np.isinf(r2[0])


def test_noise_has_the_configured_sigma_and_the_seed_repeats(make_world: MakeWorld) -> None:
    robot = [{"id": "r1", "x": 1.0, "y": 5.0}]
    scans = scans_of(make_world, robot, count=40)["r1"]
    straight = np.array([s[0] for s in scans])
    assert abs(straight.mean() - 2.0) < 0.01
    assert 0.006 < straight.std() < 0.014
    again = scans_of(make_world, robot, count=3)["r1"]
    np.testing.assert_array_equal(again[2], scans[2])
    other_seed = scans_of(make_world, robot, count=1, seed=7)["r1"]
    assert not np.array_equal(other_seed[0], scans[0])


def test_noise_free_lidar_is_exact_and_clamps_to_range(make_world: MakeWorld) -> None:
    exact = {"name": "turtlebot3_burger", "lidar": {"noise_m": 0.0}}
    ranges = scans_of(make_world, [{"id": "r1", "x": 2.8, "y": 5.0, "model": exact}])["r1"][0]
    assert ranges[0] == pytest.approx(0.2, abs=1e-6)
    assert ranges.min() >= 0.12  # the Burger's range_min
