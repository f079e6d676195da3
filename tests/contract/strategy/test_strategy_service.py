"""The strategy service alone against Postgres and Zenoh, fed rows as a foreign client would."""

from __future__ import annotations

import asyncio
import threading
from dataclasses import replace
from typing import Any

import asyncpg
import pytest

from common import bus
from common.config import LeaseSettings, ServiceConfig
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import ClockPlayer, eventually, running_service
from services.strategy.scenario import ApplyCommand
from services.strategy.service import StrategyService
from tests.contract.conftest import CLOCK_START, split_between

USER_SQL = "INSERT INTO user_command (robot_id, command, argument) VALUES ($1, $2, $3) RETURNING id"
SYSTEM_SQL = (
    "INSERT INTO system_command (robot_id, command, reason, stamp) "
    "VALUES ($1, $2, 'test', 1.0) RETURNING id"
)


async def add_robot(client: Runtime, robot_id: str) -> None:
    await client.database.write(
        keys.ROBOT, robot_id, "INSERT INTO robot (robot_id) VALUES ($1)", robot_id
    )


async def user_command(
    client: Runtime, robot_id: str, command: str, argument: str | None = None
) -> int:
    return int(
        await client.database.write(
            keys.USER_COMMAND, robot_id, USER_SQL, robot_id, command, argument
        )
    )


async def system_command(client: Runtime, robot_id: str, command: str) -> int:
    return int(
        await client.database.write(keys.SYSTEM_COMMAND, robot_id, SYSTEM_SQL, robot_id, command)
    )


async def active(client: Runtime, robot_id: str) -> dict[str, Any] | None:
    row = await client.database.pool.fetchrow(
        "SELECT * FROM active_strategy WHERE robot_id = $1", robot_id
    )
    return dict(row) if row else None


async def treated(client: Runtime, table: str, command_id: int) -> dict[str, Any]:
    async def probe() -> dict[str, Any] | None:
        row = await client.database.pool.fetchrow(
            f"SELECT * FROM {table} WHERE id = $1 AND status <> 'pending'", command_id
        )
        return dict(row) if row else None

    return await eventually(probe, what=f"{table} {command_id} to be treated")


async def default_applied(client: Runtime, robot_id: str) -> dict[str, Any]:
    return await eventually(lambda: active(client, robot_id), what=f"{robot_id}'s default strategy")


async def started(service: StrategyService) -> None:
    """The service heard the sim clock (so the stamps it writes are defined)."""

    async def probe() -> bool:
        return service.runtime.clock.started

    await eventually(probe, what="the service to hear the sim clock")


async def test_a_new_robot_gets_the_default_strategy(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    async with running_service(StrategyService, service_config) as service:
        assert isinstance(service, StrategyService)
        await started(service)
        await add_robot(client, "r1")
        row = await default_applied(client, "r1")
        assert row["strategy_code"] == "GOTO_AVOID"
        assert row["source"] == "default"
        assert row["resume_code"] is None and row["command_id"] is None
        assert row["stamp"] == pytest.approx(CLOCK_START)


async def test_set_strategy_is_accepted_and_notified(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    notes: list[bus.Notification] = []
    lock = threading.Lock()

    def on_note(key: str, payload: bytes) -> None:
        with lock:
            notes.append(bus.Notification.decode(key, payload))

    sub = bus.subscribe_threaded(client.zenoh, keys.notify_key(keys.ACTIVE_STRATEGY, "r1"), on_note)
    try:
        await add_robot(client, "r1")
        async with running_service(StrategyService, service_config) as service:
            assert isinstance(service, StrategyService)
            await started(service)
            await default_applied(client, "r1")
            clock.stamp = 20.0
            await eventually(
                lambda: _clock_at(service, 20.0), what="the service to see sim time 20"
            )
            command_id = await user_command(client, "r1", "SET_STRATEGY", "GOTO_DIRECT")
            row = await treated(client, keys.USER_COMMAND, command_id)
            assert row["status"] == "accepted"
            assert row["reason"] == "GOTO_AVOID -> GOTO_DIRECT"
            assert row["treated_at"] is not None
            now = await active(client, "r1")
            assert now is not None
            assert (now["strategy_code"], now["source"], now["command_id"]) == (
                "GOTO_DIRECT",
                "user",
                command_id,
            )
            assert now["stamp"] == pytest.approx(20.0)

            async def notified() -> int:
                with lock:
                    return len(notes)

            await eventually(notified, what="active_strategy notifications")  # default, then user
            await eventually(lambda: _at_least(notified, 2), what="the second notification")
            with lock:
                assert all(n.robot == "r1" and n.table == keys.ACTIVE_STRATEGY for n in notes)
    finally:
        sub.undeclare()


async def _clock_at(service: StrategyService, stamp: float) -> bool:
    return service.runtime.clock.now() >= stamp


async def _at_least(probe: Any, n: int) -> bool:
    return bool(await probe() >= n)


async def test_a_strategy_inserted_at_run_time_is_selectable_at_once(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client, "r1")
    async with running_service(StrategyService, service_config):
        await default_applied(client, "r1")
        # Used once before it exists, so any cache would have to be refreshed.
        early = await user_command(client, "r1", "SET_STRATEGY", "PATROL")
        assert (await treated(client, keys.USER_COMMAND, early))["status"] == "rejected"
        await client.database.write(
            keys.STRATEGY,
            None,
            "INSERT INTO strategy (code, planner_scenario, controller_scenarios, description) "
            "VALUES ('PATROL', 'move_while_turning', '{safety_stop}', 'added at run time')",
        )
        command_id = await user_command(client, "r1", "SET_STRATEGY", "PATROL")
        row = await treated(client, keys.USER_COMMAND, command_id)
        assert (row["status"], row["reason"]) == ("accepted", "GOTO_AVOID -> PATROL")
        now = await active(client, "r1")
        assert now is not None and now["strategy_code"] == "PATROL"


async def test_battsave_then_resume_round_trip(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client, "r1")
    async with running_service(StrategyService, service_config):
        await default_applied(client, "r1")
        set_id = await user_command(client, "r1", "SET_STRATEGY", "GOTO_DIRECT")
        await treated(client, keys.USER_COMMAND, set_id)

        save_id = await system_command(client, "r1", "CMD_BATTSAVE")
        save = await treated(client, keys.SYSTEM_COMMAND, save_id)
        assert save["status"] == "accepted"
        assert save["status_reason"].startswith("GOTO_DIRECT -> CHARGE")
        now = await active(client, "r1")
        assert now is not None
        assert (now["strategy_code"], now["resume_code"], now["source"], now["command_id"]) == (
            "CHARGE",
            "GOTO_DIRECT",
            "system",
            save_id,
        )

        resume_id = await system_command(client, "r1", "CMD_RESUME")
        resume = await treated(client, keys.SYSTEM_COMMAND, resume_id)
        assert resume["status"] == "accepted"
        assert resume["status_reason"].startswith("CHARGE -> GOTO_DIRECT")
        now = await active(client, "r1")
        assert now is not None
        assert (now["strategy_code"], now["resume_code"], now["command_id"]) == (
            "GOTO_DIRECT",
            None,
            resume_id,
        )


async def test_rejections_carry_a_reason_and_change_nothing(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client, "r1")
    async with running_service(StrategyService, service_config):
        before = await default_applied(client, "r1")
        cases = [
            ("DANCE", None, "unknown command"),
            ("SET_STRATEGY", "NO_SUCH", "unknown strategy"),
            ("SET_STRATEGY", None, "needs a strategy code"),
            ("CMD_RESUME", None, "nothing to resume"),
        ]
        ids = [await user_command(client, "r1", c, a) for c, a, _ in cases]
        for command_id, (command, _, why) in zip(ids, cases, strict=True):
            row = await treated(client, keys.USER_COMMAND, command_id)
            assert row["status"] == "rejected", command
            assert why in row["reason"], row["reason"]
            assert row["treated_at"] is not None
        assert await active(client, "r1") == before

        save_id = await system_command(client, "r1", "CMD_BATTSAVE")
        assert (await treated(client, keys.SYSTEM_COMMAND, save_id))["status"] == "accepted"
        charging = await active(client, "r1")
        assert charging is not None and charging["strategy_code"] == "CHARGE"
        again = await user_command(client, "r1", "CMD_BATTSAVE")
        row = await treated(client, keys.USER_COMMAND, again)
        assert row["status"] == "rejected" and "already in CHARGE" in row["reason"]
        assert await active(client, "r1") == charging


async def test_commands_apply_in_id_order_even_without_notifications(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig, db_url: str
) -> None:
    await add_robot(client, "r1")
    async with running_service(StrategyService, service_config) as service:
        await default_applied(client, "r1")
        # One transaction, no notification at all: only the period F can find these.
        plain = await asyncpg.connect(db_url)
        try:
            async with plain.transaction():
                ids = [
                    await plain.fetchval(USER_SQL, "r1", "SET_STRATEGY", code)
                    for code in ("IDLE", "CHARGE", "GOTO_DIRECT")
                ]
                ids.append(await plain.fetchval(USER_SQL, "r1", "CMD_BATTSAVE", None))
        finally:
            await plain.close()
        rows = [await treated(client, keys.USER_COMMAND, i) for i in ids]
        assert [r["reason"] for r in rows] == [
            "GOTO_AVOID -> IDLE",
            "IDLE -> CHARGE",
            "CHARGE -> GOTO_DIRECT",
            "GOTO_DIRECT -> CHARGE (resume GOTO_DIRECT)",
        ]
        stamps = [r["treated_at"] for r in rows]
        assert stamps == sorted(stamps)
        now = await active(client, "r1")
        assert now is not None
        assert (now["strategy_code"], now["resume_code"], now["command_id"]) == (
            "CHARGE",
            "GOTO_DIRECT",
            ids[-1],
        )
        assert service.engine.counters.woken_by_period > 0


async def test_a_restarted_service_carries_on_from_the_tables(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client, "r1")
    async with running_service(StrategyService, service_config):
        await default_applied(client, "r1")
        save_id = await user_command(client, "r1", "CMD_BATTSAVE")
        assert (await treated(client, keys.USER_COMMAND, save_id))["status"] == "accepted"
    # Down: a command arrives meanwhile, and nobody hears its notification.
    resume_id = await system_command(client, "r1", "CMD_RESUME")
    await asyncio.sleep(0.2)
    row = await client.database.pool.fetchrow(
        "SELECT status FROM system_command WHERE id = $1", resume_id
    )
    assert row is not None and row["status"] == "pending"

    async with running_service(StrategyService, service_config):
        resume = await treated(client, keys.SYSTEM_COMMAND, resume_id)
        assert (resume["status"], resume["status_reason"]) == (
            "accepted",
            "CHARGE -> GOTO_AVOID (resumed)",
        )
        now = await active(client, "r1")
        assert now is not None
        assert (now["strategy_code"], now["resume_code"], now["source"]) == (
            "GOTO_AVOID",
            None,
            "system",
        )


async def test_two_replicas_split_the_robots_and_apply_each_command_once(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    robots = ["r1", "r2", "r3", "r4"]
    leases = LeaseSettings(period_s=0.2, timeout_s=2.0)
    a_config = replace(service_config, leases=leases, instance="strategy-a")
    b_config = replace(service_config, leases=leases, instance="strategy-b")
    async with (
        running_service(StrategyService, a_config) as a,
        running_service(StrategyService, b_config) as b,
    ):
        for robot in robots:
            await add_robot(client, robot)
        for robot in robots:
            await default_applied(client, robot)
        shares = await split_between([a, b], robots)
        before = [s.engine.stats_for(ApplyCommand).executed for s in (a, b)]
        ids = [await user_command(client, r, "SET_STRATEGY", "GOTO_DIRECT") for r in robots]
        for command_id in ids:
            assert (await treated(client, keys.USER_COMMAND, command_id))["status"] == "accepted"
        after = [s.engine.stats_for(ApplyCommand).executed for s in (a, b)]
        assert await split_between([a, b], robots) == shares
    # Each command was taken up by one replica only: the one owning its robot.
    assert [n - m for n, m in zip(after, before, strict=True)] == [len(s) for s in shares]
    assert sorted(len(share) for share in shares) == [2, 2]
