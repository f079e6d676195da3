"""Robot leases no other role can take or block (CONTRACT.md, *Robot leases*; migration 10).

The database is set up as ``pnav up`` sets it up (common.contract.roles.bootstrap); a
controller replica runs as ``pnav_controller`` and owns the robots. Then ``pnav_user`` (the
people's role) tries every lock and lease call it can, and a service role of another family
holds the controller's membership lock: the replica's ownership does not move, its cycles
keep running, and nobody is counted as a replica but it.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from importlib import resources

import asyncpg
import pytest

from common.config import LeaseSettings
from common.contract.grants import lease_holders, parse_grants, role_name
from common.contract.roles import role_url
from common.lease import LeaseManager, lease_key, live_replicas, ownership
from pnav._testing import as_service_role, eventually
from pnav.bench.faults import theft

SERVICE = "controller"
ROBOTS = ["r1", "r2"]
FAST = LeaseSettings(period_s=0.2, timeout_s=2.0)


@pytest.fixture
async def controller_url(db_url: str, conn: asyncpg.Connection) -> str:
    await conn.executemany("INSERT INTO robot (robot_id) VALUES ($1)", [(r,) for r in ROBOTS])
    return await as_service_role(db_url, SERVICE)


@contextlib.asynccontextmanager
async def replica(url: str) -> AsyncIterator[LeaseManager]:
    manager = LeaseManager(url, SERVICE, "a", FAST)
    await manager.start()
    try:
        yield manager
    finally:
        await manager.stop()


async def _cycles_pass(manager: LeaseManager, n: int) -> None:
    """Wait for ``n`` more cycles of ``manager`` (more than the two a give-back settles in)."""
    target = manager.counters.cycles + n
    await eventually(lambda: manager.counters.cycles >= target, within=30, what=f"{n} cycles")


async def test_the_peoples_role_can_neither_take_nor_block_a_robot_lease(
    db_url: str, conn: asyncpg.Connection, controller_url: str
) -> None:
    thief = await asyncpg.connect(role_url(db_url, role_name("user"), None))
    try:
        await thief.execute("SET lock_timeout = '1s'")  # a lock granted must not hang us
        async with replica(controller_url) as a:
            assert a.owned == frozenset(ROBOTS)
            assert a.backend_pid is not None
            services = [SERVICE, "planner"]
            attempts = theft.lock_attempts(services, [*ROBOTS, "r9"])
            attempts += theft.table_attempts(services, ROBOTS, [a.backend_pid])
            tally = await theft.attempt(thief, attempts)
            assert tally.passed == [] and tally.refused == len(attempts)
            # what is left to people: reading, and ACCESS SHARE locks on what they read,
            # held across many cycles
            async with thief.transaction():
                await thief.execute("LOCK TABLE robot_lease, robot IN ACCESS SHARE MODE")
                await thief.fetch("SELECT * FROM robot_lease")
                await _cycles_pass(a, 8)
                assert await ownership(thief, SERVICE) == dict.fromkeys(ROBOTS, "a")
            await _cycles_pass(a, 4)
            assert a.owned == frozenset(ROBOTS) and a.replicas == 1
            assert a.counters.released == 0 and a.counters.lost == 0
            assert await live_replicas(thief, SERVICE) == 1
        rows = await conn.fetch("SELECT robot_id, instance, reason FROM robot_lease ORDER BY id")
        assert sorted(r["robot_id"] for r in rows) == ROBOTS  # one tenure each, never moved
        assert {(r["instance"], r["reason"]) for r in rows} == {("a", "shutdown")}
    finally:
        await thief.close()


async def test_a_lock_held_by_a_role_that_may_not_hold_the_lease_is_ignored(
    db_url: str, conn: asyncpg.Connection, controller_url: str
) -> None:
    # the planner may take advisory locks (its own leases) and read the controller's keys
    planner = await asyncpg.connect(role_url(db_url, role_name("planner"), None))
    try:
        ks = lease_key(SERVICE)
        async with replica(controller_url) as a:
            # counted, it would be a second replica: fair share 1, and `a` would give one back
            assert await planner.fetchval("SELECT pg_try_advisory_lock_shared($1, 0)", ks)
            # a robot registered while the planner holds its lock: not the planner's either
            assert await planner.fetchval(
                "SELECT pg_try_advisory_lock($1, $2)", ks, lease_key("r3")
            )
            await conn.execute("INSERT INTO robot (robot_id) VALUES ('r3')")
            await _cycles_pass(a, 8)
            assert a.replicas == 1 and a.counters.released == 0
            assert a.owned == frozenset(ROBOTS)
            assert await live_replicas(conn, SERVICE) == 1
            assert await ownership(conn, SERVICE) == {"r1": "a", "r2": "a", "r3": None}
            # once it lets go, the robot is taken as any free one
            await planner.execute("SELECT pg_advisory_unlock_all()")
            await eventually(lambda: a.owns("r3"), within=10, what="r3 leased")
            assert a.replicas == 1
    finally:
        await planner.close()


async def test_advisory_locks_are_granted_to_the_contracts_lease_holders_only(
    conn: asyncpg.Connection, controller_url: str
) -> None:
    rows = await conn.fetch(
        r"""
        SELECT p.oid::regprocedure::text AS fn, array_agg(r.rolname::text ORDER BY r.rolname)
               FILTER (WHERE has_function_privilege(r.oid, p.oid, 'EXECUTE')) AS may,
               has_function_privilege('public', p.oid, 'EXECUTE') AS public
          FROM pg_proc p, pg_roles r
         WHERE p.pronamespace = 'pg_catalog'::regnamespace AND r.rolname LIKE 'pnav\_%'
           AND p.proname ~ '^pg_(try_)?advisory_(xact_)?lock(_shared)?$'
         GROUP BY p.oid
        """
    )
    assert len(rows) == 16  # 8 functions, each with a bigint and an (int, int) key
    holders = sorted(
        role_name(r) for r in ("owner", "controller", "decision", "planner", "strategy")
    )
    for row in rows:
        assert row["may"] == holders and not row["public"], row["fn"]
    # giving back stays open to all: it frees only the caller's own locks (and pools call it)
    user = await asyncpg.connect(role_url(controller_url, role_name("user"), None))
    try:
        assert await user.fetchval("SELECT pg_advisory_unlock_all()") is None
    finally:
        await user.close()


def test_the_lease_holders_are_the_roles_the_contract_lets_write_robot_lease() -> None:
    assert lease_holders() == ("controller", "decision", "planner", "strategy")
    text = resources.files("common.contract").joinpath("CONTRACT.md").read_text()
    extra = "| robot_lease | controller | INSERT, UPDATE (released_at, reason) |\n"
    text = text.replace(extra, extra + "| robot_lease | bridge | INSERT |\n")
    assert lease_holders(parse_grants(text)) == (
        "bridge",
        "controller",
        "decision",
        "planner",
        "strategy",
    )
