"""The simulation loop: sensors on sim time, walls stop robots, contacts become events."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest

from services.sim.robot import BURGER
from services.sim.sim import SimConfig, Simulation
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld

pytestmark = pytest.mark.timeout(30)


class Recorder:
    def __init__(self) -> None:
        self.msgs: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)

    def __call__(self, robot: str, topic: str, msg: dict[str, Any]) -> None:
        self.msgs[(robot, topic)].append(msg)


# A command set once is held for the whole run, as the stack's re-issues every 0.1 s would
# hold it: these tests are about motion and sensors; the command timeout has its own.
HELD: dict[str, Any] = {"cmd_timeout_s": 0.0}


def simulate(
    path: Path, commands: dict[str, tuple[float, float]], seconds: float, **config: Any
) -> tuple[Simulation, Recorder]:
    rec = Recorder()
    sim = Simulation(load_world(path), SimConfig(**{**HELD, **config}), rec)
    try:
        for robot, (v, w) in commands.items():
            assert sim.set_command(robot, v, w)
        sim.run_for(seconds)
    finally:
        sim.close()
    return sim, rec


def test_sensor_rates_are_counted_in_sim_time(make_world: MakeWorld) -> None:
    _, rec = simulate(make_world(4.0, 4.0), {}, 10.0)
    scans, odoms, bats = (rec.msgs[("r1", t)] for t in ("scan", "odom", "battery"))
    assert (len(scans), len(odoms), len(bats)) == (50, 300, 10)
    assert [m["stamp"] for m in scans[:3]] == pytest.approx([0.0, 0.2, 0.4])
    assert [m["seq"] for m in odoms] == list(range(300))
    assert odoms[1]["stamp"] == pytest.approx(1 / 30)


def test_scan_rate_is_configurable_and_independent_of_physics_rate(make_world: MakeWorld) -> None:
    _, rec = simulate(make_world(4.0, 4.0), {}, 4.0, scan_hz=10.0, physics_hz=120.0)
    assert len(rec.msgs[("r1", "scan")]) == 40 and len(rec.msgs[("r1", "odom")]) == 120


def test_driving_into_a_wall_stops_at_it_with_one_collision(make_world: MakeWorld) -> None:
    # wall face at x = 2.0; the robot starts at x = 1.0 and drives 0.22 m/s for 10 s
    path = make_world(4.0, 4.0, [(2.0, 0.0, 2.2, 4.0)])
    sim, rec = simulate(path, {"r1": (1.0, 0.0)}, 10.0)  # 1.0 is clamped to 0.22
    robot = sim.robots[0]
    assert 2.0 - 0.105 - 0.001 < robot.x <= 2.0 - 0.105 + 1e-9
    assert robot.y == pytest.approx(1.0)
    (event,) = rec.msgs[("r1", "collision")]
    assert event["other"] == "wall" and event["seq"] == 0
    assert event["x"] == pytest.approx(2.0 - 0.105, abs=0.001)
    # the contact starts after about (2.0 - 0.105 - 1.0) / 0.22 s, plus the half of the ramp
    # up to 0.22 m/s at the Burger's acceleration limit that is lost
    ramp_s = 0.22 / BURGER.max_linear_accel_mps2
    assert event["stamp"] == pytest.approx(0.895 / 0.22 + ramp_s / 2, abs=0.02)
    odom = rec.msgs[("r1", "odom")]
    assert odom[30]["linear"] == pytest.approx(0.22)
    assert odom[-1]["linear"] == 0.0  # pushing against the wall, not moving
    # against the wall the lidar reads range_min ahead, never inf or what lies beyond
    ranges = rec.msgs[("r1", "scan")][-1]["ranges"]
    assert ranges[0] == 0.12 and max(ranges[350:] + ranges[:11]) < 0.13


def test_backing_off_and_driving_in_again_is_a_new_contact(make_world: MakeWorld) -> None:
    path = make_world(4.0, 4.0, [(2.0, 0.0, 2.2, 4.0)])
    rec = Recorder()
    sim = Simulation(load_world(path), SimConfig(**HELD), rec)
    try:
        sim.set_command("r1", 0.22, 0.0)
        sim.run_for(5.0)
        sim.set_command("r1", -0.1, 0.0)
        sim.run_for(1.0)
        sim.set_command("r1", 0.22, 0.0)
        sim.run_for(1.0)
    finally:
        sim.close()
    assert [e["seq"] for e in rec.msgs[("r1", "collision")]] == [0, 1]


def test_turning_in_place_against_a_wall_is_free(make_world: MakeWorld) -> None:
    path = make_world(4.0, 4.0, [(2.0, 0.0, 2.2, 4.0)])
    rec = Recorder()
    sim = Simulation(load_world(path), SimConfig(**HELD), rec)
    try:
        sim.set_command("r1", 0.22, 0.0)
        sim.run_for(5.0)
        sim.set_command("r1", 0.0, 1.0)
        sim.run_for(1.0)
        # 1 rad/s for 1 s, less half the ramp up to it at the angular acceleration limit
        ramp_s = 1.0 / BURGER.max_angular_accel_rps2
        assert sim.robots[0].yaw == pytest.approx(1.0 - ramp_s / 2, abs=0.01)
    finally:
        sim.close()


def test_robots_bump_into_each_other_and_both_report_it(make_world: MakeWorld) -> None:
    robots = [{"id": "a", "x": 1.0, "y": 2.0}, {"id": "b", "x": 2.0, "y": 2.0}]
    sim, rec = simulate(make_world(4.0, 4.0, robots=robots), {"a": (0.2, 0.0)}, 6.0)
    assert [e["other"] for e in rec.msgs[("a", "collision")]] == ["b"]
    assert [e["other"] for e in rec.msgs[("b", "collision")]] == ["a"]
    a, b = sim.robots
    assert b.x - a.x >= 2 * 0.105 - 1e-9
    assert b.x == 2.0  # b is not pushed: every robot is kinematic


def test_extra_obstacles_stop_robots_and_are_named(make_world: MakeWorld) -> None:
    obstacles = [{"name": "bin", "type": "cylinder", "x": 2.0, "y": 1.0, "radius": 0.2}]
    sim, rec = simulate(make_world(4.0, 4.0, obstacles=obstacles), {"r1": (0.22, 0.0)}, 6.0)
    assert [e["other"] for e in rec.msgs[("r1", "collision")]] == ["bin"]
    assert sim.robots[0].x == pytest.approx(2.0 - 0.2 - 0.105, abs=0.002)


def test_same_seed_same_run(make_world: MakeWorld) -> None:
    path = make_world(4.0, 4.0, [(2.0, 0.0, 2.2, 4.0)])
    runs = [simulate(path, {"r1": (0.15, 0.4)}, 3.0, seed=3)[1] for _ in range(2)]
    assert runs[0].msgs == runs[1].msgs


def test_commands_are_clamped_and_unknown_robots_refused(make_world: MakeWorld) -> None:
    sim, rec = simulate(make_world(6.0, 6.0, robots=[{"id": "r1", "x": 3, "y": 3}]), {}, 0.0)
    assert not sim.set_command("ghost", 0.1, 0.0)
    path = make_world(6.0, 6.0, robots=[{"id": "r1", "x": 3.0, "y": 3.0}])
    _, rec = simulate(path, {"r1": (5.0, -10.0)}, 1.0)  # time to reach both limits
    last = rec.msgs[("r1", "odom")][-1]
    assert (last["linear"], last["angular"]) == (pytest.approx(0.22), pytest.approx(-2.84))
