"""Both planner scenarios, closed around an ideal unicycle on a walled map with a gap: the
robot gets to the goal and keeps its footprint clear of the walls (no database, no engine)."""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np
import pytest

from services.planner import move_while_turning, turn_then_move
from services.planner.scenario import Movement
from services.planner.state import MapData, PlannerState, RobotInfo, RobotState, Target
from services.planner.tracking import heading_error

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
    state = PlannerState(cast(Any, None), lambda: 0.0, lambda: True)
    state.maps["walled"] = MapData("walled", "1", occupied, RES, (0.0, 0.0, 0.0))
    info = RobotInfo("r1", "walled", 0.22, 2.84, FOOTPRINT)
    robot = RobotState(info)
    target = Target("goal", "1", goal[0], goal[1], 0.15, 0.0, 1)
    rows, cols = np.nonzero(occupied)
    wall_x, wall_y = (cols + 0.5) * RES, (rows + 0.5) * RES
    x, y, yaw = start
    turning = False
    dt = 1 / 30
    pending: list[Movement] = []  # commands reach the wheels 0.1 s late, as through the stack
    closest = math.inf
    for step in range(int(90 / dt)):
        if math.hypot(goal[0] - x, goal[1] - y) <= target.reach_m:
            return True, closest
        progress = state.route_for(robot, x, y, target)
        error = heading_error(x, y, yaw, progress.lookahead)
        if scenario == "turn_then_move":
            move = turn_then_move.select_movement(error, progress.remaining_m, 0.22, 2.84, turning)
        else:
            move = move_while_turning.select_movement(error, progress.remaining_m, 0.22, 2.84)
        turning = move.turning
        pending.append(move)
        applied = pending.pop(0) if len(pending) > 3 else Movement(0.0, 0.0, False)
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
