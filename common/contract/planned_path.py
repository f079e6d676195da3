"""The planned_path table (migration 6): the route the planner follows for a robot, as a
typed record, with its read and its write. Writer: the planner; readers: local controllers
(they score trajectories against it), the dashboard, recorders (CONTRACT.md)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from common.contract import keys
from common.contract.records import Executor
from common.db import ASYNC_COMMIT, Database


@dataclass(frozen=True)
class PlannedPath:
    """A planned_path row: the route in force for a robot (no points: the planner has none)."""

    id: int
    robot_id: str
    stamp: float
    goal_id: int | None
    target: str  # "goal", "charger" or "none"
    target_x: float | None
    target_y: float | None
    xs: tuple[float, ...]
    ys: tuple[float, ...]
    length_m: float

    @property
    def empty(self) -> bool:
        return not self.xs


PLANNED_PATH_COLUMNS = (
    *("robot_id", "stamp", "goal_id", "target", "target_x", "target_y"),
    *("xs", "ys", "length_m"),
)
_PLANNED_PATH = (
    "SELECT id, " + ", ".join(PLANNED_PATH_COLUMNS) + " FROM planned_path "
    "WHERE robot_id = $1 ORDER BY id DESC LIMIT 1"
)
_WRITE_PLANNED_PATH = (
    "INSERT INTO planned_path (" + ", ".join(PLANNED_PATH_COLUMNS) + ") "
    "SELECT $1::text, $2::float8, $3::bigint, $4::text, $5::float8, $6::float8, $7::float8[], "
    f"$8::float8[], $9::float8 FROM {ASYNC_COMMIT} RETURNING id"
)


def _optional(value: Any) -> float | None:
    return None if value is None else float(value)


def planned_path_of(image: Mapping[str, Any]) -> PlannedPath:
    """The :class:`PlannedPath` of a planned_path row (a query's record or a row image)."""
    goal_id = image["goal_id"]
    return PlannedPath(
        id=int(image["id"]),
        robot_id=image["robot_id"],
        stamp=float(image["stamp"]),
        goal_id=None if goal_id is None else int(goal_id),
        target=str(image["target"]),
        target_x=_optional(image["target_x"]),
        target_y=_optional(image["target_y"]),
        xs=tuple(float(v) for v in image["xs"]),
        ys=tuple(float(v) for v in image["ys"]),
        length_m=float(image["length_m"]),
    )


async def newest_planned_path(db: Executor, robot_id: str) -> PlannedPath | None:
    row = await db.fetchrow(_PLANNED_PATH, robot_id)
    return None if row is None else planned_path_of(dict(row))


async def write_planned_path(db: Database, path: Mapping[str, Any]) -> int:
    """Insert a planned_path row (``path``: its PLANNED_PATH_COLUMNS) and notify, with the
    row's image; its id."""
    args = [path[c] for c in PLANNED_PATH_COLUMNS]
    image = dict(zip(PLANNED_PATH_COLUMNS, args, strict=True))
    value = await db.write(
        keys.PLANNED_PATH, path["robot_id"], _WRITE_PLANNED_PATH, *args, image=image
    )
    return int(value)
