"""MetaDecision tick by tick, on the in-memory contract with the real DecisionStore.

Each ``await bench.tick(t)`` is one engine activation at sim time ``t``; beside it, what that
activation wrote (command2robot and system_command rows) and whether it hurried the engine.
The meta rule decides in one activation and its target rules write in the next (they are
queued ahead of its clone, which then sees what they wrote).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest

from common.bus import Notification
from common.contract import keys
from common.engine import Engine
from pnav.monolith.contract import MemoryContract
from pnav.monolith.memory_decision import MemoryDecisionSource, decision_engine
from services.decision.arbitration import REISSUE_PERIOD_S, RobotDecision
from services.decision.scenario import IssueRobotCommand
from services.decision.store import REREAD_S

Command = tuple[Any, ...]

# Whether a Bench's notifications carry row images unless a test says: every tick-by-tick
# test runs both ways (the fixture below), with the same expected rows beside each tick.
_IMAGES = {"on": True}


@pytest.fixture(autouse=True, params=["images", "no images"])
def images(request: pytest.FixtureRequest) -> Iterator[bool]:
    _IMAGES["on"] = request.param == "images"
    yield _IMAGES["on"]
    _IMAGES["on"] = True


# (stamp, source, linear, angular, recommendation_id, considered)


@dataclass
class Seen:
    """What one activation did."""

    commands: list[Command] = field(default_factory=list)
    system: list[Command] = field(default_factory=list)  # (command, recommendation_id, considered)
    hurried: bool = False


class TickEngine(Engine):
    """The engine, with its hurry observed: the test starts every activation itself."""

    def __init__(self) -> None:
        super().__init__(name="decision")
        self.hurried = False
        self.hurried_for: list[str | None] = []

    def hurry(self, robot: str | None = None) -> None:
        self.hurried = True
        self.hurried_for.append(robot)


class Bench:
    """``images``: notifications carry the rows' images (numbered, as a Notifier numbers
    them); without, every one is a bare hint and the store reads the table."""

    def __init__(
        self,
        robots: tuple[str, ...] = ("r1",),
        owned: set[str] | None = None,
        *,
        images: bool | None = None,
    ) -> None:
        self.contract = MemoryContract()
        for robot_id in robots:
            self.contract.insert(keys.ROBOT, {"robot_id": robot_id})
        self.clock: float | None = None
        self.owned = owned
        self.engine = TickEngine()
        self.store = decision_engine(self.contract, self.engine, lambda: self.clock, self.owns)
        self.seqs: dict[tuple[str, str | None], int] = {}
        self.images = _IMAGES["on"] if images is None else images
        self.contract.row_listeners.append(self.notify)
        self._seen = {keys.COMMAND2ROBOT: 0, keys.SYSTEM_COMMAND: 0}

    def notify(
        self, table: str, robot: str | None, row_id: int | None, row: dict[str, Any] | None
    ) -> None:
        seq = self.seqs[(table, robot)] = self.seqs.get((table, robot), 0) + 1
        image = row if self.images else None
        self.store.note(Notification(table, robot, row_id, image, "bench", seq))

    def owns(self, robot_id: str) -> bool:
        return self.owned is None or robot_id in self.owned

    def recommend(
        self,
        source: str,
        priority: int,
        linear: float | None = None,
        angular: float | None = None,
        *,
        command: str | None = None,
        expires: float = 1000.0,
        reason: str = "",
        robot_id: str = "r1",
    ) -> int:
        row: dict[str, Any] = {
            "robot_id": robot_id,
            "kind": "robot" if command is None else "system",
            "source": source,
            "priority": priority,
            "linear_mps": linear,
            "angular_rps": angular,
            "system_command": command,
            "stamp": 10.0,
            "expires_stamp": expires,
            "inputs": {},
            "reason": reason,
            "treated_by": None,
        }
        return self.contract.insert(keys.COMMAND_RECOMMENDATION, row)

    def rows(self, table: str) -> list[dict[str, Any]]:
        """In the order written (the in-memory table lists them robot by robot)."""
        return sorted(self.contract[table].all_rows(), key=lambda r: int(r["id"]))

    def treated_by(self, *ids: int) -> list[int | None]:
        by_id = self.contract[keys.COMMAND_RECOMMENDATION].by_id
        return [by_id[i]["treated_by"] for i in ids]

    async def tick(self, now: float | None) -> Seen:
        self.clock = now
        self.engine.hurried = False
        self.engine.hurried_for = []
        await self.engine.activation()
        commands = self._new(keys.COMMAND2ROBOT)
        system = self._new(keys.SYSTEM_COMMAND)
        return Seen(
            [
                (
                    r["stamp"],
                    r["source"],
                    r["linear_mps"],
                    r["angular_rps"],
                    r["recommendation_id"],
                    tuple(r["considered_ids"]),
                )
                for r in commands
            ],
            [(r["command"], r["recommendation_id"], tuple(r["considered_ids"])) for r in system],
            self.engine.hurried,
        )

    def written_elsewhere(self) -> list[Command]:
        """Rows another writer added since the last tick (not this engine's doing)."""
        return [(r["stamp"], r["source"]) for r in self._new(keys.COMMAND2ROBOT)]

    def _new(self, table: str) -> list[dict[str, Any]]:
        rows = self.rows(table)
        new, self._seen[table] = rows[self._seen[table] :], len(rows)
        return new


async def test_the_higher_priority_wins_and_the_row_says_why() -> None:
    bench = Bench()
    low = bench.recommend("turn_then_move", 10, 0.2, 0.0)
    high = bench.recommend("avoid_left", 50, 0.05, 0.8, reason="wall 0.3 m on the left")
    both = (low, high)
    #                     written this activation                                  hurried
    assert await bench.tick(10.0) == Seen([], [], True)  # decided: IssueRobotCommand queued
    assert await bench.tick(10.0) == Seen([(10.0, "avoid_left", 0.05, 0.8, high, both)])
    (row,) = bench.rows(keys.COMMAND2ROBOT)
    assert (
        row["reason"] == "avoid_left (priority 50) over turn_then_move (10): wall 0.3 m on the left"
    )
    assert bench.treated_by(low, high) == [row["id"], row["id"]]
    assert await bench.tick(10.05) == Seen()  # same winner, within REISSUE_PERIOD_S: silence


async def test_an_expired_recommendation_is_ignored() -> None:
    bench = Bench()
    high = bench.recommend("safety_stop", 100, 0.0, 0.0, expires=10.5)
    low = bench.recommend("turn_then_move", 10, 0.2, 0.1)
    assert await bench.tick(10.0) == Seen([], [], True)
    assert await bench.tick(10.0) == Seen([(10.0, "safety_stop", 0.0, 0.0, high, (high, low))])
    assert await bench.tick(10.5) == Seen([], [], True)  # high expired (expires_stamp = now)
    assert await bench.tick(10.5) == Seen([(10.5, "turn_then_move", 0.2, 0.1, low, (low,))])
    assert bench.rows(keys.COMMAND2ROBOT)[-1]["reason"] == "turn_then_move (priority 10) unopposed"


async def test_the_winner_is_reissued_every_reissue_period() -> None:
    assert REISSUE_PERIOD_S == 0.1
    bench = Bench()
    rec = bench.recommend("turn_then_move", 10, 0.2, 0.0)
    assert await bench.tick(10.0) == Seen([], [], True)
    assert await bench.tick(10.0) == Seen([(10.0, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    assert await bench.tick(10.05) == Seen()  # 0.05 s since the last row: not due
    assert await bench.tick(10.1) == Seen([], [], True)  # 0.1 s: due again
    assert await bench.tick(10.1) == Seen([(10.1, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    assert await bench.tick(10.15) == Seen()
    assert await bench.tick(10.2) == Seen([], [], True)
    assert await bench.tick(10.2) == Seen([(10.2, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    assert await bench.tick(3.0) == Seen([], [], True)  # sim time went back: the sim restarted
    assert await bench.tick(3.0) == Seen([(3.0, "turn_then_move", 0.2, 0.0, rec, (rec,))])


async def test_nothing_live_gives_one_stop_row_then_silence() -> None:
    bench = Bench()
    assert await bench.tick(10.0) == Seen()  # never commanded: nothing to stop
    rec = bench.recommend("turn_then_move", 10, 0.2, 0.0, expires=10.3)
    assert await bench.tick(10.0) == Seen([], [], True)
    assert await bench.tick(10.0) == Seen([(10.0, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    assert await bench.tick(10.3) == Seen([], [], True)  # expired: a stop is due
    assert await bench.tick(10.3) == Seen([(10.3, None, 0.0, 0.0, None, ())])
    assert bench.rows(keys.COMMAND2ROBOT)[-1]["reason"] == "no live recommendation"
    assert await bench.tick(10.4) == Seen()  # stopped already: no second stop
    assert await bench.tick(11.0) == Seen()  # longer than the bridge's watchdog: still none


async def test_a_system_recommendation_becomes_one_system_command() -> None:
    bench = Bench()
    save = bench.recommend("battery_check", 60, command="CMD_BATTSAVE", expires=10.5)
    resume = bench.recommend("charge_complete", 50, command="CMD_RESUME")
    assert await bench.tick(10.0) == Seen([], [], True)  # IssueSystemCommand queued
    assert await bench.tick(10.0) == Seen([], [("CMD_BATTSAVE", save, (save, resume))])
    (row,) = bench.rows(keys.SYSTEM_COMMAND)
    assert (row["status"], row["stamp"]) == ("pending", 10.0)
    assert row["reason"].startswith("battery_check (priority 60) over charge_complete (50)")
    assert bench.treated_by(save, resume) == [row["id"], row["id"]]
    assert await bench.tick(10.3) == Seen()  # the winner is treated: not sent again
    assert await bench.tick(11.0) == Seen()  # it expired; the CMD_RESUME it beat was consumed
    fresh = bench.recommend("charge_complete", 50, command="CMD_RESUME")
    assert await bench.tick(11.0) == Seen([], [], True)
    assert await bench.tick(11.0) == Seen([], [("CMD_RESUME", fresh, (resume, fresh))])
    assert bench.rows(keys.COMMAND2ROBOT) == []  # system recommendations never move the robot


async def test_a_robot_regained_from_another_replica_carries_on_from_the_table() -> None:
    bench = Bench(owned=set())  # another replica holds r1
    assert await bench.tick(10.0) == Seen()  # first look: the table read; r1 is not ours
    rec = bench.recommend("turn_then_move", 10, 0.2, 0.0)
    assert await bench.tick(10.0) == Seen()  # not ours: nothing decided
    # ... the other replica decides it (its own store, the same table)
    other = MemoryDecisionSource(bench.contract)
    await other.write_robot_command(
        RobotDecision("r1", 10.0, 0.2, 0.0, rec, "turn_then_move", (rec,), "theirs")
    )
    assert bench.written_elsewhere() == [(10.0, "turn_then_move")]
    bench.owned = {"r1"}
    bench.store.on_ownership_change(frozenset({"r1"}), frozenset())
    assert await bench.tick(10.05) == Seen()  # carries on from their row: not due yet
    assert await bench.tick(10.1) == Seen([], [], True)  # a period after their row
    assert await bench.tick(10.1) == Seen([(10.1, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    bench.owned = set()
    bench.store.on_ownership_change(frozenset(), frozenset({"r1"}))
    assert await bench.tick(10.2) == Seen()  # given up: nothing more from this replica


class GainDuringRead:
    """The bench's source, with a hook run while a read of the live recommendations is
    under way (between the query going out and its rows coming back)."""

    def __init__(self, source: Any) -> None:
        self.source = source
        self.during_read: list[Any] = []

    async def live_recommendations(self, now: float) -> Any:
        read = await self.source.live_recommendations(now)
        while self.during_read:
            self.during_read.pop(0)()
        return read

    def __getattr__(self, name: str) -> Any:
        return getattr(self.source, name)


async def test_a_robot_gained_while_the_table_is_read_is_caught_up_before_it_is_decided() -> None:
    bench = Bench(owned=set())  # another replica holds r1
    source = bench.store.source = GainDuringRead(bench.store.source)
    assert await bench.tick(10.0) == Seen()  # first look: the table read; r1 is not ours
    rec = bench.recommend("turn_then_move", 10, 0.2, 0.0)
    # the other replica decides it at 10.3 (its own store, the same table), then gives r1
    # back: the lease reports it gained here while this replica's periodic read is under way
    other = MemoryDecisionSource(bench.contract)
    await other.write_robot_command(
        RobotDecision("r1", 10.3, 0.2, 0.0, rec, "turn_then_move", (rec,), "theirs")
    )
    assert bench.written_elsewhere() == [(10.3, "turn_then_move")]

    def gain() -> None:
        bench.owned = {"r1"}
        bench.store.on_ownership_change(frozenset({"r1"}), frozenset())

    source.during_read.append(gain)
    assert await bench.tick(10.3) == Seen()  # carries on from their row: not due yet
    assert await bench.tick(10.35) == Seen()
    assert await bench.tick(10.4) == Seen([], [], True)  # a period after their row
    assert await bench.tick(10.4) == Seen([(10.4, "turn_then_move", 0.2, 0.0, rec, (rec,))])


async def test_a_lease_waiting_for_its_confirmation_does_not_forget_what_was_issued() -> None:
    bench = Bench(owned={"r1"})
    rec = bench.recommend("turn_then_move", 10, 0.2, 0.0)
    assert await bench.tick(10.0) == Seen([], [], True)  # decided; written next activation
    assert await bench.tick(10.0) == Seen([(10.0, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    # the lease's confirmation is late: ``owns`` is false with the lock still held and
    # nothing reported lost; a robot-table hint makes the next look read the table
    bench.owned = set()
    bench.store.note(Notification(keys.ROBOT, None, None))
    assert await bench.tick(10.02) == Seen()  # not acting meanwhile
    bench.owned = {"r1"}  # confirmed again: nothing was gained or lost
    assert await bench.tick(10.04) == Seen()  # its command of 10.0 stands: not issued again
    assert await bench.tick(10.1) == Seen([], [], True)  # re-issued a period after it


async def test_a_robot_given_back_between_its_decision_and_the_write_is_not_written() -> None:
    bench = Bench(robots=("r1", "r2"))
    one = bench.recommend("turn_then_move", 10, 0.2, 0.0, robot_id="r1")
    two = bench.recommend("turn_then_move", 10, 0.3, 0.0, robot_id="r2")
    assert await bench.tick(10.0) == Seen([], [], True)  # both decided; written next activation
    # the lease cycle gives r1 back between the two activations: no activation is under way,
    # so the hand-over does not wait, and r1's next owner decides it from the table
    bench.owned = {"r2"}
    bench.store.on_ownership_change(frozenset(), frozenset({"r1"}))
    assert await bench.tick(10.0) == Seen([(10.0, "turn_then_move", 0.3, 0.0, two, (two,))])
    assert [r["robot_id"] for r in bench.rows(keys.COMMAND2ROBOT)] == ["r2"]  # not r1's
    assert bench.treated_by(one) == [None]  # left for its next owner to consider


async def test_a_system_command_for_a_robot_given_back_before_its_write_is_not_written() -> None:
    bench = Bench()
    bench.recommend("battery_check", 50, command="CMD_CHARGE")
    assert await bench.tick(10.0) == Seen([], [], True)  # decided; written next activation
    bench.owned = set()
    bench.store.on_ownership_change(frozenset(), frozenset({"r1"}))
    assert await bench.tick(10.0) == Seen()  # given back: nothing written
    assert bench.rows(keys.SYSTEM_COMMAND) == []


async def test_nothing_is_decided_before_the_sim_clock_and_the_wait_is_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    bench = Bench()
    bench.recommend("turn_then_move", 10, 0.2, 0.0)
    with caplog.at_level(logging.INFO, logger="pnav.decision"):
        assert await bench.tick(None) == Seen()
        assert await bench.tick(None) == Seen()
    waits = [r for r in caplog.records if "waiting for the sim clock" in r.getMessage()]
    assert len(waits) == 1
    assert await bench.tick(10.0) == Seen([], [], True)


async def test_with_images_the_table_is_read_at_the_first_look_and_at_the_period() -> None:
    bench = Bench(images=True)
    assert REREAD_S == 0.25
    assert await bench.tick(10.0) == Seen()  # first look: the table read
    assert bench.store.reads == 1
    rec = bench.recommend("turn_then_move", 10, 0.2, 0.0)
    assert await bench.tick(10.0) == Seen([], [], True)  # decided from the image
    assert await bench.tick(10.0) == Seen([(10.0, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    assert bench.store.reads == 1  # no read for the new row
    assert await bench.tick(10.1) == Seen([], [], True)  # the re-issue: still no read
    assert await bench.tick(10.1) == Seen([(10.1, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    assert bench.store.reads == 1
    assert await bench.tick(10.25) == Seen([], [], True)  # re-issue due; the period: a read
    assert bench.store.reads == 2


async def test_a_hint_without_image_or_after_a_gap_reads_the_table() -> None:
    bench = Bench(images=True)
    assert await bench.tick(10.0) == Seen()
    assert bench.store.reads == 1
    bench.images = False
    rec = bench.recommend("turn_then_move", 10, 0.2, 0.0)
    assert await bench.tick(10.0) == Seen([], [], True)  # no image: read, then decided
    assert bench.store.reads == 2
    assert await bench.tick(10.0) == Seen([(10.0, "turn_then_move", 0.2, 0.0, rec, (rec,))])
    bench.images = True
    bench.seqs[(keys.COMMAND_RECOMMENDATION, "r1")] += 1  # one notification lost on the way
    high = bench.recommend("avoid_left", 50, 0.05, 0.8)
    assert await bench.tick(10.05) == Seen([], [], True)  # a gap: read, then decided
    assert bench.store.reads == 3
    decided = (10.05, "avoid_left", 0.05, 0.8, high, (rec, high))
    assert await bench.tick(10.05) == Seen([decided])


async def test_only_the_robots_that_changed_or_are_due_are_decided_and_hurried() -> None:
    bench = Bench(("r1", "r2"), images=True)
    one = bench.recommend("turn_then_move", 10, 0.2, 0.0, robot_id="r1")
    assert await bench.tick(10.0) == Seen([], [], True)
    assert bench.engine.hurried_for == ["r1"]
    assert await bench.tick(10.0) == Seen([(10.0, "turn_then_move", 0.2, 0.0, one, (one,))])
    two = bench.recommend("turn_then_move", 10, 0.1, 0.0, robot_id="r2")
    assert await bench.tick(10.05) == Seen([], [], True)
    assert bench.engine.hurried_for == ["r2"]  # r1 neither changed nor is due
    assert await bench.tick(10.05) == Seen([(10.05, "turn_then_move", 0.1, 0.0, two, (two,))])
    assert await bench.tick(10.1) == Seen([], [], True)  # r1's re-issue is due, not r2's
    assert bench.engine.hurried_for == ["r1"]


async def test_robots_decided_in_one_activation_are_written_by_one_rule() -> None:
    bench = Bench(robots=("r1", "r2", "r3"))
    a = bench.recommend("turn_then_move", 10, 0.2, 0.0, robot_id="r1")
    b = bench.recommend("avoid_left", 50, 0.05, 0.8, robot_id="r2")
    b_low = bench.recommend("turn_then_move", 10, 0.2, 0.1, robot_id="r2")
    ran = bench.engine.stats_for(IssueRobotCommand).executed
    #                     written this activation                                  hurried
    assert await bench.tick(10.0) == Seen([], [], True)  # r1 and r2 decided; r3 has nothing
    assert sorted(bench.engine.hurried_for, key=str) == ["r1", "r2"]
    assert await bench.tick(10.0) == Seen(
        [
            (10.0, "turn_then_move", 0.2, 0.0, a, (a,)),  # r1's row
            (10.0, "avoid_left", 0.05, 0.8, b, (b, b_low)),  # r2's row, its own provenance
        ]
    )
    assert bench.engine.stats_for(IssueRobotCommand).executed == ran + 1  # one rule, two rows
    r1, r2 = bench.rows(keys.COMMAND2ROBOT)
    assert (r1["robot_id"], r2["robot_id"]) == ("r1", "r2")
    assert bench.treated_by(a, b, b_low) == [r1["id"], r2["id"], r2["id"]]
    assert await bench.tick(10.05) == Seen()  # both issued: within REISSUE_PERIOD_S, silence
    assert await bench.tick(10.1) == Seen([], [], True)  # both due again
    assert await bench.tick(10.1) == Seen(
        [
            (10.1, "turn_then_move", 0.2, 0.0, a, (a,)),
            (10.1, "avoid_left", 0.05, 0.8, b, (b, b_low)),
        ]
    )
