"""World files: the shipped worlds load and fit their purpose; bad worlds fail at load with a
WorldError that names the file and the problem."""

from __future__ import annotations

from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from common.errors import WorldError
from services.sim.mapserver import FREE
from services.sim.world_spec import World, load_world
from tests.unit.sim.conftest import MakeWorld, draw, write_map, write_world

pytestmark = pytest.mark.timeout(30)

WORLDS = Path(__file__).resolve().parents[3] / "worlds"


def load_error(path: Path) -> str:
    with pytest.raises(WorldError) as err:
        load_world(path)
    message = str(err.value)
    assert str(path) in message, f"the error does not name the file: {message}"
    return message


# -- bad maps --------------------------------------------------------------------------------
def bad_map(tmp_path: Path, **overrides: Any) -> Path:
    map_path = write_map(tmp_path, draw(3.0, 3.0, []), **overrides)
    write_world(tmp_path, "map.yaml", robots=[{"id": "r1", "x": 1.0, "y": 1.0}])
    return map_path


def test_missing_image_names_the_map_and_the_image(tmp_path: Path) -> None:
    map_path = bad_map(tmp_path, image="nowhere.pgm")
    message = load_error(tmp_path / "world.yaml")
    assert str(map_path) in message and "nowhere.pgm" in message and "not found" in message


@pytest.mark.parametrize("key", ["occupied_thresh", "free_thresh"])
@pytest.mark.parametrize("value", [-0.1, 1.5])
def test_thresholds_outside_zero_one(tmp_path: Path, key: str, value: float) -> None:
    map_path = bad_map(tmp_path, **{key: value})
    message = load_error(map_path)
    assert key in message and "[0, 1]" in message


def test_free_threshold_not_below_occupied(tmp_path: Path) -> None:
    message = load_error(bad_map(tmp_path, free_thresh=0.7, occupied_thresh=0.6))
    assert "free_thresh" in message and "below occupied_thresh" in message


@pytest.mark.parametrize("resolution", [0, -0.05, "fine", float("nan")])
def test_bad_resolution(tmp_path: Path, resolution: Any) -> None:
    assert "resolution" in load_error(bad_map(tmp_path, resolution=resolution))


@pytest.mark.parametrize("key", ["image", "resolution", "origin", "negate", "free_thresh"])
def test_map_missing_required_key(tmp_path: Path, key: str) -> None:
    message = load_error(bad_map(tmp_path, **{key: None}))
    assert "missing required key" in message and key in message


def test_bad_origin_and_mode(tmp_path: Path) -> None:
    assert "origin" in load_error(bad_map(tmp_path, origin=[0.0, 0.0]))
    assert "mode" in load_error(bad_map(tmp_path, mode="scale"))


# -- bad worlds ------------------------------------------------------------------------------
def test_start_pose_inside_an_obstacle(make_world: MakeWorld) -> None:
    path = make_world(3.0, 3.0, [(1.0, 0.0, 1.1, 3.0)], robots=[{"id": "r1", "x": 1.05, "y": 1}])
    message = load_error(path)
    assert "r1" in message and "inside an obstacle" in message


def test_start_pose_too_close_to_a_wall(make_world: MakeWorld) -> None:
    # the wall face is at x=1.0; a centre 0.05 m away puts the 0.105 m footprint into it
    path = make_world(3.0, 3.0, [(1.0, 0.0, 1.1, 3.0)], robots=[{"id": "r1", "x": 0.95, "y": 1}])
    assert "inside an obstacle" in load_error(path)


def test_start_pose_inside_an_extra_obstacle(make_world: MakeWorld) -> None:
    path = make_world(
        3.0,
        3.0,
        obstacles=[{"name": "crate", "type": "box", "x": 1.2, "y": 1.0, "size": [0.3, 0.3, 0.3]}],
    )
    message = load_error(path)
    assert "inside an obstacle" in message and "crate" in message


def test_start_pose_outside_the_map(make_world: MakeWorld) -> None:
    path = make_world(3.0, 3.0, robots=[{"id": "r1", "x": 4.0, "y": 1.0}])
    message = load_error(path)
    assert "r1" in message and "outside the map" in message


def test_robots_overlapping_each_other(make_world: MakeWorld) -> None:
    robots = [{"id": "r1", "x": 1.0, "y": 1.0}, {"id": "r2", "x": 1.1, "y": 1.0}]
    assert "overlaps robot r1" in load_error(make_world(3.0, 3.0, robots=robots))


@pytest.mark.parametrize(
    "doc, problem",
    [
        ({"robots": [{"id": "r1", "x": 1.0, "y": 1.0}]}, "missing required key 'map'"),
        ({"map": "map.yaml"}, "missing required key 'robots'"),
        ({"map": "map.yaml", "robots": [{"id": "r1", "y": 1.0}]}, "missing required key 'x'"),
        ({"map": "map.yaml", "robots": [{"x": 1.0, "y": 1.0}]}, "missing required key 'id'"),
        ({"map": "map.yaml", "robots": [{"id": "r 1", "x": 1.0, "y": 1.0}]}, "must match"),
        ({"map": "gone.yaml", "robots": [{"id": "r1", "x": 1, "y": 1}]}, "map file not found"),
        (
            {"map": "map.yaml", "robots": [{"id": "r1", "x": 1, "y": 1, "battery": 120}]},
            "'battery' is a percentage",
        ),
        (
            {
                "map": "map.yaml",
                "robots": [{"id": "r1", "x": 1, "y": 1}],
                "charging_stations": [{"id": "d", "x": 2, "y": 2, "radius": 0}],
            },
            "'radius' must be positive",
        ),
        (
            {
                "map": "map.yaml",
                "robots": [{"id": "r1", "x": 1, "y": 1}],
                "obstacles": [{"type": "cone", "x": 2, "y": 2}],
            },
            "'type' must be box or cylinder",
        ),
    ],
)
def test_bad_world_documents(tmp_path: Path, doc: dict[str, Any], problem: str) -> None:
    write_map(tmp_path, draw(3.0, 3.0, []))
    path = tmp_path / "world.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert problem in load_error(path)


def test_missing_world_file_and_bad_yaml(tmp_path: Path) -> None:
    assert "not found" in load_error(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("robots: [unclosed\n")
    assert "cannot read" in load_error(bad)


# -- good worlds -----------------------------------------------------------------------------
def test_a_bare_map_is_a_world_with_one_robot_on_free_ground(tmp_path: Path) -> None:
    world = load_world(write_map(tmp_path, draw(3.0, 3.0, [(0.0, 0.0, 3.0, 0.5)])))
    assert [r.robot_id for r in world.robots] == ["r1"]
    r = world.robots[0]
    assert world.blocked(r.x, r.y, world.default_model.footprint_radius_m) is None


def test_extra_robots_are_placed_apart_on_free_ground() -> None:
    world = load_world(WORLDS / "warehouse.yaml").with_robot_count(10)
    ids = [r.robot_id for r in world.robots]
    assert ids[:2] == ["r1", "r2"] and len(set(ids)) == 10
    for i, a in enumerate(world.robots):
        assert world.blocked(a.x, a.y, world.default_model.footprint_radius_m) is None
        for b in world.robots[i + 1 :]:
            assert np.hypot(a.x - b.x, a.y - b.y) >= 2 * world.default_model.footprint_radius_m
    assert [r.robot_id for r in world.with_robot_count(1).robots] == ["r1"]


def test_world_message_follows_the_contract() -> None:
    world = load_world(WORLDS / "open_room.yaml")
    msg = world.message()
    assert set(msg) == {"name", "map", "robots", "charging_stations"}
    assert set(msg["map"]) == {"resolution", "origin", "width", "height", "grid", "source"}
    assert isinstance(msg["map"]["grid"], bytes)
    assert len(msg["map"]["grid"]) == msg["map"]["width"] * msg["map"]["height"]
    robot = msg["robots"][0]
    assert robot["robot_id"] == "r1" and robot["max_linear_mps"] == 0.22
    assert robot["footprint_radius_m"] == 0.105 and robot["battery_capacity_wh"] == 19.98
    assert set(msg["charging_stations"][0]) == {
        "station_id",
        "x",
        "y",
        "radius_m",
        "charge_power_w",
    }


def reachable(world: World, start: tuple[float, float], half_width: float) -> np.ndarray:
    """Cells a disc of radius ``half_width`` can reach from ``start`` (4-connected)."""
    g = world.grid
    blocked = g.cells != FREE
    r = int(np.ceil(half_width / g.resolution))
    inflated = blocked.copy()
    h, w = blocked.shape
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            if dx * dx + dy * dy > r * r:
                continue
            shifted = np.zeros_like(blocked)
            ys, yd = slice(max(0, -dy), min(h, h - dy)), slice(max(0, dy), min(h, h + dy))
            xs, xd = slice(max(0, -dx), min(w, w - dx)), slice(max(0, dx), min(w, w + dx))
            shifted[yd, xd] = blocked[ys, xs]
            inflated |= shifted
    seen = np.zeros(blocked.shape, dtype=bool)
    col, row = (int(v) for v in g.world_to_cell(*start))
    queue = deque([(row, col)])
    seen[row, col] = True
    while queue:
        y, x = queue.popleft()
        for ny, nx in ((y + 1, x), (y - 1, x), (y, x + 1), (y, x - 1)):
            if 0 <= ny < h and 0 <= nx < w and not seen[ny, nx] and not inflated[ny, nx]:
                seen[ny, nx] = True
                queue.append((ny, nx))
    return seen


@pytest.mark.parametrize("name", ["open_room", "cluttered_room", "warehouse"])
def test_shipped_worlds_load(name: str) -> None:
    world = load_world(WORLDS / f"{name}.yaml")
    assert world.name == name and world.robots and world.stations


def test_warehouse_is_big_with_aisles_of_at_least_0_8_m() -> None:
    world = load_world(WORLDS / "warehouse.yaml")
    g = world.grid
    assert g.width * g.resolution >= 10.0 and g.height * g.resolution >= 8.0
    # a 0.8 m wide body (half-width 0.4 m, less a cell of rasterisation) can go everywhere
    # that matters: every robot, every charger, every aisle between the racks
    seen = reachable(world, (world.robots[0].x, world.robots[0].y), 0.4 - g.resolution)
    points = [(r.x, r.y) for r in world.robots] + [(s.x, s.y) for s in world.stations]
    points += [(3.6, 2.5), (5.8, 2.5), (3.6, 5.5), (5.8, 5.5), (5.0, 3.9), (8.5, 7.0)]
    for x, y in points:
        col, row = (int(v) for v in g.world_to_cell(x, y))
        assert seen[row, col], f"({x}, {y}) is not reachable through 0.8 m aisles"
