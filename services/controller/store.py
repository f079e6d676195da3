"""Every read and write of the contract the controller does, and what it keeps of them.

- :class:`ControllerSource`: the raw typed reads and the one write, as a Protocol;
- :class:`PgControllerSource`: them in Postgres (through ``common.contract.records``);
  pnav/monolith/controller.py has them in memory;
- :class:`ControllerStore`: the one object the service holds. It implements the rules'
  :class:`~services.controller.scenario.Host`, keeps the caches, and learns from the
  change notifications (:meth:`ControllerStore.note`, on the event loop) when to read again
  (common.freshness): an activation woken by one robot's scan reads that robot's scan only,
  not every robot's, and the robots and strategies only after one of them changed.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import Protocol

from common import log
from common.bus import Notification
from common.contract import keys, records
from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot
from common.db import Database
from common.freshness import FreshCache
from services.controller.scenario import Key, Recommendation

logger = logging.getLogger("pnav.controller")

# Notifications are hints: a row is read again after this long (store clock) even if none
# came, in case one was lost.
RECHECK_S = 0.25

ScanAndOdometry = tuple[LaserScan | None, Odometry | None]
Tables = tuple[list[Robot], dict[str, ActiveStrategy]]

_META = "robots and strategies"  # the one key of the meta cache: read together, stale together
_META_TABLES = frozenset((keys.ACTIVE_STRATEGY, keys.STRATEGY, keys.ROBOT))


class ControllerSource(Protocol):
    """The contract as the controller reads and writes it."""

    async def robots(self) -> list[Robot]: ...

    async def active_strategies(self) -> dict[str, ActiveStrategy]: ...

    async def newest_scan_and_odometry(self, robot_id: str) -> ScanAndOdometry:
        """The robot's newest scan and newest odometry in one round trip (odometry is None
        when there is no scan yet, or no odometry)."""

    async def newest_odometry(self, robot_id: str) -> Odometry | None: ...

    async def recommend(self, recommendation: Recommendation) -> int:
        """Write a command_recommendation row (notified after commit); its id."""


class PgControllerSource:
    """:class:`ControllerSource` in Postgres."""

    def __init__(self, db: Database) -> None:
        self.db = db

    async def robots(self) -> list[Robot]:
        return await records.robots(self.db.pool)

    async def active_strategies(self) -> dict[str, ActiveStrategy]:
        return await records.active_strategies(self.db.pool)

    async def newest_scan_and_odometry(self, robot_id: str) -> ScanAndOdometry:
        return await records.newest_scan_and_odometry(self.db.pool, robot_id)

    async def newest_odometry(self, robot_id: str) -> Odometry | None:
        return await records.newest_odometry(self.db.pool, robot_id)

    async def recommend(self, recommendation: Recommendation) -> int:
        r = recommendation
        return await records.recommend_velocity(
            self.db,
            r.robot_id,
            source=r.source,
            priority=r.priority,
            linear=r.linear,
            angular=r.angular,
            stamp=r.stamp,
            ttl_s=r.ttl_s,
            reason=r.reason,
            inputs=r.inputs,
        )


def _scan_id(pair: ScanAndOdometry) -> int | None:
    return pair[0].id if pair[0] is not None else None


class ControllerStore:
    """The rules' :class:`~services.controller.scenario.Host` over a source, with caches.

    ``clock`` is what the caches count ``recheck_s`` in (wall time in a service, sim time in
    a lockstep or in-process run); ``sim_now`` is sim time for the rules (None before the
    first clock message; ``clock`` if not given).
    """

    def __init__(
        self,
        source: ControllerSource,
        clock: Callable[[], float],
        sim_now: Callable[[], float | None] | None = None,
        recheck_s: float = RECHECK_S,
    ) -> None:
        self.source = source
        self._sim_now = sim_now or clock
        self.tables: FreshCache[str, Tables] = FreshCache(clock, recheck_s)
        # per robot: its newest scan with the odometry read in the same round trip (the
        # avoid scenarios and safety_stop want both, for the same scan)
        self.scans: FreshCache[str, ScanAndOdometry] = FreshCache(clock, recheck_s, _scan_id)
        # per robot: (scan id, odometry) read for a scan the pair above no longer holds
        self._odometry: dict[str, tuple[int, Odometry | None]] = {}
        # per (robot, scenario): the newest scan it recommended on, so that a scenario
        # restarted (or named again) never recommends twice on one scan
        self._recommended: dict[Key, int] = {}

    # -- what the service tells it ---------------------------------------------------------
    def note(self, note: Notification) -> None:
        """A change notification (on the event loop, before the engine wakes)."""
        if note.table == keys.LASER_SCAN:
            if note.robot is None:
                self.scans.announce_all()
            else:
                self.scans.announce(note.robot, note.id)
        elif note.table in _META_TABLES or not note.table:
            self.tables.announce(_META)  # which row changed does not matter: read both again

    def forget(self, robots: Iterable[str]) -> None:
        """Drop what was read and written for ``robots`` (they changed hands: another
        replica served, or will serve, them)."""
        gone = frozenset(robots)
        for robot_id in gone:
            self.scans.forget(robot_id)
            self._odometry.pop(robot_id, None)
        for key in [k for k in self._recommended if k[0] in gone]:
            del self._recommended[key]

    # -- Host --------------------------------------------------------------------------------
    def sim_now(self) -> float | None:
        return self._sim_now()

    async def robots(self) -> list[Robot]:
        return (await self.tables.get(_META, self._read_tables))[0]

    async def active_strategies(self) -> dict[str, ActiveStrategy]:
        return (await self.tables.get(_META, self._read_tables))[1]

    async def newest_scan(self, robot_id: str) -> LaserScan | None:
        pair = await self.scans.get(
            robot_id, lambda: self.source.newest_scan_and_odometry(robot_id)
        )
        return pair[0]

    async def odometry_at(self, scan: LaserScan) -> Odometry | None:
        robot_id = scan.robot_id
        pair = self.scans.peek(robot_id)
        if pair is not None and pair[0] is not None and pair[0].id == scan.id:
            return pair[1]  # read with the scan: the usual case, no round trip
        cached = self._odometry.get(robot_id)
        if cached is not None and cached[0] == scan.id:
            return cached[1]
        odometry = await self.source.newest_odometry(robot_id)
        self._odometry[robot_id] = (scan.id, odometry)
        return odometry

    def last_recommended_scan(self, robot_id: str, source: str) -> int | None:
        return self._recommended.get((robot_id, source))

    async def recommend(self, recommendation: Recommendation) -> int:
        r = recommendation
        row_id = await self.source.recommend(r)
        if r.scan_id is not None:
            self._recommended[(r.robot_id, r.source)] = r.scan_id
        log.event(
            logger,
            logging.DEBUG,
            "recommended",
            robot=r.robot_id,
            source=r.source,
            id=row_id,
            linear=round(r.linear, 3),
            angular=round(r.angular, 3),
            reason=r.reason,
        )
        return row_id

    async def _read_tables(self) -> Tables:
        return await self.source.robots(), await self.source.active_strategies()
