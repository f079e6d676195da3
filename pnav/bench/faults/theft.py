"""Lease theft: everything the people's role can try against robot ownership.

One list of attempts, tried by ``pnav bench faults`` (fault ``lease-theft``, as
``pnav_user`` while the mission's robot drives) and by tests/contract/test_lease_theft.py:
every advisory-lock function on every key a client can read off the contract or guess, the
lease functions, writes and row or table locks on the lease tables, and ending or cancelling
the services' lock sessions. Each is refused with ``permission denied`` when the database was
set up with the roles (CONTRACT.md, *Robot leases*: who may take or block a lease).
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import asyncpg

from common.contract import keys
from common.contract.grants import lease_holders
from common.lease import lease_key, ownership

# common.contract.migrate's lock: blocking it would stall every `pnav up`
MIGRATIONS_KEY = 0x706E6176

LOCK_FUNCTIONS = tuple(
    f"pg_{try_}advisory_{xact}lock{shared}"
    for try_ in ("", "try_")
    for xact in ("", "xact_")
    for shared in ("", "_shared")
)
ROW_LOCKS = ("UPDATE", "NO KEY UPDATE", "SHARE", "KEY SHARE")
# every table lock mode but ACCESS SHARE, which reading grants (and which blocks only DDL)
TABLE_LOCKS = (
    "ROW SHARE",
    "ROW EXCLUSIVE",
    "SHARE UPDATE EXCLUSIVE",
    "SHARE",
    "SHARE ROW EXCLUSIVE",
    "EXCLUSIVE",
    "ACCESS EXCLUSIVE",
)


def lock_attempts(services: Iterable[str], robots: Iterable[str]) -> list[str]:
    """Every advisory-lock call on each service's membership key, each robot's key (as two
    keys and as one bigint), the migrations' key and an arbitrary one."""
    robots = list(robots)
    args: list[str] = [str(MIGRATIONS_KEY), "1"]
    for service in services:
        ks = lease_key(service)
        args.append(f"{ks}, {keys.LEASE_MEMBER_KEY}")
        args += [f"{ks}, {lease_key(r)}" for r in robots]
        args += [str((ks << 32) | lease_key(r)) for r in robots]
    return [f"SELECT {fn}({a})" for fn in LOCK_FUNCTIONS for a in args]


def table_attempts(
    services: Iterable[str], robots: Iterable[str], backend_pids: Iterable[int]
) -> list[str]:
    """The lease functions, writes and row or table locks on robot_lease and robot, and
    ending or cancelling the lock sessions ``backend_pids``."""
    lease, robot = keys.ROBOT_LEASE, keys.ROBOT
    out: list[str] = []
    for service in services:
        for r in robots:
            out += [
                f"SELECT {keys.LEASE_ACQUIRE_FN}('{service}', '{r}', 'thief')",
                f"SELECT {keys.LEASE_RELEASE_FN}('{service}', '{r}', 'rebalance')",
                f"INSERT INTO {lease} (service, robot_id, instance, backend_pid) "
                f"VALUES ('{service}', '{r}', 'thief', pg_backend_pid())",
            ]
    out += [
        f"UPDATE {lease} SET released_at = clock_timestamp(), reason = 'rebalance'",
        f"DELETE FROM {lease}",
        f"TRUNCATE {lease}",
        f"UPDATE {robot} SET robot_id = robot_id",
    ]
    for pid in backend_pids:
        out += [f"SELECT pg_terminate_backend({pid})", f"SELECT pg_cancel_backend({pid})"]
    for table in (lease, robot):
        out += [f"SELECT * FROM {table} FOR {s} NOWAIT" for s in ROW_LOCKS]
        out += [f"LOCK TABLE {table} IN {m} MODE NOWAIT" for m in TABLE_LOCKS]
    return out


# the backends of the lock sessions that hold the robot now (to try to end or cancel them)
_PIDS = f"""
SELECT array_agg(DISTINCT backend_pid) FROM {keys.ROBOT_LEASE}
 WHERE robot_id = $1 AND released_at IS NULL
"""


@dataclass
class Tally:
    refused: int = 0  # permission denied
    passed: list[str] = field(default_factory=list)  # got past the privilege check


async def attempt(conn: asyncpg.Connection, statements: Iterable[str]) -> Tally:
    """Try each statement on ``conn``, each in a transaction rolled back at once. A
    session-level advisory lock granted outlives the rollback (it is not transactional): the
    theft would then be real, and held until ``conn`` closes. ``conn`` should have a
    ``lock_timeout`` so that a blocking call granted cannot hang."""
    tally = Tally()
    for sql in statements:
        tx = conn.transaction()
        await tx.start()
        try:
            await conn.execute(sql)
            tally.passed.append(sql)
        except asyncpg.InsufficientPrivilegeError:
            tally.refused += 1
        except asyncpg.PostgresError as exc:
            tally.passed.append(f"{sql} ({type(exc).__name__})")  # not refused for privilege
        finally:
            await tx.rollback()
    return tally


@dataclass
class Theft:
    """What a theft achieved: ``moved`` lists every change of the robot's owner seen."""

    rounds: int = 0
    refused: int = 0
    passed: list[str] = field(default_factory=list)
    moved: list[str] = field(default_factory=list)

    def summary(self) -> str:
        return f"{self.rounds} rounds, {self.refused} lock and lease calls refused"

    def breaches(self) -> list[str]:
        """What the theft achieved: each call not refused (once), each owner change."""
        out = [f"not refused: {sql}" for sql in dict.fromkeys(self.passed)]
        return out + [f"owner moved: {m}" for m in self.moved]


async def _owners(conn: asyncpg.Connection, services: Iterable[str], robot: str) -> dict[str, Any]:
    """Service -> (owning instance, its open robot_lease row id) of ``robot``."""
    out: dict[str, Any] = {}
    for service in services:
        owner = (await ownership(conn, service)).get(robot)
        row = await conn.fetchval(
            f"SELECT max(id) FROM {keys.ROBOT_LEASE} "
            "WHERE service = $1 AND robot_id = $2 AND released_at IS NULL",
            service,
            robot,
        )
        out[service] = (owner, row)
    return out


async def steal(user_url: str, watch: asyncpg.Connection, robot: str, seconds: float) -> Theft:
    """For ``seconds``, as the people's role ``user_url`` names: hold ACCESS SHARE on the
    lease tables (all reading allows) and try every attempt against ``robot``'s leases in
    every lease-holding service, round after round; ``watch`` (any role that may read)
    checks after each round that the robot's owners and their tenures are those of the
    start."""
    services = lease_holders()
    result = Theft()
    thief = await asyncpg.connect(user_url)
    reader = await asyncpg.connect(user_url)
    try:
        await thief.execute("SET lock_timeout = '500ms'")
        before = await _owners(watch, services, robot)
        pids = [int(p) for p in await watch.fetchval(_PIDS, robot) or []]
        attempts = lock_attempts(services, [robot])
        attempts += table_attempts(services, [robot], pids)
        async with reader.transaction():
            await reader.execute(
                f"LOCK TABLE {keys.ROBOT_LEASE}, {keys.ROBOT} IN ACCESS SHARE MODE"
            )
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                # a statement each round: the server ends people's transactions left idle
                # for 5 s (idle_in_transaction_session_timeout), and a thief keeps it busy
                await reader.execute("SELECT 1")
                tally = await attempt(thief, attempts)
                result.rounds += 1
                result.refused += tally.refused
                result.passed += tally.passed
                now = await _owners(watch, services, robot)
                for service in services:
                    if now[service] != before[service]:
                        result.moved.append(f"{service}: {before[service]} -> {now[service]}")
                before = now
    finally:
        await reader.close()
        await thief.close()
    return result
