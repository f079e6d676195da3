"""A mission followed from the tables ends when its goal fails or is cancelled, with the
goal's reason, instead of waiting out its time limit (pnav/run/mission.py)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

import asyncpg
import pytest

from pnav.run.mission import GoalEnded, MissionMonitor


@pytest.fixture
async def pool(db_url: str) -> AsyncIterator[asyncpg.Pool]:
    async with asyncpg.create_pool(db_url, min_size=1, max_size=2) as p:
        await p.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
        yield p


async def goal(pool: asyncpg.Pool) -> int:
    goal_id: int = await pool.fetchval(
        "INSERT INTO goal (robot_id, x, y, status) VALUES ('r1', 50, 50, 'active') RETURNING id"
    )
    return goal_id


@pytest.mark.parametrize(
    ("status", "reason"),
    [
        ("failed", "goal (50.00, 50.00) is outside the map (the map spans ...)"),
        ("cancelled", "cancelled by the operator"),
    ],
)
async def test_a_goal_that_ends_unreached_ends_the_wait_with_its_reason(
    pool: asyncpg.Pool, status: str, reason: str
) -> None:
    goal_id = await goal(pool)
    monitor = MissionMonitor(pool, "r1")

    async def end_it() -> None:
        await asyncio.sleep(0.3)  # the monitor is polling by then
        await pool.execute(
            "UPDATE goal SET status = $2, reason = $3 WHERE id = $1", goal_id, status, reason
        )

    started = time.monotonic()
    ender = asyncio.create_task(end_it())
    with pytest.raises(GoalEnded) as ended:
        await monitor.wait_for(lambda log: log.goals.get(goal_id) == "reached", 60, goal=goal_id)
    await ender
    assert time.monotonic() - started < 30  # not the 60 s limit
    assert (ended.value.goal_id, ended.value.status, ended.value.reason) == (
        goal_id,
        status,
        reason,
    )
    assert str(ended.value) == f"goal {goal_id} {status}: {reason}"


async def test_a_superseded_goal_is_not_an_end_and_without_goal_nothing_is_raised(
    pool: asyncpg.Pool,
) -> None:
    first = await goal(pool)
    await pool.execute("UPDATE goal SET status = 'superseded' WHERE id = $1", first)
    monitor = MissionMonitor(pool, "r1")
    assert not await monitor.wait_for(lambda log: False, 0.3, goal=first)
    await pool.execute("UPDATE goal SET status = 'failed', reason = 'x' WHERE id = $1", first)
    assert not await monitor.wait_for(lambda log: False, 0.3)  # not following any goal
    assert monitor.log.ended(first) is not None
