"""Robot leases against a real Postgres: split, takeover, newcomers, expiry, history.

Several :class:`~common.lease.LeaseManager` of one service (different instances) run in this
process, each with its own lock connection, as replicas in separate processes would. A
replica's death is its backend being ended by Postgres (``pg_terminate_backend``), or its
going silent until ``idle_session_timeout`` ends it.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Iterable

import asyncpg
import pytest

from common.config import LeaseSettings
from common.lease import LeaseManager, history_overlaps, live_replicas, ownership
from pnav._testing import eventually

SERVICE = "controller"
ROBOTS = [f"r{i}" for i in range(1, 7)]
FAST = LeaseSettings(period_s=0.2, timeout_s=2.0)


async def add_robots(conn: asyncpg.Connection, robots: Iterable[str]) -> None:
    await conn.executemany("INSERT INTO robot (robot_id) VALUES ($1)", [(r,) for r in robots])


class Watch:
    """Samples the managers' own views every 20 ms: no robot may ever be owned twice."""

    def __init__(self, managers: dict[str, LeaseManager]) -> None:
        self.managers = managers
        self.problems: list[str] = []
        self._task: asyncio.Task[None] | None = None

    def check(self) -> None:
        seen: dict[str, str] = {}
        for name, manager in list(self.managers.items()):
            for robot in manager.owned:
                if robot in seen:
                    self.problems.append(f"{robot} owned by {seen[robot]} and {name}")
                seen[robot] = name

    async def _run(self) -> None:
        while True:
            self.check()
            await asyncio.sleep(0.02)

    def __enter__(self) -> Watch:
        self._task = asyncio.get_running_loop().create_task(self._run())
        return self

    def __exit__(self, *exc: object) -> None:
        if self._task is not None:
            self._task.cancel()


@contextlib.asynccontextmanager
async def managers(db_url: str, *names: str) -> AsyncIterator[dict[str, LeaseManager]]:
    running: dict[str, LeaseManager] = {}
    try:
        for name in names:
            running[name] = LeaseManager(db_url, SERVICE, name, FAST)
            await running[name].start()
        yield running
    finally:
        for manager in running.values():
            await manager.stop()


def counts(running: dict[str, LeaseManager]) -> dict[str, int]:
    return {name: len(m.owned) for name, m in running.items()}


def split_exactly(running: dict[str, LeaseManager], robots: list[str]) -> bool:
    owned = [r for m in running.values() for r in m.owned]
    return sorted(owned) == sorted(robots)


async def test_a_lone_replica_owns_every_robot_when_start_returns(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS[:3])
    async with managers(db_url, "a") as running:
        a = running["a"]
        assert a.owned == frozenset(ROBOTS[:3])  # no wait: taken before start() returned
        assert all(a.owns(r) for r in ROBOTS[:3]) and not a.owns("r9")
        assert a.replicas == 1
        assert await ownership(conn, SERVICE) == dict.fromkeys(ROBOTS[:3], "a")
        assert await live_replicas(conn, SERVICE) == 1
        # a robot registered later is taken on the next cycle (or at once when poked)
        await add_robots(conn, ["r4"])
        a.poke()
        await eventually(lambda: a.owns("r4"), within=5, what="r4 leased")
    # a clean stop gives everything back and closes the history
    assert await ownership(conn, SERVICE) == dict.fromkeys(ROBOTS[:4])
    assert await live_replicas(conn, SERVICE) == 0
    rows = await conn.fetch("SELECT robot_id, instance, released_at, reason FROM robot_lease")
    assert len(rows) == 4
    assert all(r["instance"] == "a" and r["reason"] == "shutdown" for r in rows)
    assert all(r["released_at"] is not None for r in rows)
    held = await conn.fetchval("SELECT count(*) FROM pg_locks WHERE locktype = 'advisory'")
    assert held == 0


async def test_every_robot_is_reported_gained_before_another_task_sees_it_owned(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS)
    reported: set[str] = set()
    seen_early: list[str] = []  # owned, as another task saw it, before the service was told

    def on_change(gained: frozenset[str], lost: frozenset[str]) -> None:
        reported.update(gained)
        reported.difference_update(lost)

    a = LeaseManager(db_url, SERVICE, "a", FAST, on_change=on_change)

    async def look_at_every_await() -> None:
        # an engine's activation runs whenever the lease cycle awaits (each robot's lock)
        while True:
            seen_early.extend(r for r in a.owned if r not in reported)
            await asyncio.sleep(0)

    looking = asyncio.create_task(look_at_every_await())
    try:
        await a.start()  # takes all six robots, one lock after another
        assert a.owned == frozenset(ROBOTS) and reported == set(ROBOTS)
    finally:
        looking.cancel()
        await a.stop()
    assert seen_early == []


async def test_three_replicas_split_six_robots_and_take_over_when_one_dies(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS)
    async with managers(db_url, "a", "b", "c") as running:
        with Watch(running) as watch:
            await eventually(
                lambda: (
                    split_exactly(running, ROBOTS) and sorted(counts(running).values()) == [2, 2, 2]
                ),
                within=15,
                what="a 2/2/2 split",
            )
            # Postgres agrees: it is the only judge
            assert await ownership(conn, SERVICE) == {
                r: name for name, m in running.items() for r in m.owned
            }
            assert await live_replicas(conn, SERVICE) == 3

            # b dies (its process would be gone: no reconnect), and Postgres ends its backend
            b = running["b"]
            assert b._task is not None
            b._task.cancel()
            started = time.monotonic()
            await conn.execute("SELECT pg_terminate_backend($1)", b.backend_pid)
            await eventually(lambda: not b.owned, within=2, what="b drops its robots at once")
            survivors = {"a": running["a"], "c": running["c"]}
            await eventually(
                lambda: split_exactly(survivors, ROBOTS), within=5, what="a and c own all six"
            )
            takeover_s = time.monotonic() - started
            print(f"takeover in {takeover_s:.2f} s")
            assert takeover_s < 5.0
            assert sorted(counts(survivors).values()) == [3, 3]

            # b comes back (restarted, same instance id) and gets its share back
            await b.stop()
            running["b"] = LeaseManager(db_url, SERVICE, "b", FAST)
            await running["b"].start()
            await eventually(
                lambda: (
                    split_exactly(running, ROBOTS) and sorted(counts(running).values()) == [2, 2, 2]
                ),
                within=15,
                what="b back with a share",
            )

            # a loses its lock connection but lives on: it stops acting for every robot at
            # once, reconnects, and is a replica with a share again
            a = running["a"]
            await conn.execute("SELECT pg_terminate_backend($1)", a.backend_pid)
            await eventually(lambda: a.counters.reconnects >= 1, within=5, what="a reconnects")
            assert a.counters.lost == 2
            await eventually(
                lambda: (
                    split_exactly(running, ROBOTS) and sorted(counts(running).values()) == [2, 2, 2]
                ),
                within=15,
                what="a back with a share",
            )

            # a newcomer joining a full fleet gets a share too
            d = LeaseManager(db_url, SERVICE, "d", FAST)
            await d.start()
            running["d"] = d
            await eventually(
                lambda: (
                    split_exactly(running, ROBOTS)
                    and sorted(counts(running).values()) == [1, 1, 2, 2]
                ),
                within=15,
                what="the newcomer gets a share",
            )
            assert await live_replicas(conn, SERVICE) == 4
        assert watch.problems == []
    assert await history_overlaps(conn, SERVICE) == []
    reasons = {r["reason"] for r in await conn.fetch("SELECT reason FROM robot_lease")}
    assert {"rebalance", "shutdown"} <= reasons
    assert reasons & {"holder gone", "connection lost"}  # b's rows, closed for it


async def test_a_silent_replica_loses_its_robots_to_the_idle_timeout(
    conn: asyncpg.Connection, db_url: str
) -> None:
    """A hung replica (alive, connected, saying nothing) must not keep its robots: Postgres
    ends its session after PNAV_LEASE_TIMEOUT_S, and it stops trusting its locks before."""
    await add_robots(conn, ROBOTS[:4])
    short = LeaseSettings(period_s=0.1, timeout_s=1.0)
    a = LeaseManager(db_url, SERVICE, "a", short)
    b = LeaseManager(db_url, SERVICE, "b", short)
    await a.start()
    await b.start()
    try:
        await eventually(lambda: len(a.owned) == len(b.owned) == 2, within=10, what="2/2")
        assert b._task is not None
        b._task.cancel()  # b hangs: no more cycles, its connection idles
        hung = time.monotonic()
        await eventually(lambda: len(a.owned) == 4, within=6, what="a takes b's robots")
        took = time.monotonic() - hung
        assert took > 0.5  # not before Postgres ended b's session (timeout 1 s)
        assert not b.owned  # b stopped trusting its locks (and lost its connection)
    finally:
        await a.stop()
        await b.stop()
    assert await history_overlaps(conn, SERVICE) == []


async def test_replicas_of_different_services_do_not_compete(
    conn: asyncpg.Connection, db_url: str
) -> None:
    await add_robots(conn, ROBOTS[:2])
    planner = LeaseManager(db_url, "planner", "p", FAST)
    controller = LeaseManager(db_url, "controller", "c", FAST)
    await planner.start()
    await controller.start()
    try:
        assert planner.owned == controller.owned == frozenset(ROBOTS[:2])
    finally:
        await planner.stop()
        await controller.stop()


async def test_the_sql_lease_key_is_the_python_one(conn: asyncpg.Connection) -> None:
    from common.lease import lease_key

    names = ["controller", "planner", "r1", "robot_7-b", "é-ü", "x" * 300]
    names += [f"n{i}" for i in range(200)]  # some with the top bit of the 32 set
    got = await conn.fetch("SELECT n, lease_key(n) AS k FROM unnest($1::text[]) AS n", names)
    assert {r["n"]: r["k"] for r in got} == {n: lease_key(n) for n in names}


async def test_a_database_without_the_lease_migration_is_named(empty_db_url: str) -> None:
    from common.errors import ConnectionFailure

    manager = LeaseManager(empty_db_url, SERVICE, "a", FAST)
    with pytest.raises(ConnectionFailure, match="migration 2"):
        await manager.start()
