"""The decision service's one data path: its SQL, its source Protocol, and its store.

- :class:`DecisionSource`: the raw typed reads and writes (one read of every live
  recommendation, the newest command per robot, and the two writes);
  :class:`PgDecisionSource` is its Postgres implementation (pnav.monolith.decision has the
  in-memory one).
- :class:`DecisionStore`: the one object the service holds. It keeps the last command issued
  per robot (read from the table on the first look and for robots regained from another
  replica) and the live recommendations (from the rows' images, CONTRACT.md "Row images";
  the table read as the fallback), and implements
  :class:`~services.decision.view.DecisionView`, all the rules see.

Each write is a single statement (a data-modifying CTE): the decision row and the
``treated_by`` of the rows it considered commit together, in one round trip, which keeps
the decision's latency to one query out (and, with images, none in); each notification
carries the row's image.
"""

from __future__ import annotations

import logging
import math
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any, Final, Protocol

from common import log
from common.bus import Notification
from common.contract import keys
from common.db import Database
from common.freshness import Sequences
from services.decision.arbitration import (
    Issued,
    Recommendation,
    RobotDecision,
    SystemDecision,
    reissue_due,
)
from services.decision.live import LiveRecommendations, recommendation_of

logger = logging.getLogger("pnav.decision")

# The period fallback (store clock s): the live recommendations are read from the table at
# least this often even while every notification carried its image, in case one was lost.
REREAD_S: Final = 0.25

# Every robot, with each of its live recommendations (none: one row of NULLs). The table is
# append-only and grows all run long, so each robot must be served by the
# (robot_id, kind, expires_stamp) index: `OFFSET 0` keeps the planner from flattening the
# lateral subquery into one hash join over the whole table (a sequential scan, measured at
# 20 ms for 200k rows against 0.1 ms this way).
LIVE_SQL: Final = """
SELECT r.robot_id, c.id, c.kind, c.source, c.priority, c.linear_mps, c.angular_rps,
       c.system_command, c.reason, c.treated_by, c.expires_stamp
FROM robot r
LEFT JOIN LATERAL (
    SELECT id, kind, source, priority, linear_mps, angular_rps, system_command, reason,
           treated_by, expires_stamp
    FROM command_recommendation c
    WHERE c.robot_id = r.robot_id AND c.kind IN ('robot', 'system') AND c.expires_stamp > $1
    OFFSET 0
) c ON true
"""

LAST_ISSUED_SQL: Final = """
SELECT r.robot_id, c.id, c.stamp, c.linear_mps, c.angular_rps, c.recommendation_id, c.source
FROM robot r
CROSS JOIN LATERAL (
    SELECT id, stamp, linear_mps, angular_rps, recommendation_id, source
    FROM command2robot c WHERE c.robot_id = r.robot_id ORDER BY id DESC LIMIT 1
) c
"""

WRITE_COMMAND2ROBOT_SQL: Final = """
WITH decision AS (
    INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, recommendation_id,
                               source, considered_ids, reason)
    VALUES ($1, $2, $3, $4, $5, $6, $7::bigint[], $8)
    RETURNING id
), treated AS (
    UPDATE command_recommendation SET treated_by = decision.id
    FROM decision WHERE command_recommendation.id = ANY($7::bigint[])
)
SELECT id FROM decision
"""

WRITE_SYSTEM_COMMAND_SQL: Final = """
WITH decision AS (
    INSERT INTO system_command (robot_id, command, recommendation_id, considered_ids, reason,
                                status, stamp)
    VALUES ($1, $2, $3, $4::bigint[], $5, 'pending', $6)
    RETURNING id
), treated AS (
    UPDATE command_recommendation SET treated_by = decision.id
    FROM decision WHERE command_recommendation.id = ANY($4::bigint[])
)
SELECT id FROM decision
"""


async def live_recommendations(db: Any, now: float) -> dict[str, list[Recommendation]]:
    """Robot id -> its live recommendations (every robot present, maybe with none)."""
    out: dict[str, list[Recommendation]] = defaultdict(list)
    for row in await db.fetch(LIVE_SQL, now):
        robot_id = row["robot_id"]
        if row["id"] is None:
            out[robot_id] = []
            continue
        out[robot_id].append(Recommendation.of_row(row))
    return dict(out)


async def last_issued(db: Any) -> dict[str, Issued]:
    """Robot id -> its newest command2robot row (robots that never had one are absent)."""
    return {
        row["robot_id"]: Issued(
            row["id"],
            row["stamp"],
            row["linear_mps"],
            row["angular_rps"],
            row["recommendation_id"],
            row["source"],
        )
        for row in await db.fetch(LAST_ISSUED_SQL)
    }


async def write_robot_command(db: Database, d: RobotDecision) -> int:
    """Insert the command2robot row, mark what it considered, then notify command2robot
    with the row's image (the bridge sends it without reading the table)."""
    value = await db.write(
        keys.COMMAND2ROBOT,
        d.robot_id,
        WRITE_COMMAND2ROBOT_SQL,
        d.robot_id,
        d.stamp,
        d.linear_mps,
        d.angular_rps,
        d.recommendation_id,
        d.source,
        list(d.considered_ids),
        d.reason,
        image=d.image(),
    )
    return int(value)


async def write_system_command(db: Database, d: SystemDecision) -> int:
    """Insert the pending system_command row, mark what it considered, then notify with
    the row's image."""
    value = await db.write(
        keys.SYSTEM_COMMAND,
        d.robot_id,
        WRITE_SYSTEM_COMMAND_SQL,
        d.robot_id,
        d.command,
        d.recommendation_id,
        list(d.considered_ids),
        d.reason,
        d.stamp,
        image=d.image(),
    )
    return int(value)


class DecisionSource(Protocol):
    """The decision service's reads and writes of the contract, typed."""

    async def live_recommendations(self, now: float) -> dict[str, list[Recommendation]]:
        """Robot id -> its live robot and system recommendations (every robot present)."""
        ...

    async def last_issued(self) -> dict[str, Issued]:
        """Robot id -> its newest command2robot row (robots never commanded are absent)."""
        ...

    async def write_robot_command(self, d: RobotDecision) -> int:
        """Insert the command2robot row and mark ``treated_by``; then notify. Its id."""
        ...

    async def write_system_command(self, d: SystemDecision) -> int:
        """Insert the pending system_command row and mark ``treated_by``; then notify."""
        ...


class PgDecisionSource:
    """:class:`DecisionSource` on Postgres (pool reads, ``Database.write`` for the writes)."""

    def __init__(self, db: Database) -> None:
        self.db = db

    async def live_recommendations(self, now: float) -> dict[str, list[Recommendation]]:
        return await live_recommendations(self.db.pool, now)

    async def last_issued(self) -> dict[str, Issued]:
        return await last_issued(self.db.pool)

    async def write_robot_command(self, d: RobotDecision) -> int:
        return await write_robot_command(self.db, d)

    async def write_system_command(self, d: SystemDecision) -> int:
        return await write_system_command(self.db, d)


def _everyone(_robot_id: str) -> bool:
    return True


class DecisionStore:
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
        self._seqs = Sequences()
        self.reads = 0  # reads of the live recommendations (tests, benchmarks)

    # -- DecisionView ----------------------------------------------------------------------
    def sim_now(self) -> float | None:
        now = self._sim_now()
        if now is None and not self._waiting_logged:
            self._waiting_logged = True  # once: the clock is missing at every look until then
            log.event(logger, logging.INFO, "waiting for the sim clock before deciding")
        return now

    async def live(self, now: float) -> dict[str, list[Recommendation]]:
        await self._catch_up()
        at = self._clock()
        if self._stale or not (self._read_at <= at < self._read_at + self.reread_s):
            await self._read(now, at)
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

    async def write_robot_command(self, d: RobotDecision) -> int:
        row_id = await self.source.write_robot_command(d)
        self._issued[d.robot_id] = Issued(
            row_id, d.stamp, d.linear_mps, d.angular_rps, d.recommendation_id, d.source
        )
        self._live.treated(d.robot_id, d.considered_ids, row_id)
        return row_id

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
        gap = self._seqs.gap(f"{note.table}/{note.robot}", note.src, note.seq)
        if note.row is None or gap or note.robot is None:
            self._stale = True
            return
        try:
            rec = recommendation_of(note.row)
        except (KeyError, TypeError, ValueError):
            self._stale = True  # not the contract's image: the table says
            return
        self._live.add(rec)

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
        # A robot removed from the robot table (or now another replica's) has nothing left
        # to stop here.
        for robot_id in [r for r in self._issued if r not in read or not self._owns(r)]:
            del self._issued[robot_id]

    async def _catch_up(self) -> None:
        if not self._bootstrapped:
            # First look after start: carry on from the table, so a restart neither repeats
            # a stop nor forgets that a robot is moving.
            self._issued = await self.source.last_issued()
            self._bootstrapped = True
            self._regained.clear()
        elif self._regained:
            # Robots taken over from another replica: carry on from what it issued last.
            regained, self._regained = self._regained, set()
            last = await self.source.last_issued()
            for robot_id in regained:
                if robot_id in last:
                    self._issued[robot_id] = last[robot_id]
                else:
                    self._issued.pop(robot_id, None)
