"""The lane (common/lane.py): one pooled connection held for back-to-back statements, given
back to the pool on any error, cancellation included. Real Postgres throughout."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import asyncpg
import pytest

from common.db import create_pool
from common.lane import Lane
from pnav._testing import eventually

PID = "SELECT pg_backend_pid()"


@pytest.fixture
async def pool(db_url: str) -> AsyncIterator[asyncpg.Pool]:
    pool = await create_pool(db_url, min_size=1, max_size=3)
    try:
        yield pool
    finally:
        pool.terminate()


async def test_back_to_back_statements_run_on_one_held_connection(pool: asyncpg.Pool) -> None:
    lane = Lane(pool)
    pids = {await lane.fetchval(PID) for _ in range(20)}
    assert len(pids) == 1
    assert (lane.checkouts, lane.overflows) == (1, 0)
    await lane.close()


async def test_a_statement_finding_the_lane_busy_takes_another_connection(
    pool: asyncpg.Pool,
) -> None:
    lane = Lane(pool)
    slow = "SELECT pg_backend_pid() FROM pg_sleep(0.3)"
    first, second = await asyncio.gather(lane.fetchval(slow), lane.fetchval(slow))
    assert first != second  # neither waited for the other
    assert lane.overflows == 1
    assert await lane.fetchval(PID) == first  # the lane's own connection, still held
    await lane.close()


async def test_a_statement_cancelled_halfway_gives_its_connection_back(
    pool: asyncpg.Pool,
) -> None:
    lane = Lane(pool)
    held = await lane.fetchval(PID)
    sleeping = asyncio.create_task(lane.fetchval("SELECT pg_sleep(30)"))
    await asyncio.sleep(0.2)
    sleeping.cancel()
    with pytest.raises(asyncio.CancelledError):
        await sleeping
    # the next statement runs at once on a connection in a clean state, not behind the
    # cancelled one, and the cancelled connection went back to the pool (none leaked)
    assert await asyncio.wait_for(lane.fetchval("SELECT 1"), 5) == 1
    assert lane.checkouts == 2
    await lane.close()
    await eventually(lambda: pool.get_idle_size() == pool.get_size(), within=5, what="all idle")
    assert held is not None


async def test_a_failed_statement_gives_its_connection_back_and_the_next_one_runs(
    pool: asyncpg.Pool,
) -> None:
    lane = Lane(pool)
    await lane.fetchval(PID)
    with pytest.raises(asyncpg.DivisionByZeroError):
        await lane.fetchval("SELECT 1 / 0")
    assert await lane.fetchval("SELECT 2") == 2
    assert lane.checkouts == 2
    await lane.close()


async def test_a_held_connection_the_server_closed_is_replaced(
    pool: asyncpg.Pool, conn: asyncpg.Connection
) -> None:
    lane = Lane(pool)
    pid = await lane.fetchval(PID)
    await conn.execute("SELECT pg_terminate_backend($1)", pid)
    # asyncpg sees the socket close on its own; a statement from then on must not fail
    await eventually(lambda: not lane.holding, within=5, what="the lane's connection closed")
    new_pid = await lane.fetchval(PID)
    assert new_pid != pid
    await lane.close()


async def test_closing_gives_the_connection_back_so_the_pool_can_close(
    pool: asyncpg.Pool,
) -> None:
    lane = Lane(pool)
    await lane.fetchval(PID)
    await lane.close()
    await asyncio.wait_for(pool.close(), 5)  # waits for every connection: none held


async def test_a_pool_of_one_connection_is_never_held(db_url: str) -> None:
    pool = await create_pool(db_url, min_size=1, max_size=1)
    try:
        lane = Lane(pool)
        assert await lane.fetchval("SELECT 1") == 1
        assert not lane.enabled
        assert pool.get_idle_size() == 1  # back in the pool for whoever else needs it
    finally:
        await pool.close()
