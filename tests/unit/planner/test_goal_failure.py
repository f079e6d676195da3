"""Goals the map proves unreachable are marked failed, with a reason, at the first look;
goals the map allows (even behind something only the lidar sees) are followed as before.

Tick by tick on the in-memory contract, with the store and engine the service runs."""

from __future__ import annotations

import numpy as np
import pytest

from services.planner import reachability
from services.planner.world_model import MapData, inflation_m
from tests.unit.planner.harness import Planner

RES = 0.05
ORIGIN = (-1.0, -1.0)


def room() -> np.ndarray:
    """4 x 3 m from (-1, -1), walls all round; a rack (1.0-1.5, 0.5-1.0); a room closed on
    every side, x 2.0-3.0, y -1.0-0.0 (its walls at x = 2.0 and y = 0.0)."""
    occupied = np.zeros((60, 80), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    occupied[30:40, 40:50] = True  # the rack
    occupied[0:21, 60] = True  # the closed room's west wall
    occupied[20, 60:80] = True  # ...and its north wall
    return occupied


async def started(
    goal: tuple[float, float], *, pose: tuple[float, float] = (0.0, 0.0)
) -> tuple[Planner, int]:
    p = Planner()
    p.map(room(), RES, ORIGIN)
    p.pose = pose
    p.strategy("GOTO_AVOID")
    await p.tick()
    goal_id = p.goal(*goal)
    await p.tick()  # the first look at the goal
    return p, goal_id


@pytest.mark.parametrize(
    ("goal", "reason"),
    [
        (
            (10.0, 0.5),
            "goal (10.00, 0.50) is outside the map (the map spans x -1.00 to 3.00 m, "
            "y -1.00 to 2.00 m)",
        ),
        ((1.25, 0.75), "goal (1.25, 0.75) is inside an obstacle on the map"),
        ((2.5, -0.5), "no path on the map from (0.00, 0.00) to the goal"),
    ],
)
async def test_a_goal_the_map_rules_out_fails_at_the_first_look_and_the_robot_stops_once(
    goal: tuple[float, float], reason: str
) -> None:
    p, goal_id = await started(goal)
    row = p.goal_row(goal_id)
    assert row["status"] == "failed" and row["reason"] == reason
    assert row["finished_stamp"] == p.t
    stops = p.recommendations()
    assert len(stops) == 1  # nothing but the stop for it
    assert stops[0]["linear_mps"] == 0.0 and stops[0]["angular_rps"] == 0.0
    assert stops[0]["reason"] == f"goal {goal_id} failed: {reason}: stop"
    for _ in range(10):
        await p.tick(0.1)
    assert len(p.recommendations()) == 1  # said once


async def test_a_goal_too_close_to_a_rack_for_the_footprint_fails_but_one_in_reach_does_not() -> (
    None
):
    # 0.03 m off the rack's corner: the robot's centre keeps 0.155 m from the rack, so with
    # 0.15 m of tolerance the goal is within its reach, with 0.02 m it is not
    p, goal_id = await started((0.97, 0.47))
    row = p.goal_row(goal_id)
    assert row["status"] == "active"  # 0.15 m of tolerance reaches free space: kept
    occupied = room()
    data = MapData("test", "1", occupied, RES, (*ORIGIN, 0.0))
    why = reachability.spot_problem(data, inflation_m(0.105), 0.97, 0.47, 0.02)
    assert why == (
        "goal (0.97, 0.47) is too close to an obstacle on the map: the robot's centre "
        "cannot come within 0.02 m of it"
    )


async def test_a_goal_boxed_in_only_by_what_the_lidar_sees_stays_active() -> None:
    p, goal_id = await started((0.5, 0.0))
    assert p.goal_row(goal_id)["status"] == "active"
    # crates the map does not show all round the robot, 0.3 m away: no way out past them
    p.sense(0.05)
    p.scan(np.full(360, 0.3))
    for _ in range(12):
        await p.tick(0.1)
    robot = p.store.robot("r1")
    assert (
        robot is not None and robot.seen is not None and len(robot.seen.points) > 30
    )  # one per 5 cm cell of the ring
    assert p.goal_row(goal_id)["status"] == "active"
    moving = [r for r in p.recommendations() if r["linear_mps"] or r["angular_rps"]]
    assert moving and "failed" not in moving[-1]["reason"]


async def test_a_robot_standing_in_the_inflation_by_a_wall_still_reaches_its_goal() -> None:
    # 0.08 m from the west wall's face: inside the inflated zone, A* starts next to it
    p, goal_id = await started((0.5, 0.5), pose=(-0.87, 0.0))
    assert p.goal_row(goal_id)["status"] == "active"
    assert p.recommendations()[-1]["reason"].startswith(("turning toward", "driving to"))


async def test_a_reachable_goal_stays_active_until_reached_as_before() -> None:
    p, goal_id = await started((0.5, 1.5))
    for _ in range(5):
        await p.tick(0.1)
    assert p.goal_row(goal_id)["status"] == "active"
    assert all("failed" not in r["reason"] for r in p.recommendations())
    p.pose = (0.45, 1.45)
    await p.tick(0.1)
    row = p.goal_row(goal_id)
    assert row["status"] == "reached" and row.get("reason") is None
    assert "reached" in p.recommendations()[-1]["reason"]


def test_the_flood_starts_from_the_free_cell_nearest_a_robot_in_the_inflation() -> None:
    data = MapData("test", "1", room(), RES, (*ORIGIN, 0.0))
    grid = data.grid(0.105)
    by_the_wall = (-0.87, 0.0)  # 0.105 m from the west wall's cell centres: in the inflation
    assert not grid.free(grid.cell_of(*by_the_wall))
    assert not reachability.cut_off(grid, by_the_wall, (0.5, 0.5), 0.15)
    assert reachability.cut_off(grid, by_the_wall, (2.5, -0.5), 0.15)  # the closed room
    assert not reachability.cut_off(grid, (2.5, -0.6), (2.5, -0.5), 0.15)  # from inside it
    # nothing proved from where no free cell is within 0.6 m (here: off the map)
    assert not reachability.cut_off(grid, (10.0, 0.5), (2.5, -0.5), 0.15)
