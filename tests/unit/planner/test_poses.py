"""Goal poses and routes, tick by tick: the final turn in place to a heading (reached only
when position and heading hold and the robot stands), and a route's waypoints reached in
order, each on its row, with the expected state beside each step.

On the in-memory contract, with the store and engine the service runs (harness.py)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tests.unit.planner.harness import Planner

PI = math.pi


def last(p: Planner) -> tuple[float, float, str]:
    rec = p.recommendations()[-1]
    return rec["linear_mps"], rec["angular_rps"], rec["reason"]


async def planner(strategy: str = "GOTO_AVOID") -> Planner:
    p = Planner()
    p.strategy(strategy)
    await p.tick(0.1)
    return p


async def test_the_robot_turns_in_place_to_the_goal_heading_and_is_reached_only_standing() -> None:
    p = await planner()
    goal = p.goal(0.5, 0.0, yaw=PI / 2)  # tolerance: the default, 0.1 rad
    await p.tick(0.1)
    linear, angular, why = last(p)
    assert linear > 0 and "driving to" in why  # 0.5 m away: drive first
    assert p.goal_row(goal)["status"] == "active"

    p.pose = (0.4, 0.0)  # within 0.15 m: there; heading error pi/2 -> turn left
    await p.tick(0.1)
    linear, angular, why = last(p)
    assert (linear, angular) == (0.0, 2.0)  # 1.5 x 1.57, capped at 2.0 (error > 0.5 rad)
    assert why == f"at goal {goal}: turning to its heading, error 1.57 rad (tolerance 0.10)"

    p.yaw, p.rates = 1.0, (0.0, 0.6)  # error 0.57, anticipated 0.57 - 0.6 x 0.4 = 0.33
    await p.tick(0.1)
    linear, angular, _ = last(p)
    assert linear == 0.0 and math.isclose(angular, 1.5 * (PI / 2 - 1.0 - 0.24))

    p.yaw, p.rates = 1.52, (0.0, 0.3)  # within 0.1 rad, still turning: stop to stand
    await p.tick(0.1)
    linear, angular, why = last(p)
    assert (linear, angular) == (0.0, 0.0)
    assert why == f"at goal {goal}: stopping to stand, heading error 0.05 rad"
    assert p.goal_row(goal)["status"] == "active"  # not yet: it still turns

    p.yaw, p.rates = 1.70, (0.0, 0.0)  # swept past to -0.13: turn back, slowly
    await p.tick(0.1)
    # 1.5 x 0.13 = 0.19, below the floor 2 x 0.1 = 0.2 rad/s
    assert last(p)[:2] == (0.0, -0.2)

    p.yaw, p.rates = 1.60, (0.0, 0.01)  # within tolerance, standing: reached
    await p.tick(0.1)
    linear, angular, why = last(p)
    assert (linear, angular) == (0.0, 0.0)
    assert why == f"goal {goal} reached (0.10 m away, heading error -0.03 rad): stop"
    row = p.goal_row(goal)
    assert row["status"] == "reached" and row["finished_stamp"] == p.t


async def test_a_small_heading_error_turns_at_the_floor_the_tolerance_allows() -> None:
    p = await planner()
    goal = p.goal(0.0, 0.0, yaw=0.3, yaw_tolerance_rad=0.05)
    await p.tick(0.1)
    # error 0.3: 1.5 x 0.3 = 0.45 rad/s (below FINE_TURN_RPS 0.6)
    assert last(p)[0] == 0.0 and math.isclose(last(p)[1], 0.45)
    p.yaw = 0.27  # error 0.03 < 0.05 and standing: reached
    await p.tick(0.1)
    assert p.goal_row(goal)["status"] == "reached"
    p2 = await planner()
    p2.goal(0.0, 0.0, yaw=0.08, yaw_tolerance_rad=0.05)
    await p2.tick(0.1)
    # error 0.08: 1.5 x 0.08 = 0.12, floored at 2 x 0.05 = 0.1 -> 0.12
    assert math.isclose(last(p2)[1], 0.12)
    p2.yaw = 0.02  # error 0.06, measured rate 0.12: anticipated 0.012 -> the 0.1 floor
    p2.rates = (0.0, 0.12)
    await p2.tick(0.1)
    assert math.isclose(last(p2)[1], 0.1)


async def test_the_position_holds_while_turning_within_a_slack_then_the_robot_drives_back() -> None:
    p = await planner()
    goal = p.goal(0.0, 0.0, yaw=-PI / 2)
    await p.tick(0.1)
    assert last(p)[1] < 0  # turning right, in place
    p.pose, p.yaw = (0.18, 0.0), -0.5  # drifted past 0.15 m, within 0.15 + 0.05: still turning
    await p.tick(0.1)
    linear, angular, why = last(p)
    assert linear == 0.0 and angular < 0 and "turning to its heading" in why
    p.pose = (0.25, 0.0)  # beyond the slack: drive back first
    await p.tick(0.1)
    assert "turning to its heading" not in last(p)[2]
    assert p.goal_row(goal)["status"] == "active"


async def test_a_goal_without_a_heading_is_reached_at_once_as_before() -> None:
    p = await planner()
    p.yaw, p.rates = 2.0, (0.1, 0.5)  # whatever the heading and rates
    goal = p.goal(0.1, 0.0)
    await p.tick(0.1)
    assert p.goal_row(goal)["status"] == "reached"


async def test_with_a_local_controller_driving_the_planner_still_turns_to_the_heading() -> None:
    p = await planner("GOTO_FAST")  # "planner_drives": false: dwa drives on the way
    goal = p.goal(1.0, 0.0, yaw=PI)
    await p.tick(0.1)
    assert p.recommendations() == []  # on the way: the planner says nothing
    p.pose = (0.9, 0.0)
    await p.tick(0.1)
    linear, angular, why = last(p)
    assert (linear, angular) == (0.0, 2.0) and "turning to its heading" in why
    p.yaw = PI - 0.05
    await p.tick(0.1)
    assert p.goal_row(goal)["status"] == "reached"


async def test_a_route_is_driven_through_in_order_with_progress_on_each_row() -> None:
    p = await planner()
    route: tuple[dict[str, Any], ...] = (
        {"x": 1.0, "y": 0.0},  # passed through
        {"x": 1.0, "y": 1.0, "stop": True},  # halted at
        {"x": 0.5, "y": 1.0, "yaw": PI},  # halted at, facing -x
    )
    goal = p.goal(0.0, 1.0, waypoints=route)
    await p.tick(0.1)
    linear, _, why = last(p)
    # waypoint 1, 1 m ahead, and 1 m more to waypoint 2 where it halts: full speed
    assert linear == 0.22 and why.endswith(f"1.00 m to waypoint 1 of goal {goal}")
    assert p.waypoint_rows(goal) == [
        (1, "pending", None),
        (2, "pending", None),
        (3, "pending", None),
    ]

    p.pose, p.rates = (0.8, 0.0), (0.22, 0.0)  # within 0.3 m of waypoint 1: passed
    await p.tick(0.1)
    assert p.waypoint_rows(goal) == [
        (1, "reached", p.t),
        (2, "pending", None),
        (3, "pending", None),
    ]
    linear, angular, why = last(p)
    assert why.startswith("turning toward") and f"waypoint 2 of goal {goal}" in why  # at once
    reached_1 = p.t

    p.pose, p.yaw, p.rates = (1.0, 0.8), PI / 2, (0.1, 0.0)  # at waypoint 2, still moving
    await p.tick(0.1)
    assert last(p)[:2] == (0.0, 0.0)  # stop to stand there
    assert p.waypoint_rows(goal)[1] == (2, "pending", None)

    p.rates = (0.0, 0.0)  # standing: waypoint 2 reached; on to waypoint 3, 0.5 m to the -x
    await p.tick(0.1)
    assert p.waypoint_rows(goal) == [
        (1, "reached", reached_1),
        (2, "reached", p.t),
        (3, "pending", None),
    ]
    assert f"waypoint 3 of goal {goal}" in last(p)[2]

    p.pose, p.yaw = (0.6, 1.0), PI / 2  # at waypoint 3: turn to face -x (error +pi/2)
    await p.tick(0.1)
    linear, angular, why = last(p)
    assert (linear, angular) == (0.0, 2.0)
    assert why.startswith(f"at waypoint 3 of goal {goal}: turning to its heading")
    p.yaw = PI - 0.02  # facing -x, standing: waypoint 3 reached; on to the goal (0, 1)
    await p.tick(0.1)
    assert p.waypoint_rows(goal)[2] == (3, "reached", p.t)
    assert p.goal_row(goal)["status"] == "active"
    assert "goal " + str(goal) in last(p)[2] and last(p)[0] > 0  # straight on, facing it

    p.pose = (0.1, 1.0)  # the goal's own pose: reached, the route done
    await p.tick(0.1)
    assert p.goal_row(goal)["status"] == "reached"


async def test_several_waypoints_within_reach_at_once_are_all_passed_in_one_look() -> None:
    p = await planner()
    route = ({"x": 0.1, "y": 0.0}, {"x": 0.2, "y": 0.0}, {"x": 2.0, "y": 0.0})
    goal = p.goal(3.0, 0.0, waypoints=route)
    await p.tick(0.1)
    assert [r[1] for r in p.waypoint_rows(goal)] == ["reached", "reached", "pending"]
    assert f"waypoint 3 of goal {goal}" in last(p)[2]


async def room() -> Planner:
    p = Planner()
    occupied = np.zeros((60, 80), dtype=bool)  # 4 x 3 m from (-1, -1), walls all round
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    occupied[30:40, 40:50] = True  # a rack, x 1.0-1.5, y 0.5-1.0
    p.map(occupied, 0.05, (-1.0, -1.0))
    p.strategy("GOTO_AVOID")
    await p.tick(0.1)
    return p


async def test_a_waypoint_the_map_rules_out_fails_the_route_at_the_first_look_naming_it() -> None:
    p = await room()
    goal = p.goal(2.0, 0.0, waypoints=({"x": 0.5, "y": 0.0}, {"x": 1.25, "y": 0.75}))
    await p.tick(0.1)  # waypoint 2 is inside the rack: judged ahead, before the robot is there
    why = "waypoint 2 (1.25, 0.75): goal (1.25, 0.75) is inside an obstacle on the map"
    row = p.goal_row(goal)
    assert row["status"] == "failed" and row["reason"] == why
    assert p.waypoint_rows(goal) == [(1, "pending", None), (2, "failed", p.t)]
    assert last(p)[:2] == (0.0, 0.0)
    assert last(p)[2] == f"waypoint 2 of goal {goal} failed: {why}: stop"
    await p.tick(0.1)
    assert len(p.recommendations()) == 1  # the stop, said once


async def test_a_long_route_is_judged_a_few_waypoints_per_look_while_the_robot_drives() -> None:
    p = await room()
    route = (*({"x": 0.1 * i, "y": -0.5} for i in range(1, 13)), {"x": 1.25, "y": 0.75})
    goal = p.goal(2.0, 0.0, waypoints=route)
    for look in (1, 2):  # 5 waypoints judged per look: waypoint 13 not yet
        await p.tick(0.1)
        assert p.goal_row(goal)["status"] == "active", look
    await p.tick(0.1)  # the third look judges 11 to 13
    assert p.goal_row(goal)["reason"].startswith("waypoint 13 (1.25, 0.75): ")
