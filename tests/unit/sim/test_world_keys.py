"""A world file, a robot entry, a charger, an obstacle and a map YAML refuse a key they do not
know, naming it and the closest known one (a typo is never silently ignored); a number YAML
1.1 would read as text is read as the number it is."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from common.errors import WorldError
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld, draw, write_map, write_world

pytestmark = pytest.mark.timeout(30)

R1 = {"id": "r1", "x": 1.0, "y": 1.0}


def refusal(path: Path) -> str:
    with pytest.raises(WorldError) as err:
        load_world(path)
    message = str(err.value)
    assert message.startswith(f"{path}: "), message
    return message


def test_a_typo_on_a_robot_entry_is_refused_with_the_key_it_meant(make_world: MakeWorld) -> None:
    message = refusal(make_world(3.0, 3.0, robots=[{**R1, "battry": 20}]))
    assert "robots[0]: unknown key 'battry' (did you mean 'battery'?" in message


@pytest.mark.parametrize("field", ["footprint_radius_m", "max_linear_mps", "lidar"])
def test_a_model_field_on_a_robot_entry_says_to_write_it_in_the_model(
    make_world: MakeWorld, field: str
) -> None:
    message = refusal(make_world(3.0, 3.0, robots=[{**R1, "model": "jackal", field: -1}]))
    assert f"robots[0]: '{field}' is a field of the robot model" in message
    assert "write it in 'model'" in message


@pytest.mark.parametrize(
    ("doc", "problem"),
    [
        ({"wall_hieght": 0.5}, "unknown key 'wall_hieght' (did you mean 'wall_height'?"),
        ({"obstacle": []}, "unknown key 'obstacle' (did you mean 'obstacles'?"),
        (
            {"charging_stations": [{"id": "d", "x": 2, "y": 2, "pwr": 5}]},
            "charging_stations[0]: unknown key 'pwr' (did you mean 'power'?",
        ),
        (
            {"obstacles": [{"type": "cylinder", "x": 2, "y": 2, "radius": 0.1, "size": [1, 1, 1]}]},
            "obstacles[0]: unknown key 'size' (known: height, name, radius, type, x, y, yaw): "
            "a cylinder has no such key",
        ),
        (
            {"obstacles": [{"type": "box", "x": 2, "y": 2, "size": [1, 1, 1], "radius": 1}]},
            "obstacles[0]: unknown key 'radius' (known: name, size, type, x, y, yaw)",
        ),
    ],
)
def test_an_unknown_key_anywhere_in_a_world_is_refused(
    make_world: MakeWorld, doc: dict[str, Any], problem: str
) -> None:
    assert problem in refusal(make_world(3.0, 3.0, **doc))


def test_an_unknown_key_in_a_map_yaml_is_refused(tmp_path: Path) -> None:
    write_map(tmp_path, draw(3.0, 3.0, []), ocupied_thresh=0.6)
    path = write_world(tmp_path, "map.yaml", robots=[R1])
    message = refusal(path)
    assert "map.yaml: unknown key 'ocupied_thresh' (did you mean 'occupied_thresh'?" in message


def test_a_world_with_a_benchmark_block_and_every_known_key_loads(make_world: MakeWorld) -> None:
    world = load_world(
        make_world(
            3.0,
            3.0,
            robots=[{**R1, "yaw": 0.0, "battery": 50, "model": "turtlebot3_burger"}],
            charging_stations=[{"id": "d", "x": 2.5, "y": 2.5, "radius": 0.3, "power": 20}],
            obstacles=[{"name": "c", "type": "cylinder", "x": 2, "y": 1, "radius": 0.1}],
            wall_height=0.4,
            benchmark={"format": 1},
        )
    )
    assert world.robots[0].battery_percent == 50.0


def test_exponent_notation_in_a_world_file_is_a_number(tmp_path: Path) -> None:
    write_map(tmp_path, draw(3.0, 3.0, []))
    path = tmp_path / "world.yaml"
    path.write_text("map: map.yaml\nrobots:\n  - {id: r1, x: 1e0, y: 1.0e0, battery: 5e1}\n")
    robot = load_world(path).robots[0]
    assert (robot.x, robot.y, robot.battery_percent) == (1.0, 1.0, 50.0)
    path.write_text("map: map.yaml\nrobots:\n  - {id: r1, x: 1.0, y: 1.0, battery: 1.0e308}\n")
    assert "'battery' is a percentage within [0, 100], got 1e+308" in refusal(path)
