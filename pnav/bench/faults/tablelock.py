"""Locks as people: ``pnav_user`` holds what its UPDATE grants let it hold.

A role that may UPDATE a table may also LOCK it, and one that may UPDATE some of its columns
may hold its rows (CONTRACT.md, *Roles*): the people's role may lock strategy (ACCESS
EXCLUSIVE blocks every read of it) and hold the rows of goal and retention_policy (``SELECT
... FOR UPDATE`` blocks their UPDATEs, and the INSERTs whose foreign key cites them: a
planned_path citing its goal). The
services bound their lock waits (``lock_timeout``, common.db.lock_settings) and the controller
serves the strategies it read before (services/controller/store.py), so a robot's safety_stop
never waits behind such a lock for more than one timeout. :func:`held` is the lock, for
``pnav bench faults`` (fault ``table-lock``, mid-mission) and tests/contract/test_people_locks.py.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Iterable
from typing import TYPE_CHECKING, Any

import asyncpg

from common.contract import keys
from common.contract.grants import USER
from pnav.bench.faults.context import Context, Injection

if TYPE_CHECKING:
    from pnav.bench.faults.catalogue import Fault

# the people-written tables the services read on their way to a command: locked whole, and
# whose every row is held
LOCKED = (keys.STRATEGY,)
HELD_ROWS = (keys.GOAL,)

_SAFETY_RUNS = f"""
SELECT coalesce(sum(executed), 0) FROM {keys.ENGINE_STATS}
 WHERE service = 'controller' AND rule_type = 'SafetyStop'"""


@contextlib.asynccontextmanager
async def held(
    user_url: str, tables: Iterable[str] = LOCKED, rows: Iterable[str] = HELD_ROWS
) -> AsyncIterator[asyncpg.Connection]:
    """A session of ``user_url`` (the people's role) holding ``tables`` in ACCESS EXCLUSIVE
    mode and every row of ``rows`` FOR UPDATE, in a transaction left open until the block
    ends (closing the session ends it)."""
    conn = await asyncpg.connect(user_url)
    try:
        # the role's bound on a transaction left idle (5 s) would end a longer hold: a
        # session of the role may lift it, as a hostile person would
        await conn.execute("SET idle_in_transaction_session_timeout = 0")
        await conn.execute("BEGIN")
        for table in tables:
            await conn.execute(f"LOCK TABLE {table} IN ACCESS EXCLUSIVE MODE")
        for table in rows:
            await conn.execute(f"SELECT 1 FROM {table} FOR UPDATE")
        yield conn
    finally:
        await conn.close()


async def inject(fault: Fault, ctx: Context) -> Injection:
    """Hold :data:`LOCKED` for ``fault.seconds`` as people mid-mission; a breach if the
    controller's safety_stop ran not once meanwhile (its engine_stats, every 2 s)."""
    pool: Any = ctx.rt.database.pool
    before = int(await pool.fetchval(_SAFETY_RUNS))
    async with held(ctx.stack.local.url_for(USER)):
        await asyncio.sleep(fault.seconds)
        ran = int(await pool.fetchval(_SAFETY_RUNS)) - before
    out = Injection(
        notes=[
            f"{', '.join(LOCKED)} locked and {', '.join(HELD_ROWS)}'s rows held for "
            f"{fault.seconds:.0f} s; "
            f"safety_stop ran {ran} times meanwhile"
        ]
    )
    if ran <= 0:
        out.breaches.append("safety_stop did not run while people held the tables")
    return out
