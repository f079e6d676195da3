"""Robot models in the sim: a world's robots name their model, the sim builds the body and
the lidar from it, publishes it in the world message, and the motors respect its
acceleration limits."""

from __future__ import annotations

import itertools
import math

import pytest

from common.errors import ModelError, WorldError
from common.robotmodel import load_model
from services.sim.__main__ import build, parse_args
from services.sim.robot import BURGER, accelerate
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld
from tests.unit.sim.test_sim import simulate

pytestmark = pytest.mark.timeout(30)

JACKAL = load_model("jackal")


def test_accelerate_moves_toward_the_target_by_at_most_limit_times_dt() -> None:
    assert accelerate(0.0, 2.0, 10.0, 0.01) == pytest.approx(0.1)  # speeding up
    assert accelerate(1.0, 0.0, 10.0, 0.01) == pytest.approx(0.9)  # slowing down
    assert accelerate(0.95, 1.0, 10.0, 0.01) == 1.0  # within one step: reached exactly
    assert accelerate(0.2, -0.2, 10.0, 0.01) == pytest.approx(0.1)  # reversing goes through 0


def test_a_robot_without_a_model_is_a_burger(make_world: MakeWorld) -> None:
    world = load_world(make_world(4.0, 4.0))
    assert world.robots[0].model == BURGER
    assert world.message()["robots"][0]["model"] == "turtlebot3_burger"


def test_a_robot_names_its_model_and_overrides_fields(make_world: MakeWorld) -> None:
    robots = [
        {"id": "j", "x": 1.0, "y": 1.0, "model": "jackal"},
        {"id": "k", "x": 2.5, "y": 1.0, "model": {"name": "jackal", "max_linear_mps": 1.5}},
        {"id": "b", "x": 1.0, "y": 2.5},
    ]
    world = load_world(make_world(4.0, 4.0, robots=robots))
    j, k, b = world.robots
    assert j.model == JACKAL and b.model == BURGER
    assert k.model.max_linear_mps == 1.5 and k.model.lidar == JACKAL.lidar
    rows = {r["robot_id"]: r for r in world.message()["robots"]}
    assert rows["j"]["lidar_beams"] == 720 and rows["j"]["footprint_radius_m"] == 0.22
    assert rows["k"]["max_linear_mps"] == 1.5 and rows["b"]["lidar_beams"] == 360


def test_the_default_model_applies_to_robots_that_name_none(make_world: MakeWorld) -> None:
    robots = [
        {"id": "a", "x": 1.0, "y": 1.0},
        {"id": "b", "x": 2.5, "y": 1.0, "model": "turtlebot3_burger"},
    ]
    world = load_world(make_world(4.0, 4.0, robots=robots), model="jackal")
    assert [r.model.name for r in world.robots] == ["jackal", "turtlebot3_burger"]
    # extra robots are of the default model too
    assert world.with_robot_count(3).robots[2].model == JACKAL


@pytest.mark.parametrize(
    ("model", "problem"),
    [
        ("hovercraft", r"robots\[0\]: model: no robot model 'hovercraft'"),
        ({"max_linear_mps": 1.0}, r"robots\[0\]: model: a mapping needs 'name'"),
        (
            {"name": "jackal", "lidar": {"beams": 0}},
            r"robots\[0\]: model: models/jackal\.yaml \(overridden\): lidar\.beams: ",
        ),
        ({"name": "jackal", "wheels": 6}, r"robots\[0\]: model: .*: wheels: unknown field"),
        (3, r"robots\[0\]: model: must be a model name"),
    ],
)
def test_a_bad_model_in_a_world_names_the_world_the_robot_and_the_field(
    make_world: MakeWorld, model: object, problem: str
) -> None:
    path = make_world(4.0, 4.0, robots=[{"id": "r1", "x": 1.0, "y": 1.0, "model": model}])
    with pytest.raises(WorldError, match=f"^{path}: {problem}"):
        load_world(path)


def test_a_bigger_footprint_is_checked_at_the_start_pose(make_world: MakeWorld) -> None:
    # 0.15 m from the wall: room for a Burger (0.105 m), not for a Jackal (0.22 m)
    walls = [(0.0, 0.0, 4.0, 0.85)]
    robot = {"id": "r1", "x": 2.0, "y": 1.0}
    load_world(make_world(4.0, 4.0, walls, robots=[robot]))
    with pytest.raises(WorldError, match="inside an obstacle"):
        load_world(make_world(4.0, 4.0, walls, robots=[{**robot, "model": "jackal"}]))


def test_a_jackal_scans_its_model_lidar(make_world: MakeWorld) -> None:
    robots = [{"id": "j", "x": 2.0, "y": 2.0, "model": "jackal"}, {"id": "b", "x": 1.0, "y": 1.0}]
    _, rec = simulate(make_world(8.0, 4.0, [(6.0, 0.0, 6.2, 4.0)], robots=robots), {}, 1.0)
    jackal, burger = rec.msgs[("j", "scan")], rec.msgs[("b", "scan")]
    # each at its model's rate: 50 Hz and 5 Hz
    assert (len(jackal), len(burger)) == (50, 5)
    scan = jackal[0]
    assert len(scan["ranges"]) == 720 and len(burger[0]["ranges"]) == 360
    assert scan["angle_min"] == pytest.approx(math.radians(-135.0), abs=1e-6)
    assert scan["angle_increment"] == pytest.approx(math.radians(270.0) / 719)
    assert (scan["range_min"], scan["range_max"]) == (0.1, 30.0)
    # beam 0 points 135 degrees right of the heading; the middle beam straight ahead (+x),
    # where the wall's face is 4.0 m away: a range the Burger's 3.5 m lidar could not read
    middle = scan["ranges"][359:361]
    assert min(middle) == pytest.approx(4.0, abs=0.01)


def test_motors_reach_a_command_at_the_models_acceleration_limit(make_world: MakeWorld) -> None:
    path = make_world(12.0, 4.0, robots=[{"id": "j", "x": 1.0, "y": 2.0, "model": "jackal"}])
    _, rec = simulate(path, {"j": (2.0, 0.0)}, 1.0)
    odom = rec.msgs[("j", "odom")]
    # 10 m/s^2: 2.0 m/s after 0.2 s, speed growing by at most 10 m/s^2 x the time between
    for before, after in itertools.pairwise(odom):
        gained = after["linear"] - before["linear"]
        assert 0.0 <= gained <= 10.0 * (after["stamp"] - before["stamp"]) + 1e-9
    ramp = [m for m in odom if 0.0 < m["stamp"] < 0.2]
    assert ramp and all(m["linear"] < 2.0 for m in ramp)
    assert all(m["linear"] == pytest.approx(2.0) for m in odom if m["stamp"] >= 0.21)
    # speed within one physics step's gain of accel x time all along the ramp: at the
    # limit, not below it
    for m in ramp:
        assert m["linear"] == pytest.approx(10.0 * m["stamp"], abs=10.0 / 240 + 1e-9)


def test_the_sim_option_and_variable_set_the_default_model(
    make_world: MakeWorld, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("PNAV_SIM_MODEL", raising=False)
    path = str(make_world(4.0, 4.0))
    assert build(parse_args(["--world", path]))[0].robots[0].model == BURGER
    assert build(parse_args(["--world", path, "--model", "jackal"]))[0].robots[0].model == JACKAL
    monkeypatch.setenv("PNAV_SIM_MODEL", "jackal")
    assert build(parse_args(["--world", path]))[0].robots[0].model == JACKAL
    with pytest.raises(ModelError, match="no robot model 'tank'"):
        build(parse_args(["--world", path, "--model", "tank"]))
