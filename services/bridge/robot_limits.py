"""The robots' speed limits, footprint and acceleration, as the command relay clamps to them
(and the safety layer sizes the swept corridor with the footprint and the stopping distance
with the acceleration) without reading the table.

A command2robot image carries the decision but not the robot's limits; the relay takes them
from this cache of the ``robot`` table, read at start and again after every robot
notification (the bridge hands those over: :meth:`RobotLimits.changed`). A notification that
comes while a read is under way leaves the cache stale, so it is read once more
(``common.freshness.FreshCache`` keeps that bookkeeping). While the cache is stale, or a read
of it failed, :meth:`RobotLimits.of` says nothing and the relay reads the command with its
limits in one query, as it did before images.

The relay's periodic full read returns every commanded robot's limits with its command; a
difference from the cache (a robot notification that was lost) marks the cache stale.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import asyncpg

from common.contract import keys, records
from common.footprint import Footprint
from common.freshness import FreshCache

# (max_linear_mps, max_angular_rps, footprint, max_linear_accel_mps2): the clamp's, and the
# safety layer's (the swept corridor's shape, the stopping distance's deceleration); the
# footprint is the row's footprint_polygon, or the disc of its footprint_radius_m
Limits = tuple[float, float, Footprint, float]
LIMIT_COLUMNS = (
    "max_linear_mps, max_angular_rps, footprint_radius_m, footprint_polygon, max_linear_accel_mps2"
)

_READ = f"SELECT robot_id, {LIMIT_COLUMNS} FROM {keys.ROBOT}"


def limits_of(row: Sequence[Any]) -> Limits:
    """The :data:`Limits` of the LIMIT_COLUMNS of a row (in that order)."""
    footprint = Footprint.of(row[2], records.polygon_of(row[3]))
    return (row[0], row[1], footprint, row[4])


_TABLE = keys.ROBOT  # the one key of the cache: the whole table is read as one unit


class RobotLimits:
    """Per robot, its :data:`Limits` as last read, while nothing says they changed since."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        # no recheck period: robot rows change with the world, which is notified; a lost
        # notification is caught by the relay's periodic read (see the module docstring)
        self._cache: FreshCache[str, dict[str, Limits]] = FreshCache(clock, math.inf)
        self.reads = 0

    def changed(self) -> None:
        """A robot notification: the table may have changed."""
        self._cache.announce(_TABLE)

    def stale(self) -> bool:
        return self._cache.stale(_TABLE)

    def of(self, robot: str) -> Limits | None:
        """The robot's limits if the cache is fresh and knows the robot, else None."""
        if self._cache.stale(_TABLE):
            return None
        table = self._cache.peek(_TABLE)
        return None if table is None else table.get(robot)

    def check(self, robot: str, limits: Limits) -> None:
        """Limits read from the table with a command: if they differ, the cache is stale."""
        table = self._cache.peek(_TABLE)
        if table is not None and table.get(robot) != limits:
            self._cache.announce(_TABLE)

    async def read(self, conn: asyncpg.Connection) -> None:
        """Read the robot table into the cache (if stale; a failed read leaves it stale)."""

        async def fetch() -> dict[str, Limits]:
            rows = await conn.fetch(_READ)
            return {r[0]: limits_of(tuple(r)[1:]) for r in rows}

        try:
            await self._cache.get(_TABLE, fetch)
        except BaseException:
            self._cache.announce(_TABLE)  # get() took the entry for fresh before reading
            raise
        self.reads = self._cache.reads
