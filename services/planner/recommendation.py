"""A command_recommendation row the planner is about to write (a velocity, or a system
command): what its store's source takes (store.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Recommendation:
    """A command_recommendation row to write: a velocity, or a system ``command``, valid
    from ``stamp`` for ``ttl_s`` (sim s)."""

    robot_id: str
    source: str
    priority: int
    stamp: float
    ttl_s: float
    reason: str
    inputs: dict[str, Any]
    linear: float = 0.0
    angular: float = 0.0
    command: str | None = None  # a system recommendation (no velocity) when set
