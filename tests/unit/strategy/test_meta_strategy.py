"""MetaStrategy and its target rules tick by tick, on the in-memory contract with the real
StrategyStore.

Each ``await bench.tick()`` is one engine activation; beside it, the robot's active_strategy
after it (strategy_code, resume_code, source, command_id), the command rows it treated
(table, id, status, reason) and whether it hurried the engine. The meta rule schedules in
one activation and its target rules apply in the next.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import pytest

from common.bus import Notification
from common.contract import keys
from common.engine import Engine
from pnav.monolith.contract import MemoryContract
from pnav.monolith.memory_strategy import strategy_engine, user_command
from pnav.monolith.strategies import shipped_strategies

Active = tuple[str, str | None, str, int | None] | None
Treated = tuple[str, int, str, str]

DEFAULT: Active = ("GOTO_AVOID", None, "default", None)


@dataclass
class Seen:
    """What one activation left behind."""

    active: Active
    treated: list[Treated] = field(default_factory=list)
    hurried: bool = False


class TickEngine(Engine):
    """The engine, with its hurry observed: the test starts every activation itself."""

    def __init__(self) -> None:
        super().__init__(name="strategy")
        self.hurried = False

    def hurry(self) -> None:
        self.hurried = True


class Bench:
    def __init__(self, strategies: tuple[str, ...] | None = None) -> None:
        self.contract = MemoryContract()
        for strategy in shipped_strategies().values():
            if strategies is None or strategy.code in strategies:
                self.contract.insert(keys.STRATEGY, {"code": strategy.code})
        self.contract.insert(keys.ROBOT, {"robot_id": "r1"})
        self.clock = 20.0
        self.engine = TickEngine()
        self.store = strategy_engine(self.contract, self.engine, lambda: self.clock)
        self.contract.listeners.append(
            lambda table, robot, row_id: self.store.note(Notification(table, robot, row_id))
        )
        self._status: dict[tuple[str, int], str] = {}

    def user(self, command: str, argument: str | None = None) -> int:
        return self._remember(
            keys.USER_COMMAND, user_command(self.contract, "r1", command, argument)
        )

    def system(self, command: str) -> int:
        """A system_command row as the decision service writes it."""
        row: dict[str, Any] = {"robot_id": "r1", "command": command, "recommendation_id": None}
        row |= {"considered_ids": [], "reason": "test", "status": "pending", "stamp": 1.0}
        row |= {"status_reason": None, "created_at": datetime.now(UTC), "treated_at": None}
        return self._remember(keys.SYSTEM_COMMAND, self.contract.insert(keys.SYSTEM_COMMAND, row))

    def _remember(self, table: str, row_id: int) -> int:
        self._status[table, row_id] = "pending"
        return row_id

    def active(self) -> Active:
        row = self.contract[keys.ACTIVE_STRATEGY].newest("r1")
        if row is None:
            return None
        return (row["strategy_code"], row["resume_code"], row["source"], row["command_id"])

    def row(self, table: str, row_id: int) -> dict[str, Any]:
        return dict(self.contract[table].by_id[row_id])

    async def tick(self) -> Seen:
        self.engine.hurried = False
        await self.engine.activation()
        treated: list[Treated] = []
        for (table, row_id), status in self._status.items():
            row = self.contract[table].by_id[row_id]
            if row["status"] != status:
                reason = row["reason" if table == keys.USER_COMMAND else "status_reason"]
                treated.append((table, row_id, row["status"], reason))
                self._status[table, row_id] = row["status"]
        return Seen(self.active(), treated, self.engine.hurried)

    async def ready(self) -> None:
        """A new robot gets the default strategy (the start of every story here)."""
        assert await self.tick() == Seen(None, [], True)  # ApplyDefaultStrategy queued
        assert await self.tick() == Seen(DEFAULT)  # written; nothing else pending


async def test_a_user_command_sets_the_strategy() -> None:
    bench = Bench()
    await bench.ready()
    set_id = bench.user("SET_STRATEGY", "GOTO_DIRECT")
    after = ("GOTO_DIRECT", None, "user", set_id)
    assert await bench.tick() == Seen(DEFAULT, [], True)  # ApplyCommand queued
    assert await bench.tick() == Seen(
        after, [(keys.USER_COMMAND, set_id, "accepted", "GOTO_AVOID -> GOTO_DIRECT")]
    )
    row = bench.contract[keys.ACTIVE_STRATEGY].newest("r1")
    assert row is not None and row["stamp"] == 20.0  # stamped with sim time
    assert await bench.tick() == Seen(after)  # nothing pending: nothing scheduled


async def test_battsave_remembers_the_strategy_and_switches_to_charge() -> None:
    bench = Bench()
    await bench.ready()
    save = bench.system("CMD_BATTSAVE")
    charging = ("CHARGE", "GOTO_AVOID", "system", save)
    assert await bench.tick() == Seen(DEFAULT, [], True)
    assert await bench.tick() == Seen(
        charging,
        [(keys.SYSTEM_COMMAND, save, "accepted", "GOTO_AVOID -> CHARGE (resume GOTO_AVOID)")],
    )
    again = bench.user("CMD_BATTSAVE")  # a second save while charging is refused
    assert await bench.tick() == Seen(charging, [], True)
    assert await bench.tick() == Seen(
        charging, [(keys.USER_COMMAND, again, "rejected", "already in CHARGE")]
    )


async def test_resume_goes_back_to_the_remembered_strategy() -> None:
    bench = Bench()
    await bench.ready()
    set_id = bench.user("SET_STRATEGY", "GOTO_DIRECT")
    save = bench.system("CMD_BATTSAVE")
    assert await bench.tick() == Seen(DEFAULT, [], True)  # both queued, in creation order
    assert await bench.tick() == Seen(
        ("CHARGE", "GOTO_DIRECT", "system", save),
        [
            (keys.USER_COMMAND, set_id, "accepted", "GOTO_AVOID -> GOTO_DIRECT"),
            (keys.SYSTEM_COMMAND, save, "accepted", "GOTO_DIRECT -> CHARGE (resume GOTO_DIRECT)"),
        ],
    )
    resume = bench.system("CMD_RESUME")
    assert await bench.tick() == Seen(("CHARGE", "GOTO_DIRECT", "system", save), [], True)
    assert await bench.tick() == Seen(
        ("GOTO_DIRECT", None, "system", resume),
        [(keys.SYSTEM_COMMAND, resume, "accepted", "CHARGE -> GOTO_DIRECT (resumed)")],
    )


async def test_an_unknown_command_is_rejected_with_a_reason_and_changes_nothing() -> None:
    bench = Bench()
    await bench.ready()
    dance = bench.user("DANCE")
    assert await bench.tick() == Seen(DEFAULT, [], True)
    seen = await bench.tick()
    assert seen.active == DEFAULT
    ((table, row_id, status, reason),) = seen.treated
    assert (table, row_id, status) == (keys.USER_COMMAND, dance, "rejected")
    assert reason.startswith("unknown command 'DANCE' (expected one of SET_STRATEGY")
    assert bench.row(keys.USER_COMMAND, dance)["treated_at"] is not None
    assert await bench.tick() == Seen(DEFAULT)  # treated: not looked at again


async def test_a_missing_default_strategy_is_said_once_and_nothing_is_written(
    caplog: pytest.LogCaptureFixture,
) -> None:
    bench = Bench(strategies=("CHARGE", "IDLE"))
    with caplog.at_level(logging.ERROR, logger="pnav.strategy"):
        assert await bench.tick() == Seen(None, [], True)  # ApplyDefaultStrategy queued
        assert await bench.tick() == Seen(None, [], True)  # it found no GOTO_AVOID; again
        assert await bench.tick() == Seen(None, [], True)
    missing = [r for r in caplog.records if "default strategy missing" in r.getMessage()]
    assert len(missing) == 1
