"""The foreign-client example's leases (examples/sql_controller/leases.py) beside a shipped
replica, when the example's lock session ends while it is idle and it learns of it late
(tests/unit/pgproxy.py keeps its socket open after the FATAL)."""

from __future__ import annotations

import asyncio
import contextlib
import time

import asyncpg

from common.config import LeaseSettings
from common.lease import LeaseManager, history_overlaps
from examples.sql_controller.environment import Settings
from examples.sql_controller.leases import Leases
from pnav._testing import eventually
from tests.unit.pgproxy import PgProxy
from tests.unit.test_lease import ROBOTS, SERVICE, add_robots

TIMEOUT_S = 4.0
VALID_S = 0.8 * TIMEOUT_S
PERIOD_S = 1.0


async def test_the_example_drops_its_robots_at_once_and_keeps_running_when_its_session_ends(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS[:4])
    overlaps: list[str] = []
    async with PgProxy(db_url, hold_after_fatal_s=VALID_S + 2) as proxy:
        settings = Settings(
            database_url=proxy.url(),
            instance="example",
            lease_period_s=PERIOD_S,
            lease_timeout_s=TIMEOUT_S,
        )
        example = Leases(settings, lambda robot, lease_id: None)
        shipped = LeaseManager(
            db_url, SERVICE, "shipped", LeaseSettings(period_s=0.1, timeout_s=TIMEOUT_S)
        )
        stop = asyncio.Event()
        await example.start()
        task = asyncio.create_task(example.run(stop))
        await shipped.start()

        async def watch() -> None:
            while True:
                overlaps.extend(example.owned() & shipped.owned)
                await asyncio.sleep(0.01)

        watcher = asyncio.create_task(watch())
        try:
            await eventually(
                lambda: len(example.owned()) == len(shipped.owned) == 2, within=15, what="2/2"
            )
            mine = example.owned()
            # end its session just after one of its cycles: its next query is a period away
            confirmed = example._confirmed
            await eventually(lambda: example._confirmed != confirmed, within=3, interval=0.005)
            ended = time.monotonic()
            await conn.execute(
                "SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                "WHERE application_name = 'pnav-lease controller/example'"
            )
            await eventually(lambda: proxy.fatals == 1, within=2, what="a FATAL went to it")
            await eventually(lambda: not example.owned(), within=3, interval=0.01, what="drop")
            dropped_s = time.monotonic() - ended
            print(f"the example dropped its robots {dropped_s:.2f} s after its session ended")
            assert proxy.holding == 1  # its socket was still open
            assert dropped_s < 1.5 * PERIOD_S
            await eventually(
                lambda: all(r in example.owned() or shipped.owns(r) for r in mine),
                within=VALID_S + 5,
                interval=0.01,
                what="its robots acted for again",
            )
            assert time.monotonic() - ended >= VALID_S
            assert not task.done()  # the lease task lives on, and gets a share back
            await eventually(
                lambda: len(example.owned()) == len(shipped.owned) == 2, within=30, what="2/2"
            )
        finally:
            watcher.cancel()
            stop.set()
            example.poke()
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.wait_for(task, 10)
            await example.stop()
            await shipped.stop()
    assert overlaps == []
    assert await history_overlaps(conn, SERVICE) == []
