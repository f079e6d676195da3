"""A command_recommendation row the planner is about to write (a velocity, or a system
command): what its store's source takes (store.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from common.contract.recommendations import RecommendationRow


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

    def row(self) -> RecommendationRow:
        """The command_recommendation row it is written as."""
        fields: dict[str, Any] = {
            "source": self.source,
            "priority": self.priority,
            "stamp": self.stamp,
            "ttl_s": self.ttl_s,
            "reason": self.reason,
            "inputs": self.inputs,
        }
        if self.command is None:
            return RecommendationRow.velocity(
                self.robot_id, linear=self.linear, angular=self.angular, **fields
            )
        return RecommendationRow.system(self.robot_id, command=self.command, **fields)
