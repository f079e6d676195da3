"""The decision service's source on the in-memory contract, and its engine for the monolith.

:class:`MemoryDecisionSource` is :class:`~services.decision.store.DecisionSource` over
:class:`~pnav.monolith.contract.MemoryContract`: the same reads and writes as
``PgDecisionSource``'s SQL, typed, with no statement to parse. :func:`decision_engine` seeds
the service's own meta rule on a given engine, behind the service's own
:class:`~services.decision.store.DecisionStore`, so the monolith runs the decision exactly as
the service does, bookkeeping included.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import fields
from datetime import UTC, datetime

from common.contract import keys
from common.contract.recommendations import Recommendation
from common.engine import Engine
from pnav.monolith.contract import MemoryContract, Row, owns_every_robot
from services.decision import meta
from services.decision.arbitration import Issued, RobotDecision, SystemDecision
from services.decision.store import DecisionStore

_KINDS = ("robot", "system")
_ISSUED = tuple(f.name for f in fields(Issued))  # command2robot's columns of those names


class MemoryDecisionSource:
    """The decision's reads and writes on a :class:`MemoryContract`."""

    def __init__(self, contract: MemoryContract) -> None:
        self.contract = contract

    async def live_recommendations(self, now: float) -> dict[str, list[Recommendation]]:
        """As LIVE_SQL: every robot, with its robot and system rows whose expiry is ahead."""
        return {
            robot["robot_id"]: [
                Recommendation.of_row(r)
                for r in self.contract.live_recommendations(robot["robot_id"], now)
                if r["kind"] in _KINDS
            ]
            for robot in self.contract[keys.ROBOT].all_rows()
        }

    async def last_issued(self) -> dict[str, Issued]:
        """As LAST_ISSUED_SQL: each robot's newest command2robot row, if it has one."""
        out: dict[str, Issued] = {}
        for robot in self.contract[keys.ROBOT].all_rows():
            row = self.contract[keys.COMMAND2ROBOT].newest(robot["robot_id"])
            if row is not None:
                out[row["robot_id"]] = Issued(**{name: row[name] for name in _ISSUED})
        return out

    async def write_robot_commands(self, ds: Sequence[RobotDecision]) -> list[int | None]:
        """As WRITE_COMMANDS2ROBOT_SQL: every row and its ``treated_by`` first (one
        statement commits them together), then one notification per robot."""
        written = [self._insert(keys.COMMAND2ROBOT, _command_row(d), d.considered_ids) for d in ds]
        for row_id, row in written:
            self.contract.changed(keys.COMMAND2ROBOT, row["robot_id"], row_id, row)
        return [row_id for row_id, _ in written]

    async def write_robot_command(self, d: RobotDecision) -> int:
        return self._commit(keys.COMMAND2ROBOT, _command_row(d), d.considered_ids)

    async def write_system_command(self, d: SystemDecision) -> int:
        row = {
            "robot_id": d.robot_id,
            "command": d.command,
            "recommendation_id": d.recommendation_id,
            "considered_ids": list(d.considered_ids),
            "reason": d.reason,
            "status": "pending",
            "status_reason": None,
            "stamp": d.stamp,
            "created_at": datetime.now(UTC),
            "treated_at": None,
        }
        return self._commit(keys.SYSTEM_COMMAND, row, d.considered_ids)

    def _commit(self, table: str, row: Row, considered: tuple[int, ...]) -> int:
        """The decision row and ``treated_by`` of what it considered, then the notification
        (as the statement's CTE commits both before ``Database.write`` notifies)."""
        row_id, row = self._insert(table, row, considered)
        self.contract.changed(table, row["robot_id"], row_id, row)
        return row_id

    def _insert(self, table: str, row: Row, considered: tuple[int, ...]) -> tuple[int, Row]:
        row_id = self.contract.insert(table, row, notify=False)
        by_id = self.contract[keys.COMMAND_RECOMMENDATION].by_id
        for rec_id in considered:
            rec = by_id.get(rec_id)
            if rec is not None:  # UPDATE ... WHERE id = ANY(...) skips a missing row too
                rec["treated_by"] = row_id
        return row_id, row


def _command_row(d: RobotDecision) -> Row:
    return {
        "robot_id": d.robot_id,
        "stamp": d.stamp,
        "linear_mps": d.linear_mps,
        "angular_rps": d.angular_rps,
        "recommendation_id": d.recommendation_id,
        "source": d.source,
        "considered_ids": list(d.considered_ids),
        "reason": d.reason,
        "created_at": datetime.now(UTC),
    }


def decision_engine(
    contract: MemoryContract,
    engine: Engine,
    now: Callable[[], float | None],
    owns: Callable[[str], bool] = owns_every_robot,
) -> DecisionStore:
    """Seed the decision's meta rule on ``engine`` as the service does; its store.

    ``now`` is sim time (None: the sim clock is not heard yet); ``owns`` stands for the
    replica's leases (one process owns every robot, unless a test says otherwise). Hand the
    store every change notification (``store.note``) as the service does.
    """
    # the store's period fallback counts sim time too (a run depends on the sim alone)
    store = DecisionStore(MemoryDecisionSource(contract), now, owns, clock=lambda: now() or 0.0)
    meta.seed(engine, store)
    return store
