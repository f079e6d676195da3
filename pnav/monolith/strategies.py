"""The shipped strategy rows, read from the contract's own schema.sql.

In the stack the strategy table is filled by the contract's migrations; the monolith has no
Postgres to run them, so it reads the ``INSERT INTO strategy`` statements of schema.sql
instead of keeping a copy of the rows that could drift from them. A migration that merges
params into a row (``UPDATE strategy SET params = params || '{...}' WHERE code = '...'``) is
applied in its place among the inserts; any other update, and any delete, of strategy rows is
refused here rather than ignored.

A benchmark combo is the shipped strategy with another planner scenario, under the code
``Combo.code``: what ``pnav.bench.nav.stack_episode.ensure_combo`` inserts in the stack.
"""

from __future__ import annotations

import json
import re
from dataclasses import replace
from typing import Any

from common.contract import records
from common.contract.migrate import schema_text
from pnav.bench.nav.stack_episode import Combo
from pnav.monolith.contract import AdapterError

_TOKEN = re.compile(r"\s+|--[^\n]*|'(?:[^']|'')*'|NULL|-?\d+(?:\.\d+)?|[(),;]|[^\s(),;']+")
_INSERT = re.compile(r"INSERT INTO strategy\s*\(([^)]*)\)\s*VALUES", re.IGNORECASE)
_CHANGE = re.compile(r"\b(UPDATE\s+strategy|DELETE\s+FROM\s+strategy)\b", re.IGNORECASE)
# the one change the monolith follows: params merged into a shipped row, by its code
_MERGE = re.compile(
    r"UPDATE\s+strategy\s+SET\s+params\s*=\s*params\s*\|\|\s*'((?:[^']|'')*)'\s+"
    r"WHERE\s+code\s*=\s*'([^']*)'[^;]*;",
    re.IGNORECASE,
)


def shipped_strategies(schema: str | None = None) -> dict[str, records.Strategy]:
    """Strategy code -> row, as the contract's migrations insert them."""
    text = schema_text() if schema is None else schema
    merges = {m.start(): m for m in _MERGE.finditer(text)}
    for change in _CHANGE.finditer(text):
        if change.start() not in merges:
            raise AdapterError(
                f"schema.sql changes strategy rows ({change[0]!r}): teach "
                "pnav/monolith/strategies.py"
            )
    out: dict[str, records.Strategy] = {}
    steps = sorted([*((m.start(), m) for m in _INSERT.finditer(text)), *merges.items()])
    for _, step in steps:
        if step.re is _MERGE:
            code, more = step[2], json.loads(step[1].replace("''", "'"))
            if code in out:  # a row the statement's WHERE finds
                out[code] = replace(out[code], params={**out[code].params, **more})
            continue
        columns = [c.strip() for c in step[1].split(",")]
        for values in _tuples(text, step.end()):
            row = dict(zip(columns, values, strict=True))
            out[str(row["code"])] = records.Strategy(
                code=str(row["code"]),
                planner_scenario=row.get("planner_scenario"),
                controller_scenarios=_array(row.get("controller_scenarios") or "{}"),
                params=json.loads(row.get("params") or "{}"),
            )
    if not out:
        raise AdapterError("schema.sql inserts no strategy rows")
    return out


def combo_strategy(
    combo: Combo, shipped: dict[str, records.Strategy] | None = None
) -> records.Strategy:
    """The strategy row a combo runs: its shipped strategy with the combo's planner."""
    rows = shipped_strategies() if shipped is None else shipped
    base = rows.get(combo.strategy)
    if base is None:
        raise AdapterError(
            f"no shipped strategy {combo.strategy!r} (have {', '.join(sorted(rows))})"
        )
    return replace(base, code=combo.code, planner_scenario=combo.planner)


def _tuples(text: str, start: int) -> list[list[Any]]:
    """The ``(v, ...), (v, ...);`` list of literals that starts at ``start``."""
    tuples: list[list[Any]] = []
    current: list[Any] | None = None
    for m in _TOKEN.finditer(text, start):
        token = m[0]
        if token.isspace() or token.startswith("--") or token == ",":
            continue
        if token == ";":
            return tuples
        if token == "(":
            current = []
        elif token == ")":
            if current is None:
                break
            tuples.append(current)
            current = None
        elif current is None:
            break
        elif token == "NULL":
            current.append(None)
        elif token.startswith("'"):
            current.append(token[1:-1].replace("''", "'"))
        else:
            raise AdapterError(f"schema.sql: unexpected {token!r} in the strategy rows")
    raise AdapterError("schema.sql: the strategy INSERT is not a plain list of literal rows")


def _array(literal: str) -> tuple[str, ...]:
    """A Postgres text[] literal of plain words, ``{a,b}``."""
    inner = literal.strip()
    if not (inner.startswith("{") and inner.endswith("}")):
        raise AdapterError(f"schema.sql: {literal!r} is not an array literal")
    return tuple(part.strip() for part in inner[1:-1].split(",") if part.strip())
