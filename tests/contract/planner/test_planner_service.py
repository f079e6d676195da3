"""The planner alone against Postgres and Zenoh: what it recommends, and what it writes."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import math

import numpy as np

from common.config import EngineSettings, LeaseSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from pnav._testing import eventually, running_service
from services.planner.service import PlannerService
from tests.contract.conftest import split_between
from tests.contract.planner.conftest import ROBOT, World


def live_window(rec: object) -> float:
    return float(rec["expires_stamp"]) - float(rec["stamp"])  # type: ignore[index]


async def test_turns_toward_a_goal_on_the_left_then_follows_a_new_goal_ahead(
    world: World, planner: PlannerService
) -> None:
    await world.strategy("GOTO_AVOID")
    left = await world.goal(0.0, 2.0)
    rec = await world.next_recommendation(lambda r: r["inputs"].get("goal") == left)
    assert rec["source"] == "turn_then_move" and rec["priority"] == 10
    assert rec["linear_mps"] == 0.0 and rec["angular_rps"] > 0  # turn left, in place
    assert math.isclose(live_window(rec), 0.5)
    odom = await world.db.pool.fetchrow(
        "SELECT stamp FROM odometry WHERE id = $1", rec["inputs"]["odometry"]
    )
    assert odom is not None and rec["stamp"] == odom["stamp"]
    assert "turning toward waypoint 1/1" in rec["reason"] and "heading error" in rec["reason"]

    # A new goal while the robot moves: the recommendations follow it at once.
    ahead = await world.goal(2.0, 0.0)
    rec = await world.next_recommendation(lambda r: r["inputs"].get("goal") == ahead)
    assert rec["linear_mps"] > 0.1 and abs(rec["angular_rps"]) < 0.1
    assert rec["reason"].startswith("driving to waypoint")
    superseded = await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", left)
    assert superseded == "superseded"  # the planner left the foreign client's update alone


async def test_a_strategy_switch_changes_the_scenario_with_no_restart(
    world: World, planner: PlannerService
) -> None:
    await world.db.pool.execute(
        "INSERT INTO strategy (code, planner_scenario, params) VALUES "
        "('GOTO_SMOOTH', 'move_while_turning', '{\"target\": \"goal\"}')"
    )
    await world.strategy("GOTO_AVOID")
    await world.goal(1.0, 1.0)  # 45 degrees to the left
    first = await world.next_recommendation(lambda r: True)
    assert first["source"] == "turn_then_move" and first["linear_mps"] == 0.0

    await world.strategy("GOTO_SMOOTH")
    switched = await world.next_recommendation(
        lambda r: r["source"] == "move_while_turning", after=first["id"]
    )
    assert switched["linear_mps"] > 0 and switched["angular_rps"] > 0  # drives while turning
    await asyncio.sleep(0.5)
    later = await world.recommendations(after=switched["id"])
    assert later and {r["source"] for r in later} == {"move_while_turning"}  # exactly one scenario


async def test_reaching_the_goal_marks_it_reached_and_stops_once(
    world: World, planner: PlannerService
) -> None:
    world.pose = (1.0, 0.0, 0.0)
    await world.strategy("GOTO_AVOID")
    goal_id = await world.goal(1.5, 0.0, tolerance=0.15)
    await world.next_recommendation(lambda r: r["linear_mps"] > 0, what="driving to the goal")

    world.pose = (1.45, 0.02, 0.0)  # inside the tolerance
    row = await eventually(
        lambda: world.db.pool.fetchrow(
            "SELECT status, finished_stamp FROM goal WHERE id = $1 AND status <> 'active'",
            goal_id,
        ),
        what="the goal marked reached",
    )
    assert row["status"] == "reached" and row["finished_stamp"] > 100.0
    stop = await world.next_recommendation(lambda r: "reached" in r["reason"])
    assert stop["linear_mps"] == 0.0 and stop["angular_rps"] == 0.0 and stop["priority"] == 10
    await asyncio.sleep(0.6)
    assert await world.recommendations(after=stop["id"]) == []  # no goal, nothing to say


async def test_the_path_goes_around_a_wall_on_the_map(
    world: World, planner: PlannerService
) -> None:
    # 3 x 2 m at 5 cm, walls all round, and a wall across x = 1.5 with a gap at y 1.3-1.8
    grid = np.zeros((40, 60), dtype=np.uint8)
    grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = 100
    grid[:, 30] = 100
    grid[26:36, 30] = 0
    async with world.db.transaction() as tx:
        await tx.conn.execute(
            "INSERT INTO map (map_id, resolution_m, origin_x, origin_y, width, height, grid) "
            "VALUES ('walled', 0.05, 0, 0, 60, 40, $1)",
            grid.tobytes(),
        )
        await tx.conn.execute("UPDATE robot SET world = 'walled' WHERE robot_id = $1", ROBOT)
        tx.changed(keys.MAP, None)
        tx.changed(keys.ROBOT, ROBOT)
    world.pose = (0.5, 0.5, 0.0)
    await world.strategy("GOTO_AVOID")
    goal_id = await world.goal(2.5, 0.5)
    rec = await world.next_recommendation(lambda r: r["inputs"].get("goal") == goal_id)
    # Straight ahead is the wall: the path bends up to the gap first, so the robot turns left.
    assert rec["angular_rps"] > 0 and rec["linear_mps"] == 0.0
    assert "waypoint 1/" in rec["reason"] and "waypoint 1/1" not in rec["reason"]
    remaining = float(rec["reason"].split(" m to goal")[0].rsplit(" ", 1)[1])
    assert remaining > 2.5  # longer than the 2 m straight line


async def test_battery_too_low_for_the_path_recommends_battsave_once_while_live(
    world: World, planner: PlannerService
) -> None:
    await world.strategy("GOTO_AVOID")
    await world.goal(10.0, 0.0)  # 10 m x 0.006 Wh/m + 0.05 reserve = 0.11 Wh needed
    await world.battery(0.5)
    await world.next_recommendation(lambda r: True, what="the planner driving")
    assert await world.recommendations(kind="system") == []  # 0.5 Wh is plenty

    await world.battery(0.08)
    rec = await world.next_recommendation(lambda r: True, kind="system", what="CMD_BATTSAVE")
    assert rec["system_command"] == "CMD_BATTSAVE" and rec["source"] == "battery_check"
    assert rec["priority"] == 60 and math.isclose(live_window(rec), 2.0)
    assert "battery" in rec["inputs"] and "goal" in rec["inputs"]
    await world.battery(0.07)
    await asyncio.sleep(0.5)  # well within its 2 s validity: no second one
    assert len(await world.recommendations(kind="system")) == 1


async def test_charge_drives_to_the_nearest_station_then_resumes_once(
    world: World, planner: PlannerService
) -> None:
    await world.execute(
        keys.CHARGING_STATION,
        None,
        "INSERT INTO charging_station (station_id, x, y, radius_m, charge_power_w) VALUES "
        "('far', -5.0, 0.0, 0.3, 20), ('near', 2.0, 0.0, 0.3, 20)",
    )
    await world.goal(0.0, 3.0)  # the mission goal stays active all along
    await world.battery(0.05)
    await world.strategy("CHARGE")
    rec = await world.next_recommendation(lambda r: True, what="driving to the charger")
    assert rec["inputs"].get("charger") == "near" and "goal" not in rec["inputs"]
    assert rec["linear_mps"] > 0  # the station is straight ahead
    assert "charger near" in rec["reason"]

    world.pose = (1.95, 0.0, 0.0)  # inside the station
    stop = await world.next_recommendation(
        lambda r: (
            "charger near" in r["reason"] and r["linear_mps"] == 0.0 and r["angular_rps"] == 0.0
        ),
        after=rec["id"],
        what="a stop at the charger",
    )
    assert "charge" in stop["reason"]
    assert await world.recommendations(kind="system") == []  # no BATTSAVE while charging

    # 3.6 m from the station to the goal x 0.006 + 0.05 = 0.072 Wh; x 3.0 margin = 0.215 Wh
    await world.battery(0.15)
    await asyncio.sleep(0.4)
    assert await world.recommendations(kind="system") == []
    await world.battery(0.3)
    rec = await world.next_recommendation(lambda r: True, kind="system", what="CMD_RESUME")
    assert rec["system_command"] == "CMD_RESUME" and rec["source"] == "charge_complete"
    assert rec["priority"] == 50 and math.isclose(live_window(rec), 2.0)
    await world.battery(19.98)
    await asyncio.sleep(0.5)
    assert len(await world.recommendations(kind="system")) == 1  # once per session
    status = await world.db.pool.fetchval("SELECT status FROM goal WHERE robot_id = $1", ROBOT)
    assert status == "active"


async def test_idle_recommends_nothing_and_an_unknown_scenario_fails_the_goal_with_why(
    world: World, planner: PlannerService
) -> None:
    await world.db.pool.execute(
        "INSERT INTO strategy (code, planner_scenario, params) VALUES "
        "('TELEPORT', 'teleport', '{\"target\": \"goal\"}')"
    )
    goal_id = await world.goal(2.0, 0.0)
    await world.battery(0.01)  # far too low, but IDLE has no planner and no battery check
    await world.strategy("IDLE")
    await asyncio.sleep(0.8)
    assert await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", goal_id) == (
        "active"
    )
    await world.strategy("TELEPORT")  # no such scenario here: the goal fails, no crash
    row = await eventually(
        lambda: world.db.pool.fetchrow(
            "SELECT status, reason FROM goal WHERE id = $1 AND status <> 'active'", goal_id
        ),
        what="the goal marked failed",
    )
    assert row["status"] == "failed"
    assert row["reason"].startswith(
        "strategy TELEPORT names planner scenario 'teleport' that this planner cannot run; "
        "it runs: turn_then_move, move_while_turning"
    )
    assert await world.recommendations() == []
    assert await world.recommendations(kind="system") == []
    await world.strategy("GOTO_DIRECT")  # still alive: a known scenario starts at once
    await world.goal(2.0, 0.0)
    await world.next_recommendation(lambda r: r["source"] == "turn_then_move")


async def test_a_goal_is_failed_for_a_strategy_only_while_that_strategy_is_active(
    world: World, planner: PlannerService
) -> None:
    """The unrunnable rule fails goals for its strategy; a goal given just after a switch it
    has not yet been ended for belongs to the new strategy, and the write refuses it."""
    await world.strategy("IDLE")
    goal_id = await world.goal(2.0, 0.0)
    store = planner.store
    # the robot is on IDLE now: a rule failing goals for TELEPORT fails none
    assert not await store.mark_failed(goal_id, "r1", "stale", 0.0, "TELEPORT")
    assert await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", goal_id) == (
        "active"
    )
    # for the strategy in force, it does
    assert await store.mark_failed(goal_id, "r1", "for IDLE", 0.0, "IDLE")
    assert await world.db.pool.fetchval("SELECT status FROM goal WHERE id = $1", goal_id) == (
        "failed"
    )


async def test_steady_driving_is_recommended_at_a_cadence_not_on_every_odometry_row(
    world: World, planner: PlannerService
) -> None:
    world.pose = (0.0, 0.0, 0.0)
    await world.strategy("GOTO_AVOID")
    goal_id = await world.goal(20.0, 0.0)
    first = await world.next_recommendation(lambda r: r["inputs"].get("goal") == goal_id)
    assert first["linear_mps"] > 0.1
    world.streaming = False
    rows = []
    for _ in range(50):  # odometry at 50 Hz for a second: driving straight, nothing changes
        rows.append(await world.odometry(0.0, 0.0, 0.0))
        await asyncio.sleep(0.02)
    await asyncio.sleep(0.2)
    said = [r for r in await world.recommendations() if r["inputs"]["odometry"] in rows]
    # one every 0.1 s of sim time (here 1 sim s per wall s), not one per row
    assert 5 <= len(said) <= 15, len(said)
    stamps = sorted(float(r["stamp"]) for r in said)
    assert max(b - a for a, b in itertools.pairwise(stamps)) < 0.3
    # A new goal is answered at once, whatever the cadence.
    world.streaming = True
    behind = await world.goal(-2.0, 0.0)
    rec = await world.next_recommendation(lambda r: r["inputs"].get("goal") == behind)
    assert rec["linear_mps"] == 0.0 and rec["angular_rps"] != 0.0


async def test_an_obstacle_the_lidar_sees_but_the_map_does_not_bends_the_route(
    world: World, planner: PlannerService
) -> None:
    # 4 x 2 m at 5 cm, walls all round, nothing inside
    grid = np.zeros((40, 80), dtype=np.uint8)
    grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = 100
    async with world.db.transaction() as tx:
        await tx.conn.execute(
            "INSERT INTO map (map_id, resolution_m, origin_x, origin_y, width, height, grid) "
            "VALUES ('room', 0.05, 0, 0, 80, 40, $1)",
            grid.tobytes(),
        )
        await tx.conn.execute("UPDATE robot SET world = 'room' WHERE robot_id = $1", ROBOT)
        tx.changed(keys.MAP, None)
        tx.changed(keys.ROBOT, ROBOT)
    world.pose = (0.5, 1.0, 0.0)
    await world.strategy("GOTO_AVOID")
    goal_id = await world.goal(3.5, 1.0)
    rec = await world.next_recommendation(
        lambda r: r["inputs"].get("goal") == goal_id and r["linear_mps"] > 0
    )
    assert "waypoint 1/1," in rec["reason"]  # straight across the empty room
    # A crate 1 m ahead, 0.3 m wide, in a sweep taken where the robot stands.
    stamp = await world.db.pool.fetchval("SELECT max(stamp) FROM odometry")
    angles = np.degrees(np.arange(360) * (2 * np.pi / 360))
    angles = np.where(angles > 180, angles - 360, angles)
    ranges = np.where(np.abs(angles) <= 8, 1.0, np.inf).astype(np.float32)
    await world.execute(
        keys.LASER_SCAN,
        ROBOT,
        "INSERT INTO laser_scan (robot_id, stamp, angle_min, angle_increment, range_min, "
        "range_max, ranges) VALUES ($1, $2, 0, $3, 0.12, 3.5, $4) RETURNING id",
        ROBOT,
        stamp,
        2 * np.pi / 360,
        ranges.tolist(),
    )
    bent = await world.next_recommendation(
        lambda r: r["inputs"].get("goal") == goal_id and "waypoint 1/1," not in r["reason"],
        after=rec["id"],
        what="a route round the crate",
    )
    assert bent["inputs"]["goal"] == goal_id
    remaining = float(bent["reason"].split(" m to goal")[0].rsplit(" ", 1)[1])
    assert remaining > 3.05  # longer than the 3 m straight line


async def test_two_replicas_split_the_robots_and_plan_for_each_once(
    world: World, db_url: str, zenoh_settings: ZenohSettings
) -> None:
    robots = [ROBOT, "r2", "r3", "r4"]
    db = world.db
    for robot in robots[1:]:
        await db.write(keys.ROBOT, robot, "INSERT INTO robot (robot_id) VALUES ($1)", robot)
    for robot in robots:
        await db.write(
            keys.ACTIVE_STRATEGY,
            robot,
            "INSERT INTO active_strategy (robot_id, strategy_code, source) "
            "VALUES ($1, 'GOTO_AVOID', 'user')",
            robot,
        )
        await db.write(
            keys.GOAL,
            robot,
            "INSERT INTO goal (robot_id, x, y, tolerance_m, stamp) VALUES ($1, 0, 2, 0.15, $2)",
            robot,
            world.now(),
        )

    async def odometry() -> None:  # the world streams r1's; the others' here, as a bridge
        while True:
            for robot in robots[1:]:
                await db.write(
                    keys.ODOMETRY,
                    robot,
                    "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps)"
                    " VALUES ($1, $2, 0, 0, 0, 0, 0)",
                    robot,
                    world.now(),
                )
            await asyncio.sleep(0.1)

    def config(instance: str) -> ServiceConfig:
        return ServiceConfig(
            service="planner",
            database_url=db_url,
            zenoh=zenoh_settings,
            engine=EngineSettings(period_s=0.05),
            leases=LeaseSettings(period_s=0.2, timeout_s=2.0),
            stats_period_s=5.0,
            instance=instance,
        )

    feed = asyncio.create_task(odometry())
    try:
        async with (
            running_service(PlannerService, config("planner-a")) as a,
            running_service(PlannerService, config("planner-b")) as b,
        ):
            assert isinstance(a, PlannerService) and isinstance(b, PlannerService)
            shares = await split_between([a, b], robots)
            await asyncio.sleep(1.0)  # past any hand-over
            after = await world.newest_id()

            async def every_robot_planned() -> bool:
                rows = await db.pool.fetch(
                    "SELECT DISTINCT robot_id FROM command_recommendation "
                    "WHERE id > $1 AND source = 'turn_then_move'",
                    after,
                )
                return len(rows) == len(robots)

            await eventually(every_robot_planned, what="a recommendation for every robot")
            await asyncio.sleep(1.0)
            # Each robot's planner rules live in the replica that owns it, and only there.
            for robot in robots:
                planned_by = [s for s in (a, b) if s.rules and s.rules.running(robot)]
                owners = [s for s, share in zip((a, b), shares, strict=True) if robot in share]
                assert planned_by == owners, robot
            assert await split_between([a, b], robots) == shares
            # Up to here both replicas ran; stopping one hands its robots to the other, which
            # may then say again what the first said about the newest odometry row: a
            # hand-over in turn, not two owners at once, so it is left out of the count.
            until = await world.newest_id()
    finally:
        feed.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await feed
    # One replica never says the same thing twice about one odometry row; two would.
    twice = await db.pool.fetch(
        "SELECT robot_id, inputs->>'odometry' AS odometry, count(*) FROM command_recommendation"
        " WHERE id > $1 AND id <= $2 AND kind = 'robot' GROUP BY 1, 2 HAVING count(*) > 1",
        after,
        until,
    )
    assert twice == []
    assert sorted(len(share) for share in shares) == [2, 2]
