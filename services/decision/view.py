"""What the decision rules see of the contract: a Protocol, no pool, no service.

:class:`~services.decision.store.DecisionStore` implements it on Postgres in the service and
on the in-memory contract in the monolith (pnav.monolith.memory_decision); a test may implement it
with anything. The rules import this module and the pure ``arbitration`` only.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from common.contract.recommendations import Recommendation
from services.decision.arbitration import Issued, RobotDecision, SystemDecision


class DecisionView(Protocol):
    """What the decision rules see of the contract: no pool, no service."""

    def sim_now(self) -> float | None:
        """Sim time now, or None while the sim clock has not been heard."""
        ...

    async def live(self, now: float) -> dict[str, list[Recommendation]]:
        """The live recommendations of the robots this replica owns that are due a look
        (their recommendations changed, or their re-issue is due), by robot id."""
        ...

    def owns(self, robot_id: str) -> bool:
        """Whether this replica acts for ``robot_id`` now (always, without replicas)."""
        ...

    def issued(self, robot_id: str) -> Issued | None:
        """The newest command2robot row of ``robot_id`` (None: none to carry on from)."""
        ...

    async def write_robot_commands(self, ds: Sequence[RobotDecision]) -> list[int | None]:
        """One command2robot row per decision (one robot each), in one commit; the ids in
        order (None: the row was refused). The store remembers each as issued."""
        ...

    async def write_system_command(self, d: SystemDecision) -> int: ...
