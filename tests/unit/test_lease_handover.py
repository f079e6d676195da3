"""The hand-over: a robot given back keeps its lock until the work under way has ended.

Two :class:`~common.lease.LeaseManager` against a real Postgres. The first one's
``under_way`` stands for its engine's activation: a future the test resolves when the
activation's write has "committed". Until then the robot it gives back must not be
anyone else's, in Postgres (the lock) or in the other replica's view (``owns``).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable, Iterable

import asyncpg
import pytest

import common.lease.cycle as cycle
from common.config import LeaseSettings
from common.lease import REBALANCE, LeaseManager, history_overlaps, lease_key, ownership
from pnav._testing import eventually

SERVICE = "decision"
ROBOTS = ["r1", "r2"]
FAST = LeaseSettings(period_s=0.1, timeout_s=2.0)


async def add_robots(conn: asyncpg.Connection, robots: Iterable[str]) -> None:
    await conn.executemany("INSERT INTO robot (robot_id) VALUES ($1)", [(r,) for r in robots])


async def cycles(manager: LeaseManager, n: int) -> None:
    start = manager.counters.cycles
    await eventually(
        lambda: manager.counters.cycles >= start + n, within=10, what=f"{n} more lease cycles"
    )


@contextlib.asynccontextmanager
async def replicas(
    db_url: str, under_way: Callable[[], asyncio.Future[None] | None]
) -> AsyncIterator[tuple[LeaseManager, LeaseManager]]:
    """Replica a (its work under way given by ``under_way``) alone with every robot, then b
    joining; both stopped (b first) on the way out."""
    a = LeaseManager(db_url, SERVICE, "a", FAST, under_way=under_way)
    b = LeaseManager(db_url, SERVICE, "b", FAST)
    await a.start()
    try:
        await b.start()
        try:
            yield a, b
        finally:
            await b.stop()
    finally:
        await a.stop()


async def test_a_robot_given_back_stays_locked_until_the_activation_under_way_ends(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS)
    loop = asyncio.get_running_loop()
    activation: asyncio.Future[None] = loop.create_future()  # a write in flight, for ever
    lost: list[frozenset[str]] = []
    a = LeaseManager(
        db_url,
        SERVICE,
        "a",
        FAST,
        under_way=lambda: activation,
        on_change=lambda _gained, gone: lost.append(gone) if gone else None,
    )
    b = LeaseManager(db_url, SERVICE, "b", FAST)
    await a.start()
    try:
        assert a.owned == frozenset(ROBOTS)
        await b.start()
        # a gives one robot back: it stops acting for it at once (reported lost) ...
        await eventually(lambda: len(a.owned) == 1, within=10, what="a gives a robot back")
        (given,) = set(ROBOTS) - a.owned
        assert lost == [frozenset({given})]
        assert a.handing_over == frozenset({given})
        # ... but keeps its lock while the activation may still be writing for it
        await cycles(b, 5)
        await cycles(a, 3)
        assert not b.owns(given) and b.owned == frozenset()
        assert await ownership(conn, SERVICE) == dict.fromkeys(ROBOTS, "a")
        assert a.handing_over == frozenset({given})  # b's fair-share view did not take it
        # the activation ends: the lock is released at a's next cycle, and b takes it
        activation.set_result(None)
        await eventually(lambda: b.owns(given), within=10, what="b takes the robot")
        assert a.handing_over == frozenset() and not a.owns(given)
        assert a.counters.handovers_waited == 1 and a.counters.handovers_expired == 0
        reasons = await conn.fetch(
            "SELECT reason FROM robot_lease WHERE robot_id = $1 AND instance = 'a'", given
        )
        assert [r["reason"] for r in reasons] == [REBALANCE]
    finally:
        await b.stop()
        await a.stop()
    assert await history_overlaps(conn, SERVICE) == []


async def test_with_no_activation_under_way_a_robot_is_given_back_in_the_same_cycle(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS)
    async with replicas(db_url, lambda: None) as (a, b):
        await eventually(lambda: len(a.owned) == len(b.owned) == 1, within=10, what="1/1")
        assert a.counters.handovers_waited == 0


async def test_a_stuck_activation_does_not_keep_the_robot_for_ever(
    conn: asyncpg.Connection, db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(cycle, "HANDOVER_LIMIT_S", 0.5)
    await add_robots(conn, ROBOTS)
    stuck: asyncio.Future[None] = asyncio.get_running_loop().create_future()
    async with replicas(db_url, lambda: stuck) as (a, b):
        await eventually(lambda: len(b.owned) == 1, within=10, what="b gets its share anyway")
        assert a.counters.handovers_expired == 1 and a.handing_over == frozenset()
        assert not stuck.done()
    assert await history_overlaps(conn, SERVICE) == []


async def test_a_clean_stop_during_a_hand_over_releases_the_robot(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS)
    pending: asyncio.Future[None] = asyncio.get_running_loop().create_future()
    async with replicas(db_url, lambda: pending) as (a, b):
        await eventually(lambda: a.handing_over, within=10, what="a hand-over under way")
        await a.stop()  # its engine has drained (a service stops leases after it)
        await eventually(lambda: len(b.owned) == 2, within=10, what="b owns both")
    assert await ownership(conn, SERVICE) == dict.fromkeys(ROBOTS)
    assert await history_overlaps(conn, SERVICE) == []


async def test_a_robot_removed_during_its_hand_over_is_still_released_when_the_work_ends(
    conn: asyncpg.Connection, db_url: str, caplog: pytest.LogCaptureFixture
) -> None:
    await add_robots(conn, ROBOTS)
    pending: asyncio.Future[None] = asyncio.get_running_loop().create_future()
    async with replicas(db_url, lambda: pending) as (a, _b):
        await eventually(lambda: a.handing_over, within=10, what="a hand-over under way")
        (given,) = a.handing_over
        await conn.execute("DELETE FROM robot WHERE robot_id = $1", given)
        await cycles(a, 3)
        assert a.handing_over == frozenset({given})  # still ours until the work ends
        pending.set_result(None)
        await eventually(lambda: not a.handing_over, within=10, what="the lock released")
        held = await conn.fetchval(
            "SELECT count(*) FROM pg_locks WHERE locktype = 'advisory' AND objsubid = 2 "
            "AND objid = $1::bigint::oid AND pid = $2",
            lease_key(given),
            a.backend_pid,
        )
        assert held == 0
        assert "lock not held any more" not in caplog.text
