"""The decision service's one data path: its source and its store.

- :class:`~services.decision.source.DecisionSource`: the raw typed reads and writes, with
  their SQL (services/decision/source.py; re-exported here with
  :class:`~services.decision.source.PgDecisionSource`, its Postgres implementation);
  pnav.monolith.memory_decision has the in-memory one.
- :class:`DecisionStore`: the one object the service holds. It keeps the last command issued
  per robot (read from the table on the first look and for robots regained from another
  replica) and the live recommendations (from the rows' images, CONTRACT.md "Row images";
  the table read as the fallback), and implements
  :class:`~services.decision.view.DecisionView`, all the rules see.

Each write is a single statement (a data-modifying CTE): the decision row and the
``treated_by`` of the rows it considered commit together, in one round trip, which keeps
the decision's latency to one query out (and, with images, none in); the commands of every
robot decided in one activation go in one statement; each notification carries its row's
image.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from typing import Final

from common import log
from common.bus import Notification
from common.contract import keys
from common.contract.recommendations import Recommendation
from common.freshness import Sequences
from common.images import GuardedStore, ImageGuard
from services.decision.arbitration import (
    Issued,
    RobotDecision,
    SystemDecision,
    reissue_due,
)
from services.decision.live import LiveRecommendations
from services.decision.source import DecisionSource, PgDecisionSource

__all__ = ["REREAD_S", "DecisionSource", "DecisionStore", "PgDecisionSource"]

logger = logging.getLogger("pnav.decision")

# The period fallback (store clock s): the live recommendations are read from the table at
# least this often even while every notification carried its image, in case one was lost.
REREAD_S: Final = 0.25


def _everyone(_robot_id: str) -> bool:
    return True


class DecisionStore(GuardedStore):
    """The decision service's store: a :class:`DecisionSource` and what the service keeps.

    ``sim_now`` reads the sim clock (None until it is heard); ``owns`` says which robots this
    replica decides for (docs/REPLICAS.md; every robot by default). Runs on the event loop.

    The live recommendations are kept in memory from the rows' images
    (:class:`~services.decision.live.LiveRecommendations`); the table is read (LIVE_SQL) at
    the first look, after a notification without a usable image (none, a ``seq`` gap, no
    robot) or about the robot table, after an ownership change, and at least every
    ``reread_s`` of ``clock`` (the period fallback, on the store's side: the engine's F only
    says when the meta rule looks, and a look needs no read; wall time in a service, sim
    time in a lockstep or in-process run, so a run does not depend on the machine's speed;
    sim time may stand still, the fallback must not). :meth:`live` gives only the
    robots to decide for: those whose recommendations changed (new, expired, or read
    again) and those whose re-issue is due.
    """

    def __init__(
        self,
        source: DecisionSource,
        sim_now: Callable[[], float | None],
        owns: Callable[[str], bool] = _everyone,
        reread_s: float = REREAD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.source = source
        self._sim_now = sim_now
        self._clock = clock
        self._owns = owns
        self.reread_s = reread_s
        # Robot id -> newest command2robot row; read from the table on the first look.
        self._issued: dict[str, Issued] = {}
        self._bootstrapped = False
        # Robots taken over from another replica: their issued entry is read again.
        self._regained: set[str] = set()
        self._waiting_logged = False
        self._live = LiveRecommendations()
        self._stale = True  # read the table at the next look
        self._read_at = -math.inf  # sim time of the last read of the table
        # images held to the table's rules (the safety band...) before they count as live
        self.images = ImageGuard(logger)
        self.reads = 0  # reads of the live recommendations (tests, benchmarks)

    @property
    def sequences(self) -> Sequences:
        """The numbering seen per publisher and robot (tests)."""
        return self.images.sequences

    # -- DecisionView ----------------------------------------------------------------------
    def sim_now(self) -> float | None:
        now = self._sim_now()
        if now is None and not self._waiting_logged:
            self._waiting_logged = True  # once: the clock is missing at every look until then
            log.event(logger, logging.INFO, "waiting for the sim clock before deciding")
        return now

    async def live(self, now: float) -> dict[str, list[Recommendation]]:
        while True:
            await self._catch_up()
            at = self._clock()
            if self._stale or not (self._read_at <= at < self._read_at + self.reread_s):
                await self._read(now, at)
            # A robot gained while a read was under way is owned from now on: deciding it
            # before its last command is read again would issue it twice (its old owner's
            # command is not in what this replica kept). So catch it up first.
            if not self._regained:
                break
        live = self._live
        live.expire(now)
        due = {
            robot_id: list(recs.values())
            for robot_id, recs in live.robots.items()
            if self._owns(robot_id)
            and (
                robot_id in live.changed or (recs and reissue_due(self._issued.get(robot_id), now))
            )
        }
        live.changed.clear()
        return due

    def issued(self, robot_id: str) -> Issued | None:
        return self._issued.get(robot_id)

    async def write_robot_commands(self, ds: Sequence[RobotDecision]) -> list[int | None]:
        ids = await self.source.write_robot_commands(ds)
        for d, row_id in zip(ds, ids, strict=True):
            if row_id is None:
                continue  # refused: the robot's last issued command stays what it was
            self._issued[d.robot_id] = Issued(
                row_id, d.stamp, d.linear_mps, d.angular_rps, d.recommendation_id, d.source
            )
            self._live.treated(d.robot_id, d.considered_ids, row_id)
        return ids

    async def write_system_command(self, d: SystemDecision) -> int:
        row_id = await self.source.write_system_command(d)
        self._live.treated(d.robot_id, d.considered_ids, row_id)
        return row_id

    # -- what the service forwards -----------------------------------------------------------
    def note(self, note: Notification) -> None:
        """A change notification: a recommendation's image is kept as live (CONTRACT.md "Row
        images"); anything else it cannot stand for means reading the table at the next look."""
        if note.table != keys.COMMAND_RECOMMENDATION:
            if note.table in (keys.ROBOT, ""):
                self._stale = True  # a robot came or went (or an unreadable hint)
            return
        # no image, one after a lost notification, or one the table would refuse (a forward
        # command in the safety band, another robot's row, a NaN stamp...): the table says
        if note.robot is None:
            self.images.gap(note)  # numbered all the same
            self._stale = True
            return
        rec = self.images.fresh(note, Recommendation.of_row)
        if rec is None:
            self._stale = True
            return
        self._live.add(rec)

    def owns(self, robot_id: str) -> bool:
        return self._owns(robot_id)

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        """Drop what is kept for the ``lost`` robots; read the ``gained`` ones' again."""
        for robot_id in lost:
            self._issued.pop(robot_id, None)
        self._live.forget(lost)
        self._regained -= lost
        self._regained |= gained
        self._stale = self._stale or bool(gained)

    async def _read(self, now: float, at: float) -> None:
        """Every live recommendation from the table; robots gone from it are dropped."""
        self._stale = False
        self._read_at = at
        self._live.reading()
        try:
            read = await self.source.live_recommendations(now)
        except BaseException:
            self._live.read_failed()
            self._stale = True
            raise
        self.reads += 1
        self._live.replace(read)
        # A robot removed from the robot table has nothing left to stop here. Robots given
        # up are dropped when the lease reports them lost (on_ownership_change), not here:
        # ``owns`` is also false while the lease waits for its next confirmation, with the
        # lock still held, and a robot dropped then would be issued again when it is true.
        for robot_id in [r for r in self._issued if r not in read]:
            del self._issued[robot_id]

    async def _catch_up(self) -> None:
        # A read covers the robots gained before it starts; one gained while it is under way
        # may have had its old owner's last command committed after the read looked, so it
        # stays in ``_regained`` for the next read.
        if not self._bootstrapped:
            # First look after start: carry on from the table, so a restart neither repeats
            # a stop nor forgets that a robot is moving.
            self._regained.clear()
            self._issued = await self.source.last_issued()
            self._bootstrapped = True
        elif self._regained:
            # Robots taken over from another replica: carry on from what it issued last.
            regained, self._regained = self._regained, set()
            last = await self.source.last_issued()
            for robot_id in regained:
                if robot_id in last:
                    self._issued[robot_id] = last[robot_id]
                else:
                    self._issued.pop(robot_id, None)
