"""Robot leases when a lock session ends under a replica that does not notice at once.

Postgres ends a session (``pg_terminate_backend``, ``idle_session_timeout``, a restart) and
frees its locks at that instant, but the replica may learn of it late: the FATAL reaches an
idle asyncpg connection, which then only fails its next query while its socket stays open
(tests/unit/pgproxy.py makes that happen every time). Two rules keep one owner per robot:
the replica drops every robot as soon as a query on its lock connection fails, and a replica
that takes over a robot from a holder that vanished does not act for it before that holder
can have stopped trusting its own view (80 % of the idle timeout).
"""

from __future__ import annotations

import time

import asyncpg

from common.config import LeaseSettings
from common.lease import LeaseManager, history_overlaps
from common.outage import outage_for
from pnav._testing import eventually
from tests.unit.pgproxy import PgProxy
from tests.unit.test_lease import ROBOTS, SERVICE, Watch, add_robots

SETTINGS = LeaseSettings(period_s=0.2, timeout_s=4.0)
# How long a replica trusts its last confirmed cycle; a takeover from a vanished holder
# waits this long.
VALID_S = 0.8 * SETTINGS.timeout_s


def counts(running: dict[str, LeaseManager]) -> list[int]:
    return sorted(len(m.owned) for m in running.values())


async def test_a_replica_drops_its_robots_at_once_when_its_session_ends_while_it_is_idle(
    conn: asyncpg.Connection, db_url: str
) -> None:
    """a cycles every second, b ten times a second: b sees a's robots free long before a's
    next query can tell a its session is gone."""
    await add_robots(conn, ROBOTS[:4])
    slow = LeaseSettings(period_s=1.0, timeout_s=SETTINGS.timeout_s)
    quick = LeaseSettings(period_s=0.1, timeout_s=SETTINGS.timeout_s)
    async with PgProxy(db_url, hold_after_fatal_s=VALID_S + 2) as proxy:
        a = LeaseManager(proxy.url(), SERVICE, "a", slow)
        b = LeaseManager(db_url, SERVICE, "b", quick)
        running = {"a": a, "b": b}
        await a.start()
        await b.start()
        try:
            await eventually(lambda: counts(running) == [2, 2], within=15, what="a 2/2 split")
            with Watch(running) as watch:
                # end a's session just after one of its cycles: its next query is a period away
                mine = a.owned
                cycles = a.counters.cycles
                await eventually(lambda: a.counters.cycles > cycles, within=3, interval=0.005)
                ended = time.monotonic()
                await conn.execute("SELECT pg_terminate_backend($1)", a.backend_pid)
                await eventually(lambda: proxy.fatals == 1, within=2, what="a FATAL went to a")
                # a's socket stays open, so a learns of it from its next query, which fails
                # (asyncpg: "cannot switch to state ..."): from then on it owns nothing
                await eventually(lambda: not a.owned, within=3, interval=0.01, what="a drops")
                dropped_s = time.monotonic() - ended
                assert proxy.holding == 1  # the stream had not ended: the failed query told a
                print(f"a dropped its robots {dropped_s:.2f} s after its session ended")
                assert dropped_s < 1.5 * slow.period_s
                # b takes a's robots at once (a reconnects a period later) but acts for them
                # only once a can have stopped trusting its last confirmed cycle
                await eventually(
                    lambda: all(b.owns(r) or a.owns(r) for r in mine),
                    within=VALID_S + 5,
                    interval=0.01,
                    what="a's robots acted for again",
                )
                took_s = time.monotonic() - ended
                print(f"a's robots acted for again {took_s:.2f} s after a's session ended")
                assert took_s >= VALID_S
            assert watch.problems == []
            # a reconnects and gets its share back
            await eventually(lambda: counts(running) == [2, 2], within=30, what="a is back")
            assert a.counters.lost == 2 and a.counters.reconnects >= 1
        finally:
            await a.stop()
            await b.stop()
    assert await history_overlaps(conn, SERVICE) == []


async def test_a_clean_handover_is_acted_on_without_the_takeover_wait(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS[:4])
    a = LeaseManager(db_url, SERVICE, "a", SETTINGS)
    b = LeaseManager(db_url, SERVICE, "b", SETTINGS)
    await a.start()
    await b.start()
    try:
        await eventually(lambda: counts({"a": a, "b": b}) == [2, 2], within=15, what="2/2")
        stopped = time.monotonic()
        await b.stop()  # gives its robots back with reason "shutdown"
        a.poke()
        await eventually(lambda: len(a.owned) == 4, within=VALID_S / 2, what="a takes all")
        print(f"handed over in {time.monotonic() - stopped:.2f} s")
    finally:
        await a.stop()
        await b.stop()


async def test_a_robot_handed_on_during_a_takeover_wait_still_waits_for_the_vanished_holder(
    conn: asyncpg.Connection, db_url: str
) -> None:
    """b takes over a vanished holder's robots and shuts down cleanly before acting for them;
    c, taking them from b's clean release, still waits out the vanished holder."""
    await add_robots(conn, ROBOTS[:2])
    a = LeaseManager(db_url, SERVICE, "a", SETTINGS)
    b = LeaseManager(db_url, SERVICE, "b", SETTINGS)
    c = LeaseManager(db_url, SERVICE, "c", SETTINGS)
    await a.start()
    try:
        assert len(a.owned) == 2
        assert a._task is not None
        a._task.cancel()  # a's process is gone: it will not reconnect
        ended = time.monotonic()
        # with a timeout, pg_terminate_backend returns once the backend has exited and its
        # locks are free; without, b's first cycle could still find them held by a
        assert await conn.fetchval("SELECT pg_terminate_backend($1, 10000)", a.backend_pid)
        await b.start()
        assert b.owned == frozenset()  # its locks are taken, its wait is running
        assert await conn.fetchval(
            "SELECT count(*) FROM robot_lease WHERE instance = 'b' AND released_at IS NULL"
        )
        await b.stop()
        await c.start()
        assert c.owned == frozenset()
        await eventually(lambda: len(c.owned) == 2, within=VALID_S + 5, what="c acts")
        assert time.monotonic() - ended >= VALID_S
    finally:
        for manager in (a, b, c):
            await manager.stop()


async def test_a_lease_session_that_connects_ends_the_outage_its_pools_back_off_from(
    conn: asyncpg.Connection, db_url: str
) -> None:
    # Postgres restarted: the pools of the process still back off (their next probe up to
    # 2 s away) when the lease connection gets through; the robots it takes start scenarios
    # that query at once, so the pools must try again at once too
    outage = outage_for(db_url)
    outage.failed(ConnectionRefusedError(111, "refused"))
    assert outage.down and not outage.may_try()  # the probe just let through was spent
    a = LeaseManager(db_url, SERVICE, "a", SETTINGS)
    await a.start()
    try:
        await eventually(lambda: not outage.down, within=10, what="the outage over")
        assert outage.may_try()
    finally:
        await a.stop()
        outage.recovered()
