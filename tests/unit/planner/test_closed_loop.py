"""Both planner scenarios, closed around an ideal unicycle on a walled map with a gap: the
robot gets to the goal and keeps its footprint clear of the walls (no database, no engine).
And with a crate the map does not show, seen only by a simulated lidar: the route goes round
it."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from common.contract.records import LaserScan, Odometry
from common.planner_core.scenario import Movement, RobotInfo
from services.planner import move_while_turning, turn_then_move
from services.planner.routes import Router, Target
from services.planner.tracking import heading_error
from services.planner.world_model import MapData, RobotState, World, see

RES = 0.05
FOOTPRINT = 0.105


def walled_map() -> np.ndarray:
    """4 x 3 m, walls all round, a wall across x = 2 m with a 0.6 m gap at y 2.0-2.6."""
    occupied = np.zeros((60, 80), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    occupied[:, 40] = True
    occupied[40:52, 40] = False
    return occupied


def drive(
    scenario: str, start: tuple[float, float, float], goal: tuple[float, float]
) -> tuple[bool, float]:
    occupied = walled_map()
    world = World()
    world.maps["walled"] = MapData("walled", "1", occupied, RES, (0.0, 0.0, 0.0))
    router = Router(world, time.monotonic)
    info = RobotInfo("r1", "walled", 0.22, 2.84, FOOTPRINT)
    robot = RobotState(info)
    target = Target("goal", "1", goal[0], goal[1], 0.15, 0.0, 1)
    rows, cols = np.nonzero(occupied)
    wall_x, wall_y = (cols + 0.5) * RES, (rows + 0.5) * RES
    x, y, yaw = start
    rate = 0.0
    turning = False
    dt = 1 / 30
    pending: list[Movement] = []  # commands reach the wheels 0.1 s late, as through the stack
    closest = math.inf
    for step in range(int(90 / dt)):
        if math.hypot(goal[0] - x, goal[1] - y) <= target.reach_m:
            return True, closest
        progress = router.route_for(robot, x, y, target, step * dt)
        error = heading_error(x, y, yaw, progress.lookahead)
        if scenario == "turn_then_move":
            move = turn_then_move.select_movement(
                error, progress.remaining_m, 0.22, 2.84, turning, turn_rate=rate
            )
        else:
            move = move_while_turning.select_movement(error, progress.remaining_m, 0.22, 2.84)
        turning = move.turning
        pending.append(move)
        applied = pending.pop(0) if len(pending) > 3 else Movement(0.0, 0.0, False)
        rate = applied.angular
        yaw += applied.angular * dt
        x += applied.linear * math.cos(yaw) * dt
        y += applied.linear * math.sin(yaw) * dt
        if step % 5 == 0:
            closest = min(closest, float(np.min(np.hypot(wall_x - x, wall_y - y))) - RES / 2)
    return False, closest


@pytest.mark.parametrize("scenario", ["turn_then_move", "move_while_turning"])
def test_the_robot_goes_through_the_gap_to_the_goal_without_touching_a_wall(scenario: str) -> None:
    reached, closest = drive(scenario, (0.5, 0.5, 0.0), (3.5, 0.5))
    assert reached
    assert closest > FOOTPRINT  # centre-to-wall distance never below the footprint radius


def lidar(truth: np.ndarray, x: float, y: float, yaw: float, stamp: float) -> LaserScan:
    """A 360-beam sweep of ``truth`` (cells at RES, origin 0) from (x, y, yaw), range 3.5 m."""
    angles = np.arange(360) * (2 * math.pi / 360)
    steps = np.arange(0.12, 3.5, 0.01)
    px = x + np.outer(np.cos(angles + yaw), steps)
    py = y + np.outer(np.sin(angles + yaw), steps)
    cols = np.clip((px / RES).astype(int), 0, truth.shape[1] - 1)
    rows = np.clip((py / RES).astype(int), 0, truth.shape[0] - 1)
    hit = truth[rows, cols]
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
    ranges = np.where(first >= 0, steps[np.maximum(first, 0)], np.inf).astype(np.float32)
    return LaserScan(int(stamp * 10), "r1", stamp, 0.0, 2 * math.pi / 360, 0.12, 3.5, ranges)


def test_a_crate_the_map_does_not_show_is_planned_around_once_the_lidar_sees_it() -> None:
    occupied = np.zeros((60, 140), dtype=bool)  # 7 x 3 m, walls all round
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    truth = occupied.copy()
    truth[26:34, 96:104] = True  # a 0.4 m crate at (5.0, 1.5), on the straight line, out of sight
    crate_x, crate_y = (
        np.nonzero(truth & ~occupied)[1] * RES,
        np.nonzero(truth & ~occupied)[0] * RES,
    )
    world = World()
    world.maps["room"] = MapData("room", "1", occupied, RES, (0.0, 0.0, 0.0))
    router = Router(world, time.monotonic)
    robot = RobotState(RobotInfo("r1", "room", 0.22, 2.84, FOOTPRINT))
    target = Target("goal", "1", 6.5, 1.5, 0.15, 0.0, 1)
    x, y, yaw, rate, turning = 0.5, 1.5, 0.0, 0.0, False
    dt = 1 / 30
    closest = math.inf
    replans = 0
    for step in range(int(80 / dt)):
        now = step * dt
        if math.hypot(target.x - x, target.y - y) <= target.reach_m:
            break
        robot.note_pose(Odometry(step, "r1", now, x, y, yaw, 0.0, rate))
        if step % 6 == 0:  # 5 Hz
            see(world, robot, lidar(truth, x, y, yaw, now))
        before = robot.route
        progress = router.route_for(robot, x, y, target, now)
        replans += robot.route is not before
        error = heading_error(x, y, yaw, progress.lookahead)
        move = turn_then_move.select_movement(
            error, progress.remaining_m, 0.22, 2.84, turning, turn_rate=rate
        )
        turning, rate = move.turning, move.angular
        yaw += move.angular * dt
        x += move.linear * math.cos(yaw) * dt
        y += move.linear * math.sin(yaw) * dt
        closest = min(
            closest, float(np.min(np.hypot(crate_x + RES / 2 - x, crate_y + RES / 2 - y)))
        )
    else:
        raise AssertionError("the goal was not reached")
    assert 2 <= replans <= 6  # the first plan, then one or a few as the crate comes into view
    assert closest > FOOTPRINT + 0.2  # round the crate with room to spare
