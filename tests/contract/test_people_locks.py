"""People's locks stall no service for long, and never a robot's safety_stop (CONTRACT.md,
*Roles*: "Locks").

The people's role ``pnav_user`` may UPDATE strategy, so it may LOCK it (ACCESS EXCLUSIVE
blocks every read), and columns of goal and retention_policy, so it may hold their rows
(``SELECT ... FOR UPDATE``), in a transaction it keeps open. The
services run with a ``lock_timeout`` (common.db.lock_settings): a statement blocked by such a
lock fails fast and its rule runs again at the next activation; the controller serves the
strategies it read before (tests/contract/controller/test_locked_strategies.py), the planner
runs on (tests/contract/planner/test_locked_goal.py). The server ends a people's transaction
left idle for 5 s.
"""

from __future__ import annotations

import asyncio

import asyncpg
import pytest

from common.contract import keys
from common.contract.grants import role_name
from common.contract.roles import PEOPLE_IDLE_IN_TRANSACTION, role_url
from pnav._testing import as_service_role


async def user_url(db_url: str) -> str:
    await as_service_role(db_url, "controller")  # sets the roles up, as `pnav up` does
    return role_url(db_url, role_name("user"), None)


async def test_the_peoples_role_may_lock_only_what_it_may_update(db_url: str) -> None:
    """A table-wide UPDATE grant lets it LOCK the table (strategy); a column grant only lets
    it hold rows (goal, retention_policy); the rest it may only read."""
    people = await asyncpg.connect(await user_url(db_url))
    table_lock = "LOCK TABLE {} IN ACCESS EXCLUSIVE MODE"
    row_lock = "SELECT * FROM {} FOR UPDATE"
    allowed = [table_lock.format(keys.STRATEGY)]
    allowed += [row_lock.format(t) for t in (keys.STRATEGY, keys.GOAL, keys.RETENTION_POLICY)]
    refused = [table_lock.format(t) for t in (keys.GOAL, keys.RETENTION_POLICY)]
    for table in (keys.ACTIVE_STRATEGY, keys.USER_COMMAND, keys.ROBOT, keys.LASER_SCAN):
        refused += [table_lock.format(table), row_lock.format(table)]
    try:
        await people.execute("SET lock_timeout = '1s'")
        for sql in allowed:
            async with people.transaction():
                await people.execute(sql)
        for sql in refused:
            with pytest.raises(asyncpg.InsufficientPrivilegeError):
                async with people.transaction():
                    await people.execute(sql)
    finally:
        await people.close()


async def test_a_peoples_transaction_left_idle_is_ended_by_the_server(db_url: str) -> None:
    people = await asyncpg.connect(await user_url(db_url))
    planner = await asyncpg.connect(await as_service_role(db_url, "planner"))
    try:
        shown = await people.fetchval("SHOW idle_in_transaction_session_timeout")
        assert shown == PEOPLE_IDLE_IN_TRANSACTION
        await planner.execute("SET lock_timeout = '100ms'")
        await people.execute("BEGIN")
        await people.execute(f"LOCK TABLE {keys.STRATEGY} IN ACCESS EXCLUSIVE MODE")
        with pytest.raises(asyncpg.LockNotAvailableError):
            await planner.fetchval(f"SELECT count(*) FROM {keys.STRATEGY}")
        await asyncio.sleep(float(PEOPLE_IDLE_IN_TRANSACTION.rstrip("s")) + 2.0)
        # the server ended the session, and its lock with it: the service reads again
        assert await planner.fetchval(f"SELECT count(*) FROM {keys.STRATEGY}") > 0
        with pytest.raises((asyncpg.PostgresError, asyncpg.InterfaceError, OSError)):
            await people.fetchval("SELECT 1")
    finally:
        await people.close()
        await planner.close()
