"""One lease cycle: from a read of ``pg_locks`` to the robots given back and taken."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from common import log
from common.lease.holdings import Holdings
from common.lease.session import LockSession
from common.lease.share import Snapshot, decide
from common.lease.sql import REBALANCE, ROBOT_GONE

logger = logging.getLogger("pnav.lease")

Announce = Callable[[str, int | None], None]  # robot_lease written for (robot, id or None)


@dataclass
class LeaseCounters:
    cycles: int = 0
    acquired: int = 0
    released: int = 0
    lost: int = 0  # robots dropped because the lock connection went
    reconnects: int = 0
    errors: int = 0  # cycles that failed for another reason than the connection


class Cycle:
    """What one replica carries from cycle to cycle besides its locks: the hysteresis count
    and the share last seen."""

    def __init__(
        self,
        service: str,
        instance: str,
        held: Holdings,
        counters: LeaseCounters,
        announce: Announce,
        *,
        settle_cycles: int,
        takeover_wait_s: float,
    ) -> None:
        self.service = service
        self.instance = instance
        self.held = held
        self.counters = counters
        self.announce = announce
        self.settle_cycles = settle_cycles
        self.takeover_wait_s = takeover_wait_s
        self.pending = 0  # consecutive cycles a give-back was due (decide)
        self.members = 0
        self.share = (0, 0)

    async def run(self, session: LockSession, view: Snapshot) -> None:
        """Act on ``view``, just read on ``session``."""
        self.counters.cycles += 1
        self.held.promote()
        held = self.held.owned
        # Robots whose row is gone: give the lock back. Robots whose lock is not ours any
        # more (it cannot happen while the connection lives; be safe): forget them.
        gone = {r for r in held if r not in view.holders}
        stolen = {r for r in held if r in view.holders and view.holders[r] != view.me}
        if stolen:
            logger.error("locks not held any more: %s", ",".join(sorted(stolen)))
        self.held.drop(gone | stolen)
        await self.release(session, sorted(gone), ROBOT_GONE)

        decision = decide(view, frozenset(held), self.instance, self.pending, self.settle_cycles)
        self.pending, self.members, self.share = (
            decision.pending,
            decision.replicas,
            decision.share,
        )
        if decision.release:
            self.held.drop(decision.release)  # stop acting first
            await self.release(session, decision.release, REBALANCE)
            self._log("robots given back", decision.release)
        await self._take(session, decision.acquire, decision.want)

    async def release(self, session: LockSession, robots: Iterable[str], reason: str) -> None:
        """Give ``robots`` back (the caller has stopped acting for them)."""
        for robot in robots:
            await session.release(robot, reason)
            self.counters.released += 1
            self.announce(robot, None)

    async def _take(self, session: LockSession, free: tuple[str, ...], want: int) -> None:
        gained: list[str] = []
        waiting: list[str] = []
        for robot in free:
            if len(gained) + len(waiting) >= want:
                break
            taken = await session.acquire(robot, self.takeover_wait_s)
            if taken is None:
                continue
            lease_id, wait_s = taken
            self.counters.acquired += 1
            self.announce(robot, lease_id)
            (gained if self.held.add(robot, wait_s) else waiting).append(robot)
        if waiting:
            self._log("robots taken over, waiting out their vanished holder", waiting)
        if gained:
            self._log("robots leased", gained)
            self.held.report(frozenset(gained), frozenset())

    def _log(self, what: str, robots: Iterable[str]) -> None:
        log.event(
            logger,
            logging.INFO,
            what,
            service=self.service,
            robots=",".join(robots),
            replicas=self.members,
            share="{}-{}".format(*self.share),
            owned=len(self.held.owned),
        )
