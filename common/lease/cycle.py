"""One lease cycle: from a read of ``pg_locks`` to the robots given back and taken.

A robot is given back in two moves (the *hand-over*): the replica stops acting for it at
once (:meth:`Holdings.drop`, reported lost), and releases its lock only once the work under
way when it stopped has ended (``under_way``: the engine's activation, which may be writing
for the robot right now). Until then the lock stays ours, so the next owner cannot read the
tables before that write is committed and act a second time on what it answered.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import KW_ONLY, dataclass, field
from typing import Final

from common import log
from common.lease.holdings import Holdings
from common.lease.session import LockSession
from common.lease.share import Snapshot, decide
from common.lease.sql import REBALANCE, ROBOT_GONE

logger = logging.getLogger("pnav.lease")

Announce = Callable[[str, int | None], None]  # robot_lease written for (robot, id or None)
UnderWay = Callable[[], "asyncio.Future[None] | None"]  # the work under way, None when idle

# A hand-over waits this long at most: an activation still running after it is stuck, and
# the robot is better served by another replica (at the risk of one command written twice,
# which is logged) than by none.
HANDOVER_LIMIT_S: Final = 10.0

# Stands for "held by someone else" in the view a cycle decides on, for robots whose lock
# is still ours only until their hand-over ends: not ours to act for, not free to take.
HANDING_OVER: Final = -1


@dataclass(frozen=True)
class Handover:
    """A robot no longer acted for whose lock is released once ``done`` is."""

    reason: str
    done: asyncio.Future[None]
    since: float  # monotonic


@dataclass
class LeaseCounters:
    cycles: int = 0
    acquired: int = 0
    released: int = 0
    lost: int = 0  # robots dropped because the lock connection went
    reconnects: int = 0
    errors: int = 0  # cycles that failed for another reason than the connection
    handovers_waited: int = 0  # robots whose release waited for the work under way
    handovers_expired: int = 0  # ... and released anyway after HANDOVER_LIMIT_S


@dataclass(eq=False)
class Cycle:
    """What one replica carries from cycle to cycle besides its locks: the hysteresis count
    and the share last seen."""

    service: str
    instance: str
    held: Holdings
    counters: LeaseCounters
    announce: Announce
    _: KW_ONLY
    settle_cycles: int
    takeover_wait_s: float
    under_way: UnderWay | None = None
    wake: Callable[[], None] | None = None  # run a cycle soon (a hand-over's work ended)
    # robots whose lock waits for their hand-over
    handing: dict[str, Handover] = field(default_factory=dict, init=False)
    pending: int = field(default=0, init=False)  # consecutive cycles a give-back was due
    members: int = field(default=0, init=False)
    share: tuple[int, int] = field(default=(0, 0), init=False)

    async def run(self, session: LockSession, view: Snapshot) -> None:
        """Act on ``view``, just read on ``session``."""
        self.counters.cycles += 1
        self.held.promote()
        await self._release_settled(session)
        view = self._masked(view)
        held = self.held.owned
        # Robots whose row is gone: give the lock back. Robots whose lock is not ours any
        # more (it cannot happen while the connection lives; be safe): forget them.
        gone = {r for r in held if r not in view.holders}
        stolen = {r for r in held if r in view.holders and view.holders[r] != view.me}
        if stolen:
            logger.error("locks not held any more: %s", ",".join(sorted(stolen)))
        self.held.drop(gone | stolen)
        await self.hand_over(session, sorted(gone), ROBOT_GONE)

        decision = decide(view, frozenset(held), self.instance, self.pending, self.settle_cycles)
        self.pending, self.members, self.share = (
            decision.pending,
            decision.replicas,
            decision.share,
        )
        if decision.release:
            self.held.drop(decision.release)  # stop acting first
            await self.hand_over(session, decision.release, REBALANCE)
            self._log("robots given back", decision.release)
        await self._take(session, decision.acquire, decision.want)

    async def hand_over(self, session: LockSession, robots: Iterable[str], reason: str) -> None:
        """Give ``robots`` back (the caller has stopped acting for them): now if no work is
        under way, else once it has ended (a later cycle, woken when it ends)."""
        robots = list(robots)
        done = self.under_way() if robots and self.under_way is not None else None
        if done is None or done.done():
            await self.release(session, robots, reason)
            return
        now = time.monotonic()
        for robot in robots:
            self.handing[robot] = Handover(reason, done, now)
            self.counters.handovers_waited += 1
        if self.wake is not None:
            wake = self.wake
            done.add_done_callback(lambda _f: wake())

    def forget_handovers(self) -> frozenset[str]:
        """Drop every pending hand-over (the locks go with the connection, or are released
        by the caller); return their robots."""
        robots = frozenset(self.handing)
        self.handing.clear()
        return robots

    async def _release_settled(self, session: LockSession) -> None:
        """Release the robots whose hand-over is over (or has waited too long)."""
        now = time.monotonic()
        for robot, h in list(self.handing.items()):
            if not h.done.done():
                if now - h.since < HANDOVER_LIMIT_S:
                    continue
                self.counters.handovers_expired += 1
                log.event(
                    logger,
                    logging.WARNING,
                    "hand-over: the work under way did not end; robot given back anyway",
                    service=self.service,
                    robot=robot,
                    waited_s=round(now - h.since, 1),
                )
            # still handing over until the lock is given back: a robot out of ``handing``
            # must not be locked any more (it was, for the release's round trip)
            await self.release(session, [robot], h.reason)
            self.handing.pop(robot, None)

    def _masked(self, view: Snapshot) -> Snapshot:
        """``view`` with the robots being handed over shown as someone else's."""
        if not self.handing:
            return view
        holders = dict(view.holders)
        for robot in list(self.handing):
            if robot not in holders:
                continue  # its row is gone: its lock is still ours until the hand-over ends
            if holders[robot] == view.me:
                holders[robot] = HANDING_OVER
            else:
                # its lock is not ours any more (cannot happen while the connection lives)
                logger.error("lock not held any more during its hand-over: %s", robot)
                del self.handing[robot]
        return Snapshot(view.robots, holders, view.members, view.me)

    async def release(self, session: LockSession, robots: Iterable[str], reason: str) -> None:
        """Give ``robots`` back now (no work for them is under way any more)."""
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
            if self.held.add(robot, wait_s):
                gained.append(robot)
                # ``owns`` is true from here: the service hears of the gain before the next
                # await (the next robot's lock), so none of its activations sees the robot
                # owned before it has rebuilt what it keeps for it from the tables (a
                # decision replica that did issued a command its old owner had issued)
                self.held.report(frozenset((robot,)), frozenset())
            else:
                waiting.append(robot)
        if waiting:
            self._log("robots taken over, waiting out their vanished holder", waiting)
        if gained:
            self._log("robots leased", gained)

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
