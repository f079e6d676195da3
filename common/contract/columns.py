"""Typed declarations of a contract table's columns, and the bounds of each (a Column and a
Table, as SQLAlchemy Core declares them), for holding a row image to the table's rules.

common.contract.tables declares the contract's tables with these; this module only knows how
to say why a value or an image breaks a declaration.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, Final

import numpy as np

from common.contract.grants import Grant, contract_grants

# Column types, as a row image carries them (msgpack): what a reader may expect in each.
ID: Final = "id"  # a bigserial: an int >= 1 (the sequences start at 1 and only grow)
INT: Final = "int"
FLOAT: Final = "float"
TEXT: Final = "text"
BOOL: Final = "bool"
JSON: Final = "json"  # a jsonb object: a map
FLOATS: Final = "float[]"  # double precision[] or real[]: an array of numbers (or packed bytes)
INTS: Final = "int[]"  # bigint[]
TIMESTAMP: Final = "timestamp"  # timestamptz: filled by the database, never in an image

# The Postgres type of each image type, unless a column says otherwise (``Column.sql``).
SQL_TYPES: Final = {
    ID: "bigint",
    INT: "integer",
    FLOAT: "double precision",
    TEXT: "text",
    BOOL: "boolean",
    JSON: "jsonb",
    FLOATS: "double precision[]",
    INTS: "bigint[]",
    TIMESTAMP: "timestamp with time zone",
}

ROBOT_ID: Final = re.compile(r"^[A-Za-z0-9_-]+$")  # robot.robot_id's CHECK


@dataclass(frozen=True)
class Column:
    """One column: its image type, whether it may be NULL, and its bounds.

    ``low``/``high`` bound a number (inclusive, or exclusive with ``low_open``/``high_open``;
    an ``abs_high`` bounds ``|v|``); ``finite`` refuses NaN and +-Infinity (``is_finite``);
    ``choices`` lists the only texts accepted. ``checks``: the constraints that enforce them
    in the database, empty for a rule of the table's documented writer (see the module).
    ``sql``: its Postgres type where it is not the image type's (:data:`SQL_TYPES`);
    ``inserted``: a writer's INSERT names it (False: the database gives its value, as the
    id's sequence or a default clock, or a later UPDATE does).
    """

    name: str
    type: str
    nullable: bool = False
    finite: bool = False
    low: float | None = None
    low_open: bool = False
    high: float | None = None
    abs_high: float | None = None
    choices: tuple[str, ...] = ()
    pattern: re.Pattern[str] | None = None
    checks: tuple[str, ...] = ()
    sql: str = ""
    inserted: bool = True

    @property
    def sql_type(self) -> str:
        """Its Postgres type, as ``format_type`` names it."""
        return self.sql or SQL_TYPES[self.type]

    def refusal(self, value: Any) -> str | None:
        """Why ``value`` breaks this column's rules (None: it keeps them)."""
        if value is None:
            return None if self.nullable else "NULL"
        if not _typed(self.type, value):
            return f"not {self.type}: {type(value).__name__}"
        if self.type in (ID, INT, FLOAT):
            return self._number(float(value))
        if self.choices and value not in self.choices:
            return f"{value!r} not one of {', '.join(self.choices)}"
        if self.pattern is not None and not self.pattern.match(value):
            return f"{value!r} does not match {self.pattern.pattern}"
        return None

    def _number(self, v: float) -> str | None:
        if self.type == ID and v < 1:
            return f"{v:g}: an id is >= 1"
        if (self.finite or self.abs_high is not None) and not math.isfinite(v):
            return f"{v!r} is not finite"
        if math.isnan(v) and (self.low is not None or self.high is not None):
            return "NaN"
        if self.low is not None and (v <= self.low if self.low_open else v < self.low):
            return f"{v!r} below {self.low!r}"
        if self.high is not None and v > self.high:
            return f"{v!r} above {self.high!r}"
        if self.abs_high is not None and abs(v) > self.abs_high:
            return f"|{v!r}| above {self.abs_high!r}"
        return None


@dataclass(frozen=True)
class Rule:
    """A rule over several columns of one row (a table CHECK, or the writer's rule when
    ``checks`` is empty). ``holds(image)`` is only asked of an image whose columns each
    kept their own rules. ``refuses``/``accepts``: changes to a valid row that break the
    rule and that keep it, which the database test applies to the live table."""

    says: str
    holds: Callable[[Mapping[str, Any]], bool]
    checks: tuple[str, ...] = ()
    refuses: tuple[Mapping[str, Any], ...] = ()
    accepts: tuple[Mapping[str, Any], ...] = ()


@dataclass(frozen=True)
class Table:
    """A contract table: its columns in image order, and the rules across them."""

    name: str
    columns: tuple[Column, ...]
    rules: tuple[Rule, ...] = field(default=())

    @property
    def inserted(self) -> tuple[Column, ...]:
        """The columns a writer's INSERT names, in order (the row image's, without ``id``)."""
        return tuple(c for c in self.columns if c.inserted)

    @property
    def selected(self) -> tuple[str, ...]:
        """The row image's columns, what a reader selects: ``id`` and the inserted ones."""
        return tuple(c.name for c in self.columns if c.inserted or c.name == "id")

    def column(self, name: str) -> Column:
        for column in self.columns:
            if column.name == name:
                return column
        raise KeyError(name)

    def writers(self, grants: tuple[Grant, ...] | None = None) -> frozenset[str]:
        """The roles that may INSERT its rows (CONTRACT.md *Roles*): its documented writers."""
        return frozenset(
            g.role
            for g in (grants or contract_grants())
            if g.name == self.name and not g.is_function and g.privilege == "INSERT"
        )

    def refusal(self, image: Mapping[str, Any], robot: str | None) -> str | None:
        """Why ``image`` could not be a row of this table announced on ``robot``'s key
        (None: it could). A column the image leaves out is not judged here (the reader that
        needs it finds it missing); ``robot_id``, where the table has one, must be there
        and be the key's robot."""
        for column in self.columns:
            if column.name not in image:
                if column.name == "robot_id":
                    return "robot_id: missing"
                continue
            why = column.refusal(image[column.name])
            if why is not None:
                return f"{column.name}: {why}"
        if any(c.name == "robot_id" for c in self.columns) and image["robot_id"] != robot:
            return f"robot_id {image['robot_id']!r} on the key of robot {robot!r}"
        for rule in self.rules:
            try:
                holds = rule.holds(image)
            except (KeyError, TypeError, ValueError):
                holds = False
            if not holds:
                return rule.says
        return None


def _typed(kind: str, value: Any) -> bool:
    if kind in (ID, INT):
        return type(value) is int
    if kind == FLOAT:
        return isinstance(value, float | int) and not isinstance(value, bool)
    if kind == TEXT:
        return isinstance(value, str)
    if kind == BOOL:
        return isinstance(value, bool)
    if kind == JSON:
        return isinstance(value, dict)
    if kind == TIMESTAMP:
        return isinstance(value, datetime)
    if kind == INTS:
        return isinstance(value, list | tuple) and all(type(v) is int for v in value)
    if kind == FLOATS:
        if isinstance(value, bytes | bytearray | memoryview):
            return len(value) % 4 == 0  # a real[] packed as float32 (records.laser_scan_of)
        if isinstance(value, np.ndarray):  # an in-process writer's (pnav.monolith)
            return value.ndim == 1 and value.dtype.kind in "fi"
        return isinstance(value, list | tuple) and all(
            isinstance(v, float | int) and not isinstance(v, bool) for v in value
        )
    return False
