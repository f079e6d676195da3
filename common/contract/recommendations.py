"""Writing command_recommendation rows: one at a time, or a batch in one statement.

Every row is written with its image (CONTRACT.md "Row images": the columns as written, with
its ``id``), notified after the commit, so the decision service keeps the live rows without
reading them back. A batch (:func:`write_recommendations`) is one INSERT for rows of many
robots and scenarios, one commit, then one notification per row: what a store that defers
its rules' writes to the end of an activation sends (docs/ARCHITECTURE.md: batching across
robots; common.writebehind).
"""

from __future__ import annotations

import functools
import json
import logging
from collections.abc import Awaitable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, NotRequired, TypedDict, Unpack

from common.contract import keys, tables
from common.db import ASYNC_COMMIT, Database, batch_or_each

logger = logging.getLogger("pnav.contract")

# the columns a recommendation is written with, in Recommendation's order: its image, as
# the table's declaration lists them
RECOMMENDATION_COLUMNS: Final = tuple(c.name for c in tables.COMMAND_RECOMMENDATION.inserted)
_TYPES = [c.sql_type for c in tables.COMMAND_RECOMMENDATION.inserted]
_INPUTS = RECOMMENDATION_COLUMNS.index("inputs")

_RECOMMEND = f"""
INSERT INTO command_recommendation ({", ".join(RECOMMENDATION_COLUMNS)})
SELECT {", ".join(f"${i}::{t}" for i, t in enumerate(_TYPES, 1))}
  FROM {ASYNC_COMMIT}
RETURNING id
"""
# RETURNING's rows are paired with the batch's by (robot_id, source), which a batch holds
# once each (common.writebehind splits a batch that would not); inputs go as JSON text, so
# the jsonb codec is not asked to encode an array of them.
_CAST = ", ".join(f"u.{name}::{t}" for name, t in zip(RECOMMENDATION_COLUMNS, _TYPES, strict=True))
# inputs go as JSON text (see below)
_ARRAYS = ", ".join(f"${i}::{'text' if t == 'jsonb' else t}[]" for i, t in enumerate(_TYPES, 1))
_RECOMMEND_MANY = f"""
INSERT INTO command_recommendation ({", ".join(RECOMMENDATION_COLUMNS)})
SELECT {_CAST}
FROM unnest({_ARRAYS})
     AS u({", ".join(RECOMMENDATION_COLUMNS)}), {ASYNC_COMMIT}
RETURNING id, robot_id, source
"""


class _Said(TypedDict):
    """What every recommendation a scenario makes says besides its robot and its advice."""

    source: str
    priority: int
    stamp: float  # sim time it was decided at
    ttl_s: float  # valid until stamp + ttl_s
    reason: str
    inputs: NotRequired[dict[str, Any] | None]  # the rows it was derived from


class VelocityFields(_Said):
    """The keywords of a velocity recommendation (:meth:`Recommendation.velocity`, and
    every writer that takes them on: :func:`recommend_velocity`, the planner's view)."""

    linear: float
    angular: float


class SystemFields(_Said):
    """The keywords of a system recommendation (:meth:`Recommendation.system`)."""

    command: str


@dataclass(frozen=True)
class Recommendation:
    """A command_recommendation row: its contract columns, in the order of
    :data:`RECOMMENDATION_COLUMNS`. The one type every writer uses (the controller, the
    planner, their scenarios and the monolith; a scenario makes it with :meth:`velocity` or
    :meth:`system`) and the decision reads (:meth:`of_row`, with ``id`` and ``treated_by``)."""

    robot_id: str
    kind: str  # 'robot' (a velocity) or 'system' (a system command)
    source: str
    priority: int
    linear_mps: float | None
    angular_rps: float | None
    system_command: str | None
    stamp: float
    expires_stamp: float
    inputs: dict[str, Any]
    reason: str
    # what the table adds to a written row: its id (0 before it is written: the sequences
    # start at 1) and the decision that treated it; not written, so not in values()
    id: int = field(default=0, kw_only=True)
    treated_by: int | None = field(default=None, kw_only=True)

    @classmethod
    def of_row(cls, row: Mapping[str, Any]) -> Recommendation:
        """From a command_recommendation row: a query's record, an in-memory row or a row
        image (CONTRACT.md "Row images": ``treated_by`` is NULL in a row just written)."""
        linear, angular = row.get("linear_mps"), row.get("angular_rps")
        return cls(
            str(row["robot_id"]),
            str(row["kind"]),
            str(row["source"]),
            int(row["priority"]),
            None if linear is None else float(linear),
            None if angular is None else float(angular),
            row.get("system_command"),
            float(row["stamp"]),
            float(row["expires_stamp"]),
            dict(row.get("inputs") or {}),
            str(row.get("reason", "")),
            id=int(row["id"]),
            treated_by=row.get("treated_by"),
        )

    @classmethod
    def velocity(cls, robot_id: str, **f: Unpack[VelocityFields]) -> Recommendation:
        """A robot recommendation valid until ``stamp + ttl_s`` (sim time)."""
        stamp = f["stamp"]
        return cls(
            robot_id, "robot", f["source"], f["priority"], float(f["linear"]),
            float(f["angular"]), None, stamp, stamp + f["ttl_s"], f.get("inputs") or {},
            f["reason"],
        )  # fmt: skip

    @classmethod
    def system(cls, robot_id: str, **f: Unpack[SystemFields]) -> Recommendation:
        """A system recommendation (e.g. CMD_BATTSAVE) valid until ``stamp + ttl_s``."""
        stamp = f["stamp"]
        return cls(
            robot_id, "system", f["source"], f["priority"], None, None, f["command"],
            stamp, stamp + f["ttl_s"], f.get("inputs") or {}, f["reason"],
        )  # fmt: skip

    def values(self) -> tuple[Any, ...]:
        """The columns' values, in :data:`RECOMMENDATION_COLUMNS`' order (no copies)."""
        return (
            self.robot_id, self.kind, self.source, self.priority, self.linear_mps,
            self.angular_rps, self.system_command, self.stamp, self.expires_stamp,
            self.inputs, self.reason,
        )  # fmt: skip

    @property
    def scan_id(self) -> int | None:
        """The laser_scan row it was derived from (``inputs.laser_scan``), if it names one."""
        value = self.inputs.get("laser_scan")
        return value if isinstance(value, int) else None

    def image(self) -> dict[str, Any]:
        """The row's contract columns as written (the notification adds ``id``)."""
        return dict(zip(RECOMMENDATION_COLUMNS, self.values(), strict=True))


def recommendation_key(row: Recommendation) -> tuple[str, str]:
    """(robot, source): what pairs a batch's rows with the ids RETURNING gives, and what a
    store's write-behind outbox keeps one row of (common.writebehind)."""
    return row.robot_id, row.source


async def write_recommendation(db: Database, row: Recommendation) -> int:
    """Write one row and notify with its image; its id."""
    value = await db.write(
        keys.COMMAND_RECOMMENDATION, row.robot_id, _RECOMMEND, *row.values(), image=row.image()
    )
    return int(value)


async def write_recommendations(db: Database, rows: Sequence[Recommendation]) -> list[int | None]:
    """Write ``rows`` (distinct (robot, source) pairs) in one statement and one commit, then
    notify each with its image. Their ids, in order; None for a row the database refused
    (a refused batch is written again row by row; logged)."""
    if not rows:
        return []
    if len(rows) == 1:
        return [await write_recommendation(db, rows[0])]
    columns = [list(column) for column in zip(*(row.values() for row in rows), strict=True)]
    columns[_INPUTS] = [json.dumps(inputs) for inputs in columns[_INPUTS]]
    images = [(row.robot_id, row.image()) for row in rows]

    def batch() -> Awaitable[Sequence[int]]:
        return db.write_rows(
            keys.COMMAND_RECOMMENDATION,
            _RECOMMEND_MANY,
            *columns,
            images=images,
            pair_on=("robot_id", "source"),
        )

    return await batch_or_each(
        rows, batch, functools.partial(write_recommendation, db), "recommendation", logger
    )


async def recommend_velocity(db: Database, robot_id: str, **fields: Unpack[VelocityFields]) -> int:
    """Write a robot recommendation valid until ``stamp + ttl_s`` (sim time) and notify,
    with the row's image; ``fields``: :meth:`Recommendation.velocity`'s keywords."""
    return await write_recommendation(db, Recommendation.velocity(robot_id, **fields))


async def recommend_system(db: Database, robot_id: str, **fields: Unpack[SystemFields]) -> int:
    """Write a system recommendation (e.g. CMD_BATTSAVE) and notify, with the row's image;
    ``fields``: :meth:`Recommendation.system`'s keywords."""
    return await write_recommendation(db, Recommendation.system(robot_id, **fields))
