"""The decision service alone against Postgres and Zenoh, fed recommendations as a foreign
client would: plain SQL inserts and the notification every writer publishes."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import asyncpg
import pytest

from common.config import LeaseSettings, ServiceConfig
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import ClockPlayer, eventually, running_service
from services.decision.service import DecisionService
from tests.contract.conftest import split_between

RECOMMEND_SQL = """
INSERT INTO command_recommendation (robot_id, kind, source, priority, linear_mps, angular_rps,
    system_command, stamp, expires_stamp, reason)
VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10)
RETURNING id
"""


def velocity(
    source: str,
    priority: int,
    linear: float,
    angular: float,
    *,
    stamp: float = 10.0,
    expires: float = 1000.0,
    reason: str = "",
    robot_id: str = "r1",
) -> tuple[Any, ...]:
    return (robot_id, "robot", source, priority, linear, angular, None, stamp, expires, reason)


def system(
    source: str,
    priority: int,
    command: str,
    *,
    stamp: float = 10.0,
    expires: float = 1000.0,
    robot_id: str = "r1",
) -> tuple[Any, ...]:
    return (robot_id, "system", source, priority, None, None, command, stamp, expires, "")


async def recommend(client: Runtime, *rows: tuple[Any, ...]) -> list[int]:
    """Insert ``rows`` in one transaction, then notify once, as a recommender would."""
    async with client.database.transaction() as tx:
        ids = [int(await tx.conn.fetchval(RECOMMEND_SQL, *row)) for row in rows]
        for row, row_id in zip(rows, ids, strict=True):
            tx.changed(keys.COMMAND_RECOMMENDATION, row[0], row_id)
    return ids


async def add_robot(client: Runtime, robot_id: str = "r1") -> None:
    await client.database.write(
        keys.ROBOT, robot_id, "INSERT INTO robot (robot_id) VALUES ($1)", robot_id
    )


async def commands(client: Runtime, robot_id: str = "r1") -> list[dict[str, Any]]:
    rows = await client.database.pool.fetch(
        "SELECT * FROM command2robot WHERE robot_id = $1 ORDER BY id", robot_id
    )
    return [dict(r) for r in rows]


async def newest_from(client: Runtime, recommendation_id: int | None) -> dict[str, Any]:
    """Wait for the newest command2robot row to come from ``recommendation_id``."""

    async def probe() -> dict[str, Any] | None:
        rows = await commands(client)
        if rows and rows[-1]["recommendation_id"] == recommendation_id:
            return rows[-1]
        return None

    return await eventually(
        probe, what=f"a command2robot row from recommendation {recommendation_id}"
    )


async def clock_at(service: Any, stamp: float) -> None:
    async def probe() -> bool:
        return bool(service.runtime.clock.now() >= stamp)

    await eventually(probe, what=f"the service to see sim time {stamp}")


async def more_activations(service: Any, n: int) -> None:
    """Let the engine look at the tables ``n`` more times."""
    start = service.engine.counters.activations

    async def probe() -> bool:
        return bool(service.engine.counters.activations - start >= n)

    await eventually(probe, what=f"{n} more activations")


async def treated_by(client: Runtime, ids: Sequence[int]) -> list[int | None]:
    rows = await client.database.pool.fetch(
        "SELECT id, treated_by FROM command_recommendation WHERE id = ANY($1::bigint[]) "
        "ORDER BY id",
        list(ids),
    )
    return [r["treated_by"] for r in rows]


async def test_priority_wins_and_the_row_explains_itself(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client)
    async with running_service(DecisionService, service_config) as service:
        await clock_at(service, 10.0)
        ids = await recommend(
            client,
            velocity("turn_then_move", 10, 0.2, 0.0),
            velocity("avoid_left", 50, 0.05, 0.8),
            velocity("safety_stop", 100, 0.0, 0.0, reason="obstacle 0.12 m ahead"),
        )
        row = await newest_from(client, ids[2])
        assert (row["source"], row["linear_mps"], row["angular_rps"]) == ("safety_stop", 0, 0)
        assert row["stamp"] == pytest.approx(10.0)
        assert row["reason"] == (
            "safety_stop (priority 100) over avoid_left (50), turn_then_move (10): "
            "obstacle 0.12 m ahead"
        )
        assert sorted(row["considered_ids"]) == sorted(ids)
        marks = await treated_by(client, ids)
        assert None not in marks
        # treated_by names a decision that considered every one of them
        for mark in set(marks):
            decided = await client.database.pool.fetchrow(
                "SELECT considered_ids FROM command2robot WHERE id = $1", mark
            )
            assert decided is not None and set(ids) <= set(decided["considered_ids"])


async def test_a_tie_goes_to_the_newest(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client)
    async with running_service(DecisionService, service_config) as service:
        await clock_at(service, 10.0)
        ids = await recommend(
            client, velocity("avoid_left", 50, 0.0, 0.5), velocity("avoid_right", 50, 0.0, -0.5)
        )
        row = await newest_from(client, ids[1])
        assert (row["source"], row["angular_rps"]) == ("avoid_right", -0.5)


async def test_an_expired_recommendation_loses_to_a_live_lower_one(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client)
    async with running_service(DecisionService, service_config) as service:
        await clock_at(service, 10.0)
        high, low = await recommend(
            client,
            velocity("safety_stop", 100, 0.0, 0.0, expires=10.5),
            velocity("turn_then_move", 10, 0.2, 0.1),
        )
        await newest_from(client, high)
        clock.stamp = 11.0  # the safety_stop row has expired
        row = await newest_from(client, low)
        assert row["source"] == "turn_then_move"
        assert row["considered_ids"] == [low]
        assert row["stamp"] >= 10.5


async def test_the_winner_is_reissued_as_sim_time_passes(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client)
    async with running_service(DecisionService, service_config) as service:
        await clock_at(service, 10.0)
        (rec,) = await recommend(client, velocity("turn_then_move", 10, 0.2, 0.0))
        first = await newest_from(client, rec)
        # Sim time runs at half wall speed: a loaded machine still gets several activations
        # per 0.1 s of sim time.
        clock.rate = 0.5
        await clock_at(service, first["stamp"] + 1.0)
        rows = [r for r in await commands(client) if r["stamp"] <= first["stamp"] + 1.0]
        # Every 0.1 s of sim time at best; on a loaded machine fewer, but never only one.
        assert len(rows) >= 5, [r["stamp"] for r in rows]
        assert {r["recommendation_id"] for r in rows} == {rec}
        stamps = [r["stamp"] for r in rows]
        assert stamps == sorted(stamps)


async def test_one_stop_row_when_the_recommendations_expire(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client)
    async with running_service(DecisionService, service_config) as service:
        await clock_at(service, 10.0)
        (rec,) = await recommend(client, velocity("turn_then_move", 10, 0.2, 0.0, expires=10.3))
        await newest_from(client, rec)
        clock.rate = 1.0
        stop = await newest_from(client, None)
        assert (stop["linear_mps"], stop["angular_rps"], stop["source"]) == (0, 0, None)
        assert stop["reason"] == "no live recommendation"
        assert stop["considered_ids"] == []
        await clock_at(service, stop["stamp"] + 0.6)  # longer than the bridge's watchdog
        rows = await commands(client)
        assert [r["id"] for r in rows if r["recommendation_id"] is None] == [stop["id"]]
        assert rows[-1]["id"] == stop["id"]


async def test_a_recommender_the_service_never_heard_of_is_obeyed(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client)
    async with running_service(DecisionService, service_config) as service:
        await clock_at(service, 10.0)
        (avoid,) = await recommend(client, velocity("avoid_left", 50, 0.0, 0.6))
        await newest_from(client, avoid)
        (new,) = await recommend(
            client, velocity("my_new_scenario", 75, 0.1, -0.3, reason="a brand new idea")
        )
        row = await newest_from(client, new)
        assert (row["source"], row["linear_mps"], row["angular_rps"]) == (
            "my_new_scenario",
            pytest.approx(0.1),
            pytest.approx(-0.3),
        )
        assert (
            row["reason"] == "my_new_scenario (priority 75) over avoid_left (50): a brand new idea"
        )


async def test_system_recommendations_become_one_system_command_each(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client)

    async def system_commands() -> list[dict[str, Any]]:
        rows = await client.database.pool.fetch("SELECT * FROM system_command ORDER BY id")
        return [dict(r) for r in rows]

    async with running_service(DecisionService, service_config) as service:
        await clock_at(service, 10.0)
        save, low = await recommend(
            client,
            system("battery_check", 60, "CMD_BATTSAVE", expires=10.5),
            system("charge_complete", 50, "CMD_RESUME"),
        )
        first = (await eventually(system_commands, what="a system_command row"))[0]
        assert (first["command"], first["recommendation_id"], first["status"]) == (
            "CMD_BATTSAVE",
            save,
            "pending",
        )
        assert sorted(first["considered_ids"]) == [save, low]
        assert first["reason"].startswith("battery_check (priority 60) over charge_complete (50)")
        assert first["stamp"] == pytest.approx(10.0)
        assert await treated_by(client, [save, low]) == [first["id"], first["id"]]
        # The winner is treated: however often the service looks, no second row for it.
        clock.stamp = 10.3
        await clock_at(service, 10.3)
        await more_activations(service, 5)
        assert len(await system_commands()) == 1

        # The CMD_BATTSAVE expires. The CMD_RESUME it beat was consumed by that decision (it
        # carries treated_by): it is not sent late. A fresh recommendation is.
        clock.stamp = 11.0
        await clock_at(service, 11.0)
        await more_activations(service, 5)
        assert len(await system_commands()) == 1
        (fresh,) = await recommend(client, system("charge_complete", 50, "CMD_RESUME", stamp=11.0))
        rows = await eventually(
            lambda: _at_least(system_commands, 2), what="a second system_command row"
        )
        second = rows[1]
        assert (second["command"], second["recommendation_id"]) == ("CMD_RESUME", fresh)
        assert sorted(second["considered_ids"]) == [low, fresh]  # tie: the newest won
        assert await treated_by(client, [low, fresh]) == [second["id"], second["id"]]
        assert await commands(client) == []  # system recommendations never move the robot


async def _at_least(probe: Any, n: int) -> Any:
    rows = await probe()
    return rows if len(rows) >= n else None


async def test_the_period_picks_up_a_row_written_without_notification(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig, db_url: str
) -> None:
    await add_robot(client)
    async with running_service(DecisionService, service_config) as service:
        await clock_at(service, 10.0)
        plain = await asyncpg.connect(db_url)
        try:
            rec = await plain.fetchval(RECOMMEND_SQL, *velocity("avoid_right", 50, 0.0, -0.4))
        finally:
            await plain.close()
        row = await newest_from(client, rec)
        assert row["source"] == "avoid_right"
        assert service.engine.counters.woken_by_period > 0


async def test_two_replicas_split_the_robots_and_decide_each_once(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    robots = ["r1", "r2", "r3", "r4"]
    for robot in robots:
        await add_robot(client, robot)
    await recommend(client, *(velocity("goto", 10, 0.1, 0.0, robot_id=r) for r in robots))
    leases = LeaseSettings(period_s=0.2, timeout_s=2.0)
    a_config = replace(service_config, leases=leases, instance="decision-a")
    b_config = replace(service_config, leases=leases, instance="decision-b")
    async with running_service(DecisionService, a_config) as a:
        await clock_at(a, 10.0)
        async with running_service(DecisionService, b_config) as b:
            await split_between([a, b], robots)
            # Sim time holds still: a robot served by both replicas would get two rows.
            ids = await recommend(
                client, *(velocity("avoid_left", 50, 0.0, 0.5, robot_id=r) for r in robots)
            )

            async def every_robot_decided() -> bool:
                rows = await client.database.pool.fetch(
                    "SELECT DISTINCT robot_id FROM command2robot "
                    "WHERE recommendation_id = ANY($1::bigint[])",
                    ids,
                )
                return len(rows) == len(robots)

            await eventually(every_robot_decided, what="a command for every robot")
            await more_activations(a, 5)
            await more_activations(b, 5)
            shares = await split_between([a, b], robots)
    for robot, rec in zip(robots, ids, strict=True):
        rows = await commands(client, robot)
        # The first goto, issued once by whoever owned the robot then (a newcomer carries
        # on from the table), and the avoid_left, issued once by its owner.
        assert [r["recommendation_id"] for r in rows][-1:] == [rec], (robot, rows)
        assert [r["recommendation_id"] for r in rows].count(rec) == 1, (robot, rows)
        assert len(rows) == 2, (robot, rows)
    assert sorted(len(share) for share in shares) == [2, 2]


async def test_a_robot_handed_over_mid_write_is_not_decided_again_by_its_next_owner(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    """The lease hand-over race, made certain: replica a's write of the robots' commands is
    held back (the test locks command2robot against inserts) while replica b joins and a
    gives one robot back. b must not read the table before a's row is in, or it issues the
    same command a second time (docs/REPLICAS.md, "The hand-over")."""
    robots = ["r1", "r2"]
    for robot in robots:
        await add_robot(client, robot)
    leases = LeaseSettings(period_s=0.2, timeout_s=2.0)
    a_config = replace(service_config, leases=leases, instance="decision-a")
    b_config = replace(service_config, leases=leases, instance="decision-b")
    pool = client.database.pool

    async def inserts_waiting() -> int:
        return int(
            await pool.fetchval(
                "SELECT count(*) FROM pg_locks "
                "WHERE relation = 'command2robot'::regclass AND NOT granted"
            )
        )

    async with running_service(DecisionService, a_config) as a:
        await clock_at(a, 10.0)
        async with pool.acquire() as blocker:
            tx = blocker.transaction()
            await tx.start()
            held = True
            try:
                await blocker.execute("LOCK TABLE command2robot IN SHARE MODE")
                ids = await recommend(
                    client, *(velocity("goto", 10, 0.1, 0.0, robot_id=r) for r in robots)
                )
                await eventually(inserts_waiting, what="a's write of both commands in flight")
                async with running_service(DecisionService, b_config) as b:
                    assert a.leases is not None and b.leases is not None
                    await eventually(
                        lambda: len(a.owned_robots() or ()) == 1, what="a gives a robot back"
                    )
                    b_cycles = b.leases.counters.cycles

                    async def b_had_its_chance() -> bool:
                        # b has looked often enough to take the robot if a had let it go,
                        # and (had it taken it) to have tried to write its command
                        if b.leases is None or b.leases.counters.cycles < b_cycles + 5:
                            return False
                        return not b.owned_robots() or await inserts_waiting() >= 2

                    await eventually(b_had_its_chance, what="b's lease cycles")
                    await tx.rollback()  # a's write goes in
                    held = False
                    await split_between([a, b], robots)
                    await more_activations(b, 5)
                    await more_activations(a, 5)
            finally:
                if held:
                    await tx.rollback()
    for robot, rec in zip(robots, ids, strict=True):
        rows = await commands(client, robot)
        assert [r["recommendation_id"] for r in rows] == [rec], (robot, rows)
