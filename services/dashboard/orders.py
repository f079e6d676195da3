"""What people ask the dashboard for: a goal, a cancel, a strategy switch, a new strategy.

Each is checked against what the store knows (the robot exists, the strategy exists), then
written through the store's source as ``pnav goal`` and ``pnav strategy`` write it. A row
the database still refuses (a CHECK, a foreign key, a value it cannot store) is the
request's fault: 422 with the database's one-line reason, never a 500.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import asyncpg

from common.contract import keys
from common.contract.zones import Zone
from common.errors import ConnectionFailure
from services.dashboard.requests import GoalRequest, NewStrategy, Refused
from services.dashboard.store import DashboardStore

logger = logging.getLogger("pnav.dashboard.orders")


@asynccontextmanager
async def refusal_as_4xx() -> AsyncIterator[None]:
    try:
        yield
    except (
        asyncpg.IntegrityConstraintViolationError,
        asyncpg.DataError,
        asyncpg.ProgramLimitExceededError,  # e.g. a value too large for an index
    ) as exc:
        detail = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise Refused(422, f"the database refused the row: {detail}") from None


class Orders:
    def __init__(self, store: DashboardStore) -> None:
        self.store = store
        self.source = store.source

    async def require_robot(self, robot: str) -> None:
        """404 unless ``robot`` is a row of the robot table (read again if not known yet)."""
        fleet = self.store.fleet
        if not fleet.known(robot):
            fleet.set_robots(await self.source.robots())
        if not fleet.known(robot):
            known = ", ".join(r for r in sorted(fleet.robots) if fleet.known(r))
            raise Refused(404, f"no robot {robot!r}; known robots: {known or 'none'}")

    async def require_strategy(self, code: str) -> None:
        if not any(s["code"] == code for s in self.store.strategies):
            await self.store.read_globals()
        codes = [s["code"] for s in self.store.strategies]
        if code not in codes:
            raise Refused(422, f"unknown strategy {code!r}; known strategies: {', '.join(codes)}")

    async def set_goal(self, robot: str, goal: GoalRequest) -> int:
        await self.require_robot(robot)
        async with refusal_as_4xx():
            return await self.source.set_goal(robot, goal)

    async def cancel_goal(self, robot: str) -> int | None:
        await self.require_robot(robot)
        return await self.source.cancel_goal(robot)

    async def set_strategy(self, robot: str, code: str, wait_s: float) -> dict[str, Any]:
        """SET_STRATEGY as a user_command; waits up to ``wait_s`` for the strategy service's
        verdict (``pending`` if none came: the page shows it when it does)."""
        await self.require_robot(robot)
        await self.require_strategy(code)
        async with refusal_as_4xx():
            command_id = await self.source.user_command(robot, "SET_STRATEGY", code)
        deadline = time.monotonic() + wait_s
        try:
            row = await self.source.row(keys.USER_COMMAND, command_id)
            while row is not None and row["status"] == "pending" and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
                row = await self.source.row(keys.USER_COMMAND, command_id)
        except (OSError, ConnectionFailure, asyncpg.PostgresError, asyncpg.InterfaceError) as exc:
            # the command is written: its verdict comes to the page's timeline later
            logger.warning("no verdict read for user_command %s: %s", command_id, exc)
            row = None
        status = "pending" if row is None else row["status"]
        reason = "" if row is None else row["reason"] or ""
        return {"command_id": command_id, "status": status, "reason": reason}

    async def add_zone(self, zone: Zone) -> None:
        async with refusal_as_4xx():
            await self.source.add_zone(zone)
        await self._read_again(f"zone {zone.name} added")

    async def remove_zone(self, name: str) -> None:
        if not await self.source.remove_zone(name):
            raise Refused(404, f"name: no zone named {name!r}")
        await self._read_again(f"zone {name} removed")

    async def _read_again(self, what: str) -> None:
        try:
            await self.store.read_globals()  # the page draws it at once...
        except Exception as exc:
            # ...or at the next push: the row is committed, the request succeeded
            logger.warning("%s, the world not read again yet: %s", what, exc)

    async def add_strategy(self, request: NewStrategy) -> None:
        async with refusal_as_4xx():
            await self.source.add_strategy(request)
        try:
            await self.store.read_globals()  # the page lists it at once...
        except Exception as exc:
            # ...or at the next push: the row is committed, the request succeeded
            logger.warning("strategy %s added, the list not read again yet: %s", request.code, exc)
