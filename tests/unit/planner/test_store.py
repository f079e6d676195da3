"""The planner's store: what it reads again, and when (notifications, fallback times), on
the in-memory contract. A row written with no notification stands for a lost one."""

from __future__ import annotations

from common.bus import Notification
from common.contract import keys
from pnav.monolith.memory_planner import MemoryPlannerSource
from services.planner.store import FAST_REFRESH_S, REFRESH_S
from tests.unit.planner.harness import ROBOT, Planner


def robot_row(robot_id: str) -> dict[str, object]:
    return {
        "robot_id": robot_id,
        "world": None,
        "max_linear_mps": 0.22,
        "max_angular_rps": 2.84,
        "footprint_radius_m": 0.105,
    }


async def test_the_world_is_read_again_on_a_notification_or_once_refresh_s_is_exceeded() -> None:
    p = Planner()
    store = p.store
    await store.refresh()
    assert [r.info.robot_id for r in store.robots()] == [ROBOT]
    p.contract.insert(keys.ROBOT, robot_row("r2"), notify=False)  # its notification is lost
    p.t += REFRESH_S
    await store.refresh()
    assert [r.info.robot_id for r in store.robots()] == [ROBOT]  # not yet: exactly REFRESH_S
    p.t += 1e-6
    await store.refresh()
    assert [r.info.robot_id for r in store.robots()] == [ROBOT, "r2"]
    p.contract.insert(keys.ROBOT, robot_row("r3"))  # notified: read at the next refresh
    await store.refresh()
    assert [r.info.robot_id for r in store.robots()] == [ROBOT, "r2", "r3"]


async def test_a_strategy_change_is_read_at_once_and_a_lost_one_after_fast_refresh_s() -> None:
    p = Planner()
    store = p.store
    p.strategy("GOTO_AVOID")
    await store.refresh()
    robot = store.robot(ROBOT)
    assert robot is not None and robot.strategy is not None
    assert robot.strategy.code == "GOTO_AVOID"
    p.strategy("CHARGE")
    await store.refresh()
    assert robot.strategy.code == "CHARGE"
    row = {"robot_id": ROBOT, "strategy_code": "IDLE", "resume_code": None, "source": "user"}
    p.contract.insert(keys.ACTIVE_STRATEGY, row, notify=False)
    p.t += FAST_REFRESH_S
    await store.refresh()
    assert robot.strategy.code == "CHARGE"
    p.t += 1e-6
    await store.refresh()
    assert robot.strategy.code == "IDLE"


async def test_the_goal_is_read_again_after_a_goal_notification_and_says_it_has_news() -> None:
    p = Planner()
    store = p.store
    await store.refresh()
    robot = store.robot(ROBOT)
    assert robot is not None
    assert not store.goal_news(robot)  # never read: nothing to compare with
    assert await store.active_goal(robot) is None
    first = p.goal(1.0, 0.0)  # notified
    assert store.goal_news(robot)
    goal = await store.active_goal(robot)
    assert goal is not None and goal.id == first
    assert not store.goal_news(robot)
    p.contract[keys.GOAL].by_id[first]["status"] = "cancelled"  # changed in place, not told
    assert await store.active_goal(robot) == goal  # the cached read stands...
    p.t += FAST_REFRESH_S + 1e-6
    assert await store.active_goal(robot) is None  # ...until FAST_REFRESH_S is exceeded
    second = p.goal(2.0, 0.0)
    p.contract.changed(keys.GOAL, None, None)  # a hint naming no robot: every robot's goal
    assert store.goal_news(robot)
    goal = await store.active_goal(robot)
    assert goal is not None and goal.id == second


async def test_marking_a_goal_reached_notifies_and_the_next_read_sees_it() -> None:
    p = Planner()
    store = p.store
    await store.refresh()
    robot = store.robot(ROBOT)
    assert robot is not None
    goal_id = p.goal(1.0, 0.0)
    assert await store.active_goal(robot) is not None
    assert await store.mark_reached(goal_id, ROBOT, p.t)
    assert not await store.mark_reached(goal_id, ROBOT, p.t)  # no longer active
    assert p.contract[keys.GOAL].by_id[goal_id]["status"] == "reached"
    assert await store.active_goal(robot) is None  # read again: our own write notified


async def test_odometry_notifications_are_counted_per_robot() -> None:
    p = Planner()
    before = p.store.odometry_notes(ROBOT)
    p.sense(0.05)
    p.sense(0.05)
    assert p.store.odometry_notes(ROBOT) == before + 2
    assert p.store.odometry_notes("r9") == 0


def image_note(p: Planner, seq: int, table: str = keys.ODOMETRY) -> Notification:
    """The newest ``table`` row's notification with its image, numbered ``seq``."""
    row = p.contract[table].newest(ROBOT)
    assert row is not None
    return Notification(table, ROBOT, row["id"], dict(row), "test", seq)


async def test_an_odometry_image_stands_in_for_the_query_until_fast_refresh_s() -> None:
    p = Planner()
    store = p.store
    p.sense(0.05)
    store.note(image_note(p, 1))
    newest = await store.newest_odometry(ROBOT)
    assert newest is not None and newest.stamp == p.t
    assert newest == await MemoryPlannerSource(p.contract).newest_odometry(ROBOT)
    assert store.odometry_reads == 0  # the image stood in for the query
    p.sense(0.05)  # a bare hint (the harness's listener): the table is read
    source = MemoryPlannerSource(p.contract)
    assert (await store.newest_odometry(ROBOT)) == await source.newest_odometry(ROBOT)
    assert store.odometry_reads == 1
    store.note(image_note(p, 3))  # seq 2 never came: a gap, read the table
    await store.newest_odometry(ROBOT)
    assert store.odometry_reads == 2
    store.note(image_note(p, 4))
    await store.newest_odometry(ROBOT)
    assert store.odometry_reads == 2
    p.t += FAST_REFRESH_S  # nothing heard for the period: read the table
    await store.newest_odometry(ROBOT)
    assert store.odometry_reads == 3


async def test_a_battery_image_stands_in_for_the_query_until_refresh_s() -> None:
    p = Planner()
    store, source = p.store, MemoryPlannerSource(p.contract)
    p.sense(0.05)
    store.note(image_note(p, 1, keys.BATTERY))
    newest = await store.newest_battery(ROBOT)
    assert newest is not None and newest == await source.newest_battery(ROBOT)
    assert store.battery_reads == 0  # the image stood in for the query
    p.t += FAST_REFRESH_S  # longer than odometry's fallback: the battery reports at 1 Hz
    assert await store.newest_battery(ROBOT) == newest
    assert store.battery_reads == 0
    p.sense(0.05)  # a bare hint (the harness's listener): the table is read
    assert await store.newest_battery(ROBOT) == await source.newest_battery(ROBOT)
    assert store.battery_reads == 1
    store.note(image_note(p, 3, keys.BATTERY))  # seq 2 never came: a gap, read the table
    await store.newest_battery(ROBOT)
    assert store.battery_reads == 2
    store.note(image_note(p, 4, keys.BATTERY))
    await store.newest_battery(ROBOT)
    assert store.battery_reads == 2
    p.t += REFRESH_S  # nothing heard for the period: read the table
    await store.newest_battery(ROBOT)
    assert store.battery_reads == 3


async def test_velocity_recommendations_wait_for_the_activation_end_and_go_together() -> None:
    p = Planner()  # as the service: the engine's activation end flushes the store
    store = p.store
    p.contract.insert(keys.ROBOT, robot_row("r2"))
    fields = {"priority": 10, "stamp": p.t, "ttl_s": 0.5, "reason": "test", "inputs": {}}
    for robot_id in (ROBOT, "r2"):
        await store.recommend_velocity(
            robot_id, source="turn_then_move", linear=0.1, angular=0.0, **fields
        )
    # a system recommendation is written at once: the battery rule reads it back
    await store.recommend_system(ROBOT, source="battery_check", command="CMD_BATTSAVE", **fields)
    rows = p.contract[keys.COMMAND_RECOMMENDATION].all_rows()
    assert [(r["robot_id"], r["kind"]) for r in rows] == [(ROBOT, "system")]
    await p.engine.activation()  # its end writes what was held, in one call
    rows = p.contract[keys.COMMAND_RECOMMENDATION].all_rows()
    assert sorted((r["robot_id"], r["kind"]) for r in rows) == [
        (ROBOT, "robot"), (ROBOT, "system"), ("r2", "robot"),
    ]  # fmt: skip
    outbox = store.outbox
    assert outbox is not None and (outbox.calls, outbox.written) == (1, 2)  # one write
