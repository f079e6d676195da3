"""The timeline: strategy switches, system and user commands, goal changes, per robot.

Events are built from contract rows (goal, user_command, system_command, active_strategy)
and kept in wall-clock order, newest last, bounded. Each has a key naming the row and the
state it reports (``goal:7:reached``), so a row read twice (a notification, then the
periodic re-read) makes one event.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping
from datetime import datetime
from typing import Any

Row = Mapping[str, Any]
Event = dict[str, Any]

KEEP = 300
# the longest argument or reason an event quotes: anyone may write a user_command's argument
TEXT_CHARS = 200


def _short(value: Any) -> str:
    text = str(value)
    return text if len(text) <= TEXT_CHARS else text[: TEXT_CHARS - 3] + "..."


def _epoch(value: Any) -> float:
    return value.timestamp() if isinstance(value, datetime) else time.time()


def goal_event(row: Row, *, seeded: bool = False) -> Event:
    """A goal set, or leaving ``active``; ``seeded``: read at start, placed when it was set
    (the table keeps no wall time of the end)."""
    status = row["status"]
    where = f"({row['x']:.2f}, {row['y']:.2f})"
    text = f"goal {row['id']} {where} " + ("set" if status == "active" else status)
    if row.get("reason") and status != "active":
        text += f": {_short(row['reason'])}"
    return {
        "key": f"goal:{row['id']}:{status}",
        "t": _epoch(row["created_at"]) if status == "active" or seeded else time.time(),
        "robot": row["robot_id"],
        "kind": "goal",
        "text": text,
        "ref": {"table": "goal", "id": row["id"]},
    }


def command_event(table: str, row: Row) -> Event:
    """A user_command or system_command row: one event when written, one when treated."""
    status = row["status"]
    who = "user" if table == "user_command" else "system"
    argument = f" {_short(row['argument'])}" if row.get("argument") else ""
    text = f"{who}: {row['command']}{argument}"
    when = row["created_at"]
    if status != "pending":
        reason = row.get("reason") if table == "user_command" else row.get("status_reason")
        text += f" {status}" + (f": {_short(reason)}" if reason else "")
        when = row.get("treated_at") or when
    elif table == "system_command" and row.get("reason"):
        text += f" ({_short(row['reason'])})"
    return {
        "key": f"{table}:{row['id']}:{status}",
        "t": _epoch(when),
        "robot": row["robot_id"],
        "kind": who,
        "text": text,
        "ref": {"table": table, "id": row["id"]},
    }


def strategy_event(row: Row) -> Event:
    resume = f", resumes {row['resume_code']}" if row.get("resume_code") else ""
    return {
        "key": f"active_strategy:{row['robot_id']}:{_epoch(row['updated_at'])}",
        "t": _epoch(row["updated_at"]),
        "robot": row["robot_id"],
        "kind": "strategy",
        "text": f"strategy {row['strategy_code']} ({row['source']}{resume})",
        "ref": {"table": "active_strategy", "id": row.get("command_id")},
    }


class Timeline:
    """The newest :data:`KEEP` events; :meth:`add` says whether an event is new."""

    def __init__(self, keep: int = KEEP) -> None:
        self._events: deque[Event] = deque(maxlen=keep)
        self._keys: set[str] = set()
        self._fresh: list[Event] = []

    def add(self, event: Event) -> bool:
        if event["key"] in self._keys:
            return False
        if len(self._events) == self._events.maxlen:
            self._keys.discard(self._events[0]["key"])
        self._events.append(event)
        self._keys.add(event["key"])
        self._fresh.append(event)
        return True

    def seed(self, events: list[Event]) -> None:
        """Events read at start, in any order: kept in time order, none reported fresh."""
        for event in sorted(events, key=lambda e: e["t"]):
            self.add(event)
        self._fresh.clear()

    def events(self) -> list[Event]:
        return list(self._events)

    def take_fresh(self) -> list[Event]:
        """Events added since the last call (to push to the browsers)."""
        fresh, self._fresh = self._fresh, []
        return fresh
