"""The statements the navigation services issue, answered from :class:`MemoryContract`.

:class:`MemoryPool` has the three asyncpg calls the services use (``fetch``, ``fetchrow``,
``fetchval``) and ``acquire()`` (``Database.write`` runs its statement on an acquired
connection). Its coroutines never suspend, so the engine's activations run to completion
without an event loop (see ``engines.run_sync``).

Two kinds of statement are understood:

- a plain single-table ``SELECT col, ... FROM t [WHERE c = $n AND c = 'x'] [ORDER BY c
  [DESC]] [LIMIT n]``, evaluated generically, so that a service reading one more column
  needs no change here;
- the joins and writes below, recognised by their text, imported from the module that
  issues each (``records._RECOMMEND``, ``store.LIVE_SQL``...), each emulated by a handler
  that does what the statement does in Postgres.

Anything else raises :class:`UnsupportedStatement`.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from common.contract import keys, records
from pnav.monolith.contract import MemoryContract, Row, UnsupportedStatement
from services.decision import store
from services.planner import state as planner_state

Plan = Callable[[tuple[Any, ...]], list[Row]]

_SELECT = re.compile(
    r"SELECT (?P<cols>[\w, ]+?) FROM (?P<table>\w+)(?: WHERE (?P<where>.+?))?"
    r"(?: ORDER BY (?P<order>\w+)(?P<desc> DESC)?)?(?: LIMIT (?P<limit>\d+))?"
)
_PARAM = re.compile(r"(\w+) = \$(\d+)")
_LITERAL = re.compile(r"(\w+) = '([^']*)'")
# records.active_strategies: the one join on the read side that is not a module constant
_ACTIVE_STRATEGIES = re.compile(
    r"SELECT (?P<cols>[\w., ]+) FROM active_strategy a JOIN strategy s ON s.code = a.strategy_code"
)


def normalize(sql: str) -> str:
    return " ".join(sql.split())


class MemoryPool:
    def __init__(self, contract: MemoryContract) -> None:
        self.contract = contract
        self._plans: dict[str, Plan] = {}
        self._special: dict[str, Plan] = {
            normalize(records._RECOMMEND): self._recommend,
            normalize(planner_state._MARK_REACHED): self._mark_reached,
            normalize(planner_state._LIVE_SYSTEM): self._live_system,
            normalize(store.LIVE_SQL): self._live,
            normalize(store.LAST_ISSUED_SQL): self._last_issued,
            normalize(store.WRITE_COMMAND2ROBOT_SQL): self._write_command2robot,
            normalize(store.WRITE_SYSTEM_COMMAND_SQL): self._write_system_command,
        }

    # -- the asyncpg surface ------------------------------------------------------------------
    async def fetch(self, sql: str, *args: Any) -> list[Row]:
        return self._plan(sql)(args)

    async def fetchrow(self, sql: str, *args: Any) -> Row | None:
        rows = self._plan(sql)(args)
        return rows[0] if rows else None

    async def fetchval(self, sql: str, *args: Any) -> Any:
        rows = self._plan(sql)(args)
        return next(iter(rows[0].values())) if rows else None

    def acquire(self) -> _Connection:
        return _Connection(self)

    # -- planning a statement -----------------------------------------------------------------
    def _plan(self, sql: str) -> Plan:
        plan = self._plans.get(sql)
        if plan is None:
            plan = self._plans[sql] = self._make_plan(sql)
        return plan

    def _make_plan(self, sql: str) -> Plan:
        text = normalize(sql)
        special = self._special.get(text)
        if special is not None:
            return special
        joined = _ACTIVE_STRATEGIES.fullmatch(text)
        if joined is not None:
            columns = [c.split(".")[-1] for c in joined["cols"].split(", ")]
            return lambda _args: [_project(r, columns) for r in self._active_strategies()]
        match = _SELECT.fullmatch(text)
        if match is None:
            raise UnsupportedStatement(sql)
        return self._select(sql, match)

    def _select(self, sql: str, m: re.Match[str]) -> Plan:
        columns = m["cols"].split(", ")
        table = self.contract.tables.get(m["table"])
        if table is None:
            raise UnsupportedStatement(sql)
        params: list[tuple[str, int]] = []
        literals: list[tuple[str, str]] = []
        for test in m["where"].split(" AND ") if m["where"] else ():
            if p := _PARAM.fullmatch(test):
                params.append((p[1], int(p[2]) - 1))
            elif lit := _LITERAL.fullmatch(test):
                literals.append((lit[1], lit[2]))
            else:
                raise UnsupportedStatement(sql)
        robot_param = next((i for col, i in params if col == "robot_id"), None)
        order, desc = m["order"], bool(m["desc"])
        limit = int(m["limit"]) if m["limit"] else None
        # one robot's rows come in id order already: "newest first, LIMIT 1" stops at one
        presorted = order is None or (order == "id" and robot_param is not None)

        def run(args: tuple[Any, ...]) -> list[Row]:
            if robot_param is not None:  # the (robot_id, id) index
                rows = table.rows(args[robot_param], newest_first=order == "id" and desc)
            else:
                rows = table.all_rows()
            wanted = [(col, args[i]) for col, i in params] + literals
            out: list[Row] = []
            for row in rows:
                if all(row.get(col) == value for col, value in wanted):
                    out.append(row)
                    if presorted and limit is not None and len(out) >= limit:
                        break
            if not presorted:
                out.sort(key=lambda r: r[order], reverse=desc)
            return [_project(r, columns) for r in out[:limit]]

        return run

    # -- the joins ----------------------------------------------------------------------------
    def _active_strategies(self) -> list[Row]:
        strategies = {r["code"]: r for r in self.contract[keys.STRATEGY].all_rows()}
        out = []
        for active in self.contract[keys.ACTIVE_STRATEGY].all_rows():
            strategy = strategies.get(active["strategy_code"])
            if strategy is not None:
                out.append({**strategy, **active})
        return out

    def _live(self, args: tuple[Any, ...]) -> list[Row]:
        """store.LIVE_SQL: per robot, its live robot and system rows (none: one null row)."""
        (now,) = args
        out: list[Row] = []
        for robot in self.contract[keys.ROBOT].all_rows():
            robot_id = robot["robot_id"]
            live = [
                r
                for r in self.contract.live_recommendations(robot_id, now)
                if r["kind"] in ("robot", "system")
            ]
            if not live:
                out.append({"robot_id": robot_id, "id": None})
            out.extend(_project(r, _LIVE_COLUMNS) for r in live)
        return out

    def _last_issued(self, _args: tuple[Any, ...]) -> list[Row]:
        """store.LAST_ISSUED_SQL: each robot's newest command2robot row."""
        out = []
        for robot in self.contract[keys.ROBOT].all_rows():
            newest = self.contract[keys.COMMAND2ROBOT].newest(robot["robot_id"])
            if newest is not None:
                out.append(_project(newest, _ISSUED_COLUMNS))
        return out

    def _live_system(self, args: tuple[Any, ...]) -> list[Row]:
        """planner state._LIVE_SYSTEM: the newest expiry of a live system recommendation."""
        robot_id, command, now = args
        expiries = [
            r["expires_stamp"]
            for r in self.contract.live_recommendations(robot_id, now)
            if r["kind"] == "system" and r["system_command"] == command
        ]
        return [{"max": max(expiries) if expiries else None}]

    # -- the writes (Database.write notifies after them, as after a commit) -------------------
    def _recommend(self, args: tuple[Any, ...]) -> list[Row]:
        names = (
            *("robot_id", "kind", "source", "priority", "linear_mps", "angular_rps"),
            *("system_command", "stamp", "expires_stamp", "inputs", "reason"),
        )
        row = dict(zip(names, args, strict=True))
        row["treated_by"] = None
        return [{"id": self.contract.insert(keys.COMMAND_RECOMMENDATION, row, notify=False)}]

    def _mark_reached(self, args: tuple[Any, ...]) -> list[Row]:
        goal_id, stamp = args
        goal = self.contract[keys.GOAL].by_id.get(goal_id)
        if goal is None or goal["status"] != "active":
            return []
        goal.update(status="reached", finished_stamp=stamp)
        return [{"id": goal_id}]

    def _write_command2robot(self, args: tuple[Any, ...]) -> list[Row]:
        robot_id, stamp, linear, angular, rec_id, source, considered, reason = args
        row = {
            "robot_id": robot_id,
            "stamp": stamp,
            "linear_mps": linear,
            "angular_rps": angular,
            "recommendation_id": rec_id,
            "source": source,
            "considered_ids": list(considered),
            "reason": reason,
        }
        row_id = self.contract.insert(keys.COMMAND2ROBOT, row, notify=False)
        self._treat(considered, row_id)
        return [{"id": row_id}]

    def _write_system_command(self, args: tuple[Any, ...]) -> list[Row]:
        robot_id, command, rec_id, considered, reason, stamp = args
        row = {
            "robot_id": robot_id,
            "command": command,
            "recommendation_id": rec_id,
            "considered_ids": list(considered),
            "reason": reason,
            "status": "pending",
            "stamp": stamp,
        }
        row_id = self.contract.insert(keys.SYSTEM_COMMAND, row, notify=False)
        self._treat(considered, row_id)
        return [{"id": row_id}]

    def _treat(self, considered: list[int], decision_id: int) -> None:
        by_id = self.contract[keys.COMMAND_RECOMMENDATION].by_id
        for rec_id in considered:
            by_id[rec_id]["treated_by"] = decision_id


_LIVE_COLUMNS = ["robot_id", "id", "kind", "source", "priority", "linear_mps", "angular_rps"]
_LIVE_COLUMNS += ["system_command", "reason", "treated_by"]
_ISSUED_COLUMNS = ["robot_id", "id", "stamp", "linear_mps", "angular_rps", "recommendation_id"]
_ISSUED_COLUMNS += ["source"]


def _project(row: Row, columns: list[str]) -> Row:
    try:
        return {c: row[c] for c in columns}
    except KeyError as missing:
        raise UnsupportedStatement(f"no column {missing} in {sorted(row)}") from None


class _Connection:
    """What ``async with pool.acquire() as conn`` gives: the pool itself, no waiting."""

    def __init__(self, pool: MemoryPool) -> None:
        self.pool = pool

    async def __aenter__(self) -> MemoryPool:
        return self.pool

    async def __aexit__(self, *exc: object) -> None:
        return None
