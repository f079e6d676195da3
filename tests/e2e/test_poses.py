"""The whole stack, end to end: a robot reaches a goal pose with its heading (through a route's
waypoint), under the shipped strategies. Launched as ``pnav up`` does, at an accelerated sim
rate, followed from the contract tables."""

from __future__ import annotations

import math

import pytest

from common.contract import people
from pnav.cli import stack_commands
from pnav.run.launcher import launched
from pnav.run.stack_options import StackOptions
from tests.e2e.test_missions import RATE, describe, reached, stack_monitor

pytestmark = pytest.mark.timeout(240)

# The robot stands when the planner calls the pose reached (below 0.05 rad/s): by the newest
# odometry at that sim time it has turned at most a little further.
SLACK_RAD = 0.02
SLACK_M = 0.05


def wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


@pytest.mark.parametrize(
    ("strategy", "route", "goal"),
    [
        # from (1, 1) facing +x: pass (3, 1), then to (3, 3), arriving northward, to face west
        ("GOTO_AVOID", [people.Pose(3.0, 1.0)], (3.0, 3.0, math.pi)),
        # dwa drives; the planner turns at the end: arriving north-east, to face south
        ("GOTO_FAST", [], (2.5, 2.5, -math.pi / 2)),
    ],
)
async def test_a_robot_reaches_a_goal_pose_facing_its_heading(
    strategy: str, route: list[people.Pose], goal: tuple[float, float, float]
) -> None:
    options = StackOptions(world="open_room", rate=RATE, robots=1, zenoh_port=None)
    async with launched(options) as stack:
        rt, monitor = await stack_monitor(stack)
        try:
            (robot,) = await stack_commands.pick_robots(rt, None, one=True)
            status, reason = await stack_commands.send_user_command(
                rt, robot, "SET_STRATEGY", strategy
            )
            assert status == "accepted", reason
            x, y, yaw = goal
            goal_id = await stack_commands.set_goal(rt, robot, x, y, yaw=yaw, waypoints=route)
            ok = await monitor.wait_for(reached(goal_id), limit_s=150)
            log = await monitor.poll()
            assert ok, f"pose not reached under {strategy}:\n{describe(log, stack)}"
            assert log.collisions == 0, describe(log, stack)
            pool = rt.database.pool
            row = await pool.fetchrow(
                "SELECT finished_stamp, yaw_tolerance_rad FROM goal WHERE id = $1", goal_id
            )
            odom = await pool.fetchrow(
                "SELECT x, y, yaw FROM odometry WHERE robot_id = $1 AND stamp <= $2 "
                "ORDER BY id DESC LIMIT 1",
                robot,
                row["finished_stamp"],
            )
            error = wrap(odom["yaw"] - yaw)
            assert abs(error) <= row["yaw_tolerance_rad"] + SLACK_RAD, dict(odom)
            assert math.hypot(odom["x"] - x, odom["y"] - y) <= 0.15 + SLACK_M, dict(odom)
            waypoints = await pool.fetch(
                "SELECT seq, status FROM goal_waypoint WHERE goal_id = $1 ORDER BY seq", goal_id
            )
            assert [(w["seq"], w["status"]) for w in waypoints] == [
                (i, "reached") for i in range(1, len(route) + 1)
            ]
        finally:
            await rt.close()
