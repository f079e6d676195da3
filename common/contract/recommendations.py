"""Velocity recommendations queued during an activation and written together at its end.

A recommender (the planner, the controller) writes one ``command_recommendation`` row per
robot and scenario per sensor sample. Written one at a time, each row is a statement and a
synchronous commit of its own, and at 10 robots the rows queue behind each other's commits
(docs/BENCHMARKS.md, "What would meet the targets"). So a store :meth:`~RecommendationBatch.
add`\\ s them while its rules run, and the engine awaits :meth:`~RecommendationBatch.flush`
at the end of the activation (``Engine.after_activation``): every row of the activation in
ONE statement (column arrays through ``unnest``) and one commit, then one notification per
row with its image, in the order the rules recommended. A single row keeps the single-row
statement (``records.recommend_velocity``), so one robot's latency does not change.

RETURNING's rows are paired with the queued ones by position (an ``INSERT ... SELECT FROM
unnest`` returns them in the order it inserted them), and the pairing is checked (same
robot and source at each position); if the check fails the notifications go without an
image, and readers read the table (CONTRACT.md, "Row images"). A batch the database refuses
as data (a robot deleted meanwhile, a value out of the contract's bounds) is written row by
row, so one bad row costs only itself; the refusals are raised together afterwards, for the
engine to log once per distinct error.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import asyncpg

from common.contract import keys
from common.contract.records import RECOMMENDATION_COLUMNS, recommend_velocity
from common.db import Database
from common.errors import ContractError, InternalError

# Refused as data: the row, not the connection, is at fault.
_REFUSED = (asyncpg.IntegrityConstraintViolationError, asyncpg.DataError)

BATCH_SQL: Final = f"""
INSERT INTO {keys.COMMAND_RECOMMENDATION} (robot_id, kind, source, priority, linear_mps,
    angular_rps, stamp, expires_stamp, inputs, reason)
SELECT u.robot_id, 'robot', u.source, u.priority, u.linear_mps, u.angular_rps, u.stamp,
       u.expires_stamp, u.inputs::jsonb, u.reason
FROM unnest($1::text[], $2::text[], $3::int4[], $4::float8[], $5::float8[], $6::float8[],
            $7::float8[], $8::text[], $9::text[])
     AS u(robot_id, source, priority, linear_mps, angular_rps, stamp, expires_stamp, inputs,
          reason)
RETURNING id, robot_id, source"""


class RecommendationsRefused(ContractError):
    """The database refused some queued recommendations (the others were written)."""


@dataclass(frozen=True)
class VelocityRow:
    """A ``command_recommendation`` row of kind ``robot``, valid from ``stamp`` for
    ``ttl_s`` (sim s)."""

    robot_id: str
    source: str
    priority: int
    linear: float
    angular: float
    stamp: float
    ttl_s: float
    reason: str
    inputs: Mapping[str, Any] = field(default_factory=dict)

    def image(self) -> dict[str, Any]:
        """The row's contract columns as written (CONTRACT.md, "Row images"), without id."""
        values = (
            self.robot_id, "robot", self.source, self.priority, float(self.linear),
            float(self.angular), None, self.stamp, self.stamp + self.ttl_s,
            dict(self.inputs), self.reason,
        )  # fmt: skip
        return dict(zip(RECOMMENDATION_COLUMNS, values, strict=True))


def batch_args(rows: Sequence[VelocityRow]) -> list[Any]:
    """The column arrays of :data:`BATCH_SQL` for ``rows``."""
    return [
        [r.robot_id for r in rows],
        [r.source for r in rows],
        [r.priority for r in rows],
        [float(r.linear) for r in rows],
        [float(r.angular) for r in rows],
        [r.stamp for r in rows],
        [r.stamp + r.ttl_s for r in rows],
        [json.dumps(dict(r.inputs)) for r in rows],
        [r.reason for r in rows],
    ]


class RecommendationBatch:
    """The rows queued since the last flush (see the module's docstring)."""

    def __init__(self, db: Database) -> None:
        self.db = db
        self.pending: list[VelocityRow] = []
        self.statements = 0  # written so far, batched or alone (what batching saves)
        self.rows = 0

    def add(self, row: VelocityRow) -> None:
        self.pending.append(row)

    async def flush(self) -> list[int | None]:
        """Write what is queued; the ids in the order queued (None: refused). Raises
        :class:`RecommendationsRefused` after writing the rest if any row was refused."""
        rows, self.pending = self.pending, []
        refusals: list[str] = []
        ids: list[int | None]
        if len(rows) == 1:
            ids = [await self._alone(rows[0], refusals)]
        elif rows:
            try:
                ids = list(await self._together(rows))
            except _REFUSED:
                ids = [await self._alone(row, refusals) for row in rows]
        else:
            ids = []
        if refusals:
            raise RecommendationsRefused("recommendation refused: " + "; ".join(refusals))
        return ids

    async def _together(self, rows: Sequence[VelocityRow]) -> list[int]:
        async with self.db.pool.acquire() as conn:
            records = await conn.fetch(BATCH_SQL, *batch_args(rows))
        self.statements += 1
        self.rows += len(records)
        if len(records) != len(rows):
            raise InternalError(f"{len(rows)} recommendations written, {len(records)} returned")
        paired = all(
            rec["robot_id"] == row.robot_id and rec["source"] == row.source
            for rec, row in zip(records, rows, strict=True)
        )
        notify = self.db.notifier.notify
        for rec, row in zip(records, rows, strict=True):
            image = {**row.image(), "id": rec["id"]} if paired else None
            notify(keys.COMMAND_RECOMMENDATION, rec["robot_id"], rec["id"], image)
        return [int(rec["id"]) for rec in records]

    async def _alone(self, row: VelocityRow, refusals: list[str]) -> int | None:
        try:
            row_id = await recommend_velocity(
                self.db,
                row.robot_id,
                source=row.source,
                priority=row.priority,
                linear=row.linear,
                angular=row.angular,
                stamp=row.stamp,
                ttl_s=row.ttl_s,
                reason=row.reason,
                inputs=dict(row.inputs),
            )
        except _REFUSED as exc:
            # the first line only: the rest (DETAIL: the failing row) changes every time, and
            # the engine logs each distinct message once
            first = str(exc).splitlines()[0] if str(exc) else ""
            refusals.append(f"{row.source} for {row.robot_id}: {type(exc).__name__}: {first}")
            return None
        self.statements += 1
        self.rows += 1
        return row_id
