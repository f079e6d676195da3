"""Moving obstacles: where they are at a sim time (both modes), moved by the sim in step,
seen by the lidar and not by the map, a collision naming the mover, bad entries refused."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from common import bus
from common.errors import WorldError
from services.bridge.world_message import parse_world
from services.sim.sim import SimConfig, Simulation
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld
from tests.unit.sim.test_sim import Recorder, simulate

pytestmark = pytest.mark.timeout(60)

BURGER_R = 0.105


def walker(**over: Any) -> dict[str, Any]:
    """A cylinder crossing x = 3 upwards, from y = 0.5 to 3.5 at 0.5 m/s."""
    doc = {
        "name": "walker",
        "type": "cylinder",
        "radius": 0.2,
        "path": [[3.0, 0.5], [3.0, 3.5]],
        "speed": 0.5,
        "mode": "back_and_forth",
    }
    return {**doc, **over}


def test_back_and_forth_runs_the_path_to_its_end_and_back(make_world: MakeWorld) -> None:
    (m,) = load_world(make_world(5.0, 4.0, movers=[walker()])).movers
    assert m.period_s == pytest.approx(12.0)
    expected = {
        0.0: (3.0, 0.5, math.pi / 2),
        2.0: (3.0, 1.5, math.pi / 2),
        6.0: (3.0, 3.5, math.pi / 2),
        7.0: (3.0, 3.0, -math.pi / 2),  # on the way back, heading down
        12.0: (3.0, 0.5, math.pi / 2),
        14.0: (3.0, 1.5, math.pi / 2),
    }
    for t, pose in expected.items():
        assert m.pose_at(t) == pytest.approx(pose), t


def test_loop_closes_the_path_and_offset_starts_it_along(make_world: MakeWorld) -> None:
    square = [[2.0, 1.0], [4.0, 1.0], [4.0, 3.0], [2.0, 3.0]]
    movers = [
        walker(name="a", path=square, speed=1.0, mode="loop"),
        walker(name="b", path=square, speed=1.0, mode="loop", offset=3.0),
    ]
    a, b = load_world(make_world(5.0, 4.0, movers=movers)).movers
    assert a.period_s == pytest.approx(8.0)
    assert a.pose_at(1.0) == pytest.approx((3.0, 1.0, 0.0))
    assert a.pose_at(3.0) == pytest.approx((4.0, 2.0, math.pi / 2))
    assert a.pose_at(7.0) == pytest.approx((2.0, 2.0, -math.pi / 2))  # the closing leg
    assert a.pose_at(9.0) == pytest.approx(a.pose_at(1.0))
    assert b.pose_at(0.0) == pytest.approx(a.pose_at(3.0))


def test_the_sim_moves_a_mover_on_sim_time_and_repeats_exactly(make_world: MakeWorld) -> None:
    path = make_world(5.0, 4.0, movers=[walker()])
    sim, _ = simulate(path, {}, 3.0)
    # 3 s at 0.5 m/s from y = 0.5, put there by the last physics step
    assert sim.movers.poses[0] == pytest.approx((3.0, 2.0, math.pi / 2))
    runs = [simulate(path, {"r1": (0.1, 0.3)}, 4.0, seed=5)[1] for _ in range(2)]
    assert runs[0].msgs == runs[1].msgs


def forward_range(scan: dict[str, Any]) -> float:
    """The range of the beam straight ahead."""
    beam = round(-scan["angle_min"] / scan["angle_increment"]) % len(scan["ranges"])
    return float(scan["ranges"][beam])


def test_the_lidar_sees_a_mover_and_the_map_does_not(make_world: MakeWorld) -> None:
    robots = [{"id": "r1", "x": 1.0, "y": 2.0, "yaw": 0.0}]
    still = load_world(make_world(5.0, 4.0, robots=robots))
    world = load_world(make_world(5.0, 4.0, movers=[walker()], robots=robots))
    assert world.grid.to_bytes() == still.grid.to_bytes()
    assert not world.grid.occupied_near(3.0, 2.0, 0.3)
    rec = Recorder()
    sim = Simulation(world, SimConfig(cmd_timeout_s=0.0), rec)
    try:
        seen: dict[float, float] = {}
        for t in (0.0, 3.0):  # the walker below the beam, then across it
            sim.run_for(t - sim.time)
            sim.step()  # a step senses first, at exactly t
            scans = rec.msgs[("r1", "scan")]
            seen[t] = forward_range(scans[-1]) if scans[-1]["stamp"] <= t else math.nan
    finally:
        sim.close()
    # nothing ahead but the far wall (beyond the Burger's range) at first
    assert seen[0.0] == math.inf or seen[0.0] > 3.0
    assert seen[3.0] == pytest.approx(3.0 - 0.2 - 1.0, abs=0.05)


def test_a_robot_hit_by_a_mover_gets_a_collision_naming_it(make_world: MakeWorld) -> None:
    robots = [{"id": "r1", "x": 3.0, "y": 2.5, "yaw": 0.0}]
    movers = [
        walker(),
        {
            "name": "cart",
            "type": "box",
            "size": [0.6, 0.4],
            "path": [[0.5, 1], [4.5, 1]],
            "speed": 1.0,
        },
    ]
    sim, rec = simulate(make_world(5.0, 4.0, movers=movers, robots=robots), {}, 4.0)
    events = rec.msgs[("r1", "collision")]
    assert [e["other"] for e in events] == ["walker"]
    # it arrived from below: it met the robot when their discs touched
    hit_at = (2.5 - 0.2 - BURGER_R - 0.5) / 0.5
    assert events[0]["stamp"] == pytest.approx(hit_at, abs=2 * sim.dt)
    assert (sim.robots[0].x, sim.robots[0].y) == (3.0, 2.5)  # a mover pushes nothing


def test_a_driving_robot_meets_a_box_mover(make_world: MakeWorld) -> None:
    robots = [{"id": "r1", "x": 2.0, "y": 0.5, "yaw": math.pi / 2}]
    box = {
        "name": "cart",
        "type": "box",
        "size": [0.6, 0.4],
        "path": [[0.5, 2], [4.5, 2]],
        "speed": 0.3,
        "mode": "back_and_forth",
    }
    world = make_world(5.0, 4.0, movers=[box], robots=robots)
    _, rec = simulate(world, {"r1": (0.2, 0.0)}, 9.0)
    assert [e["other"] for e in rec.msgs[("r1", "collision")]] == ["cart"]


@pytest.mark.parametrize(
    ("entry", "field"),
    [
        (walker(speed=float("nan")), "'speed' must be finite"),
        (walker(speed=0.0), "'speed' must be positive"),
        (walker(speed=-1.0), "'speed' must be positive"),
        (walker(speed=400.0), "'speed' must be at most 10 m/s"),
        (walker(path=[[3.0, 0.5]]), "'path' must list at least 2 points"),
        (walker(path=[[3.0, 0.5], [3.0, 0.5]]), "'path' must have some length"),
        (walker(path=[[3.0, 0.5], [3.0, float("inf")]]), "'path'[1] must be [x, y]"),
        (walker(path=[[0.0, 0.0]] * 1001), "'path' must list at most 1000 points"),
        (walker(mode="pingpong"), "'mode' must be loop or back_and_forth"),
        (walker(offset=float("nan")), "'offset' must be finite"),
        (walker(radius=-0.2), "'radius' must be positive"),
        (walker(type="cone"), "'type' must be cylinder (or circle) or box"),
        (walker(size=[1, 1]), "a cylinder mover has no such key"),
        ({**walker(type="box", size=[0.5, float("nan")])}, "'size' must be"),
    ],
)
def test_bad_mover_entries_are_refused_naming_the_field(
    make_world: MakeWorld, entry: dict[str, Any], field: str
) -> None:
    if entry.get("type") == "box":
        entry.pop("radius")
    with pytest.raises(WorldError) as err:
        load_world(make_world(5.0, 4.0, movers=[entry]))
    message = str(err.value)
    assert "movers[0]" in message and field in message, message
    assert "\n" not in message


def test_too_many_movers_a_robot_on_one_and_shared_names_are_refused(
    make_world: MakeWorld, tmp_path: Path
) -> None:
    many = [walker(name=f"m{i}") for i in range(101)]
    with pytest.raises(WorldError, match="at most 100 movers, got 101"):
        load_world(make_world(5.0, 4.0, movers=many))
    robots = [{"id": "r1", "x": 3.0, "y": 0.6}]
    with pytest.raises(WorldError, match=r"inside an obstacle \(mover walker"):
        load_world(make_world(5.0, 4.0, movers=[walker()], robots=robots))
    bin_ = {"name": "walker", "type": "cylinder", "x": 4.5, "y": 3.5, "radius": 0.1}
    with pytest.raises(WorldError, match=r"duplicate obstacle or mover id\(s\) walker"):
        load_world(make_world(5.0, 4.0, movers=[walker()], obstacles=[bin_]))


def test_the_world_message_lists_the_movers(make_world: MakeWorld) -> None:
    world = load_world(make_world(5.0, 4.0, movers=[walker()]))
    (m,) = world.message()["movers"]
    assert m == {
        "name": "walker",
        "type": "cylinder",
        "size": [0.4, 0.4, 1.0],
        "path": [[3.0, 0.5], [3.0, 3.5]],
        "speed_mps": 0.5,
        "mode": "back_and_forth",
        "offset_m": 0.0,
    }


def test_the_bridge_reads_a_world_message_with_movers_and_its_static_map(
    make_world: MakeWorld,
) -> None:
    """An old reader (the bridge stores the map and ignores the movers) takes the message of
    a world with movers: the map it stores is the walls alone."""
    still = parse_world(bus.pack(load_world(make_world(5.0, 4.0)).message()))
    moving = parse_world(bus.pack(load_world(make_world(5.0, 4.0, movers=[walker()])).message()))
    assert moving.map == still.map and moving.robots == still.robots


@pytest.mark.parametrize("which", ["fast walker", "turning box"])
def test_skipping_contact_tests_while_clear_misses_no_mover(
    make_world: MakeWorld, which: str
) -> None:
    """The sim skips a robot's contact tests while nothing can have reached it (its
    clearance over the fastest closing speed, a robot's and a mover's, less a box's corner
    jump where its path turns). A run that tests every step gets the same events and poses:
    a walker ten times as fast as the Burger, met by a driving robot; a box whose corner
    swings onto a standing robot where its path turns."""
    if which == "fast walker":
        robot = {"id": "r1", "x": 0.5, "y": 2.0, "yaw": 0.0}
        mover = walker(speed=2.5, path=[[2.0, 0.5], [2.0, 3.5]])
        command = (0.2, 0.0)
    else:
        robot = {"id": "r1", "x": 4.6, "y": 3.2, "yaw": 0.0}  # just past the cart's turn
        mover = {"name": "cart", "type": "box", "size": [0.9, 0.3], "speed": 1.5,
                 "mode": "loop", "path": [[3.2, 2.6], [4.6, 2.6], [4.6, 3.0]]}  # fmt: skip
        command = (0.0, 1.0)
    path = make_world(5.0, 4.0, movers=[mover], robots=[robot])
    runs = []
    for every_step in (False, True):
        rec = Recorder()
        sim = Simulation(load_world(path), SimConfig(cmd_timeout_s=0.0), rec)
        if every_step:
            sim._closing = math.inf  # no step is ever thought clear
        try:
            sim.set_command("r1", *command)
            sim.run_for(12.0)
        finally:
            sim.close()
        runs.append(rec.msgs)
    assert runs[0] == runs[1]
    assert {e["other"] for e in runs[0][("r1", "collision")]} == {mover["name"]}


@pytest.mark.parametrize("shape", ["box", "cylinder"])
def test_a_mover_reads_as_the_same_obstacle_standing_there(
    make_world: MakeWorld, shape: str
) -> None:
    """A Jackal's first scan (720 beams over 270 degrees) with a mover where it is at sim
    time 0 reads what it reads with a standing obstacle of that shape there: the movers'
    cast agrees with the sim's closed-form cast of the static world, beam by beam."""
    robots = [{"id": "r1", "x": 1.0, "y": 2.3, "yaw": 0.2, "model": "jackal"}]
    heading = 0.4
    ahead = [3.0 + math.cos(heading), 2.0 + math.sin(heading)]
    if shape == "box":
        standing = {"name": "thing", "type": "box", "x": 3.0, "y": 2.0, "yaw": heading,
                    "size": [0.6, 0.4, 1.0]}  # fmt: skip
        moving = {"name": "thing", "type": "box", "size": [0.6, 0.4, 1.0],
                  "path": [[3.0, 2.0], ahead], "speed": 0.5}  # fmt: skip
    else:
        standing = {"name": "thing", "type": "cylinder", "x": 3.0, "y": 2.0, "radius": 0.3,
                    "height": 1.0}  # fmt: skip
        moving = walker(name="thing", radius=0.3, path=[[3.0, 2.0], ahead])
    scans = []
    for doc in ({"obstacles": [standing]}, {"movers": [moving]}):
        rec = Recorder()
        sim = Simulation(load_world(make_world(5.0, 4.0, robots=robots, **doc)), SimConfig(), rec)
        try:
            sim.step()  # senses at sim time 0
        finally:
            sim.close()
        scans.append(rec.msgs[("r1", "scan")][0]["ranges"])
    assert len(scans[0]) == 720
    hits = [i for i, r in enumerate(scans[0]) if r < math.inf]  # the thing (no walls here)
    assert len(hits) > 20
    assert scans[1] == pytest.approx(scans[0], abs=1e-9)
