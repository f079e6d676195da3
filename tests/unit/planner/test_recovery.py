"""Recovery, tick by tick: the machine's states (watch -> back up -> rotate -> re-plan, then
failed with a reason), then the rule in the planner as the service seeds it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.contract import keys
from common.contract.records import LaserScan
from common.footprint import Footprint
from services.planner.recovery import (
    BACK_UP,
    FAILED,
    ROTATE,
    WATCH,
    Machine,
    Observation,
    RecoveryParams,
)
from tests.unit.planner.harness import ROBOT, Planner

P = RecoveryParams(stuck_s=2.0, no_progress_s=10.0, attempts=2, back_up_m=0.3, maneuver_s=3.0)
GOAL = ("goal", 1)


def seen(t: float, x: float = 0.0, y: float = 0.0, yaw: float = 0.0, **kw: bool) -> Observation:
    return Observation(t, x, y, yaw, GOAL, 5.0, 0.0, 0.2, **kw)


def test_the_machine_backs_up_rotates_replans_then_fails_with_a_reason() -> None:
    m = Machine()
    assert m.step(seen(0.0), P).kind == "none" and m.state == WATCH  # anchored at (0, 0)
    assert m.step(seen(1.9, 0.1), P).kind == "none"  # 0.1 m away (< 0.2 m footprint): 1.9 s
    assert m.wants_scan(seen(2.0, 0.1), P)  # stuck at the next step: it wants the lidar
    a = m.step(seen(2.0, 0.1), P)  # 2 s within 0.2 m: stuck, first recovery
    assert (m.state, a.kind, a.linear, a.angular) == (BACK_UP, "drive", -0.15, 0.0)
    assert a.reason.startswith("recovery 1/2 (stayed within 0.20 m of (0.00, 0.00) for 2.0 s)")
    a = m.step(seen(2.5, 0.0), P)  # backed 0.1 of 0.3 m
    assert (m.state, a.linear) == (BACK_UP, -0.15) and "0.10 of 0.30 m" in a.reason
    a = m.step(seen(3.0, -0.2, left_freer=False), P)  # 0.3 m back: rotate, right is freer
    assert (m.state, a.linear, a.angular) == (ROTATE, 0.0, -1.0)
    a = m.step(seen(4.0, -0.2, yaw=-1.0), P)  # 1.0 of 1.57 rad
    assert (m.state, a.angular) == (ROTATE, -1.0) and "turning right" in a.reason
    a = m.step(seen(4.6, -0.2, yaw=-1.6), P)  # turned: re-plan, watch afresh from here
    assert (m.state, a.kind) == (WATCH, "replan") and "re-planning" in a.reason
    assert m.step(seen(6.5, -0.2, yaw=-1.6), P).kind == "none"  # 1.9 s since the re-plan
    a = m.step(seen(6.6, -0.2, yaw=-1.6, rear_clear=False), P)  # stuck again, wall behind
    assert (m.state, a.kind, a.angular) == (ROTATE, "drive", 1.0)  # no back-up: rotate
    assert a.reason.startswith("recovery 2/2")
    a = m.step(seen(9.6, -0.2, yaw=-1.0), P)  # 3 s of rotation: the manoeuvre's limit
    assert (m.state, a.kind) == (WATCH, "replan")
    a = m.step(seen(11.6, -0.2, yaw=-1.0), P)  # stuck a third time: 2 recoveries were all
    assert (m.state, a.kind) == (FAILED, "fail")
    assert a.reason == (
        "no progress: stayed within 0.20 m of (-0.20, 0.00) for 2.0 s, after 2 recoveries "
        "(back up, rotate, re-plan)"
    )
    assert m.step(seen(20.0, -0.2), P).kind == "none"  # given up: nothing more


def test_moving_without_coming_nearer_is_no_progress() -> None:
    m = Machine()
    m.step(seen(0.0), P)
    # circling 0.5 m round the start, never nearer the goal at (5, 0) by 0.3 m
    for k in range(1, 150):
        t = k * 0.1
        a = m.step(seen(t, 0.5 * math.cos(t) - 0.5, 0.5 * math.sin(t)), P)
        if a.kind != "none":
            break
    assert t == pytest.approx(10.0) and m.state == BACK_UP
    assert "came no 0.30 m nearer the goal in 10.0 s" in a.reason


def test_progress_and_a_new_goal_start_the_watch_afresh() -> None:
    m = Machine()
    m.step(seen(0.0), P)
    for k in range(1, 40):  # 0.2 m/s toward the goal for 3.9 s: never stuck
        assert m.step(seen(k * 0.1, k * 0.02), P).kind == "none"
    m.step(seen(4.0, 0.8), P)
    m.attempts = 2  # as if two recoveries were spent on this goal
    other = Observation(4.1, 0.8, 0.0, 0.0, ("goal", 2), 0.0, 5.0, 0.2)
    assert m.step(other, P).kind == "none" and m.attempts == 0 and m.state == WATCH


def test_params_come_from_the_strategy_with_defaults() -> None:
    p = RecoveryParams.read({"recovery_stuck_s": 3, "recovery_attempts": 1.0, "recovery_x": 1})
    assert (p.stuck_s, p.attempts, p.back_up_m) == (3.0, 1, RecoveryParams().back_up_m)
    assert RecoveryParams.read({"recovery_stuck_s": -1, "recovery_attempts": "2"}) == (
        RecoveryParams()
    )


FAST = {
    "code": "FAST_TEST",
    "planner_scenario": "turn_then_move",
    "params": {
        "target": "goal",
        "planner_drives": False,
        "recovery": True,
        "recovery_stuck_s": 1.0,
        "recovery_attempts": 1,
        "recovery_maneuver_s": 0.5,
    },
}


async def test_the_rule_recommends_the_manoeuvres_then_fails_the_goal() -> None:
    p = Planner(extra_strategies=(FAST,))
    p.strategy("FAST_TEST")
    goal = p.goal(3.0, 0.0)
    await p.tick()
    assert p.running()["recovery"] == ("Recovery", "FAST_TEST")  # asked for by the params
    p.scan(np.full(360, np.inf))  # nothing around
    # the robot never moves: after 1 s it is stuck; backing up (priority 70, valid 0.25 s)
    for _ in range(30):
        await p.tick()
    recs = p.recommendations("recovery")
    assert recs and recs[0]["priority"] == 70 and recs[0]["linear_mps"] == -0.15
    assert recs[0]["expires_stamp"] - recs[0]["stamp"] == pytest.approx(0.25)
    # it never gets anywhere: 0.5 s of backing up, 0.5 s of turning, a re-plan, then 1 s
    # stuck again with its one recovery spent: the goal fails with the reason
    for _ in range(60):
        await p.tick()
    row = p.goal_row(goal)
    assert row["status"] == "failed"
    assert row["reason"].startswith("no progress: stayed within 0.10 m of (0.00, 0.00)")
    assert row["reason"].endswith("after 1 recovery (back up, rotate, re-plan)")
    stop = p.recommendations("recovery")[-1]
    assert (stop["linear_mps"], stop["angular_rps"]) == (0.0, 0.0)
    assert stop["reason"].startswith(f"goal {goal} failed: no progress")
    turns = [r for r in p.recommendations("recovery") if r["angular_rps"] != 0.0]
    assert turns and all(r["linear_mps"] == 0.0 for r in turns)
    # the planner's path: one plan, a re-plan after the manoeuvres, then empty (no target)
    paths = list(p.contract[keys.PLANNED_PATH].rows(ROBOT))
    assert [bool(r["xs"]) for r in paths] == [True, True, False]
    # the move scenario never drove ("planner_drives": false)
    assert p.recommendations("turn_then_move") == []


async def test_strategies_without_the_param_get_no_recovery_rule() -> None:
    p = Planner()
    p.strategy("GOTO_AVOID")
    p.goal(3.0, 0.0)
    await p.tick()
    assert set(p.running()) == {"move", "battery"}


def test_a_lidar_with_no_beams_behind_never_calls_the_rear_clear() -> None:
    from services.planner.recovery_rule import surroundings

    def sweep(first_deg: float, beams: int) -> LaserScan:
        ranges = np.full(beams, np.inf, dtype=np.float32)
        return LaserScan(1, "r1", 1.0, math.radians(first_deg), math.radians(1), 0.1, 30.0, ranges)

    disc = Footprint.of(0.22)
    assert surroundings(sweep(0.0, 360), disc, 0.3)[0]  # all round and nothing near: clear
    assert not surroundings(sweep(-135.0, 270), disc, 0.3)[0]  # the Jackal's: blind behind


def test_backing_and_turning_room_are_measured_from_a_polygon() -> None:
    from services.planner.recovery_rule import surroundings

    box = Footprint.of(0.22, ((0.254, -0.215), (0.254, 0.215), (-0.254, 0.215), (-0.254, -0.215)))

    def scan_with(points: list[tuple[float, float]]) -> LaserScan:
        # a full-turn 1-degree lidar seeing only ``points`` (robot frame)
        ranges = np.full(360, np.inf, dtype=np.float32)
        for x, y in points:
            beam = round(math.degrees(math.atan2(y, x))) % 360
            ranges[beam] = math.hypot(x, y)
        return LaserScan(1, "r1", 1.0, 0.0, math.radians(1), 0.1, 30.0, ranges)

    # backing 0.3 m needs 0.4 m behind the back edge (x = -0.254)
    assert not surroundings(scan_with([(-0.6, 0.0)]), box, 0.3)[0]  # 0.346 m
    assert surroundings(scan_with([(-0.7, 0.0)]), box, 0.3)[0]  # 0.446 m
    # a post 0.34 m out at 45 degrees left: turning left swings the front right corner
    # (0.333 m out) by it within 1 cm, turning right nothing within 2 cm; a wall
    # 0.9 m away on the right makes the left look the more open side
    wall = [(0.9 * math.cos(a), 0.9 * math.sin(a)) for a in np.radians(np.arange(-120, -59))]
    post = (0.34 * math.cos(math.pi / 4), 0.34 * math.sin(math.pi / 4))
    assert not surroundings(scan_with([post, *wall]), box, 0.3, 1.57)[1]  # turn right
    # without the turn's check (a disc), the more open side wins: left
    assert surroundings(scan_with([post, *wall]), Footprint.of(0.22), 0.3, 1.57)[1]
    # mirrored: left
    mirrored = [(x, -y) for x, y in (post, *wall)]
    assert surroundings(scan_with(mirrored), box, 0.3, 1.57)[1]
    # barn_hard_002: a post 0.30 m out at 117 degrees left, 5 cm off the left side. Turning
    # right swings the rear left corner into it at once; turning left is free for about
    # 70 degrees, short of the 90 asked. Neither turn is free all the way, so the side
    # that turns farther is the one, though the right looks the more open side
    post = (0.30 * math.cos(math.radians(117)), 0.30 * math.sin(math.radians(117)))
    wall = [(0.5 * math.cos(a), 0.5 * math.sin(a)) for a in np.radians(np.arange(30, 80))]
    assert surroundings(scan_with([post, *wall]), box, 0.3, 1.57)[1]  # turn left


def test_a_robot_turning_at_its_pose_is_never_stuck_and_a_new_leg_is_watched_afresh() -> None:
    m = Machine()

    def at(t: float, x: float, leg: int | None, gx: float = 5.0) -> Observation:
        # the route's next pose at (gx, 0), reached within 0.2 m
        return Observation(t, x, 0.0, 0.0, GOAL, gx, 0.0, 0.2, leg=leg, there_m=0.2)

    assert m.step(at(0.0, 4.9, None), P).kind == "none"  # at the goal's position, turning
    assert m.step(at(5.0, 4.9, None), P).kind == "none"  # 5 s there (stuck_s 2): not stuck
    assert m.state == WATCH and m.attempts == 0
    # a route: waypoint 1 at (1, 0); 9 s of progress toward it, the best 0.1 m away
    m = Machine()
    assert m.step(at(0.0, 0.0, 1, gx=1.0), P).kind == "none"
    assert m.step(at(1.5, 0.5, 1, gx=1.0), P).kind == "none"
    assert m.step(at(3.0, 0.9, 1, gx=1.0), P).kind == "none"  # within 0.2 m: there
    # on to waypoint 2 at (-4, 0), 4.9 m away: progress now counts toward it, from here
    assert m.step(at(3.5, 0.9, 2, gx=-4.0), P).kind == "none"
    assert m.best == (4.9, 3.5)  # not waypoint 1's 0.1 m, which would never be beaten
    assert m.step(at(5.0, 0.9, 2, gx=-4.0), P).kind == "none"
    assert m.step(at(5.5, 0.4, 2, gx=-4.0), P).kind == "none"  # moving: anchored again
    assert m.state == WATCH and m.attempts == 0
    a = m.step(at(7.6, 0.4, 2, gx=-4.0), P)  # 2.1 s within 0.2 m of (0.4, 0), not there: stuck
    assert (m.state, a.kind) == (BACK_UP, "drive")
