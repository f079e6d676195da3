"""Lockstep: what participants count and report, when the sim's barrier calls the stack quiet,
and the engine's lockstep loop (F on sim time, a report after every quiet moment).

Real Zenoh sessions on a loopback router; the statuses the barrier judges are the bytes a
participant's ledger publishes.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import replace

import pytest

from common import bus
from common.config import EngineSettings, ServiceConfig, ZenohSettings
from common.contract import keys
from common.engine import Engine, Rule
from common.lockstep import Ledger, LockstepTrigger, Status
from common.runtime import Runtime
from common.service import ScenarioService
from pnav._testing import eventually
from services.sim.lockstep_barrier import Barrier

ODOM = keys.robot_key("r1", keys.ODOM)
ODOM_NOTE = keys.notify_key(keys.ODOMETRY, "r1")
CMD_VEL = keys.robot_key("r1", keys.CMD_VEL)


@pytest.fixture
def session(zenoh_settings: ZenohSettings) -> Iterator[object]:
    s = bus.open_session(zenoh_settings)
    try:
        yield s
    finally:
        s.close()


@pytest.fixture
def ledger(session: object) -> Iterator[Ledger]:
    led = Ledger(session, "bridge", "b-1")  # type: ignore[arg-type]
    try:
        yield led
    finally:
        led.close()


def status(seq: int, sent: dict[str, int], subs: list[tuple[str, dict[str, int]]]) -> bytes:
    import msgpack

    payload: bytes = msgpack.packb({"seq": seq, "sent": sent, "subs": [list(s) for s in subs]})
    return payload


# -- the participant's ledger -------------------------------------------------------------------
def test_bus_counts_a_receipt_after_its_handler_and_a_notification_as_sent(
    session: object, ledger: Ledger
) -> None:
    seen: list[int] = []

    def handler(key: str, payload: bytes) -> None:
        seen.append(ledger.mark())  # not counted yet while the handler runs

    sub = bus.subscribe_threaded(session, keys.robot_watch(keys.ODOM), handler, ledger=ledger)  # type: ignore[arg-type]
    try:
        mark = ledger.mark()  # 0
        session.put(ODOM, b"x")  # type: ignore[attr-defined]
        deadline = time.monotonic() + 5
        while ledger.mark() == mark and time.monotonic() < deadline:
            time.sleep(0.01)
        assert seen == [0] and ledger.mark() == 1
        assert ledger.tallies[0].key_expr == keys.robot_watch(keys.ODOM)
        assert ledger.tallies[0].counts == {ODOM: 1}
        assert not ledger.report_if_settled(mark)  # a receipt since the mark: not quiet
        bus.Notifier(session, ledger).notify(keys.ODOMETRY, "r1", 7)  # type: ignore[arg-type]
        assert ledger.sent == {ODOM_NOTE: 1}
    finally:
        sub.undeclare()


def test_a_report_carries_counts_that_decode_to_the_same_status(
    session: object, ledger: Ledger
) -> None:
    got: list[bytes] = []
    watcher = session.declare_subscriber(  # type: ignore[attr-defined]
        keys.LOCKSTEP_WATCH, lambda sample: got.append(sample.payload.to_bytes())
    )
    try:
        tally = ledger.tally(keys.robot_watch(keys.ODOM))
        assert tally is not None
        ledger.received(tally, ODOM)
        ledger.sent_on(ODOM_NOTE)
        assert ledger.report_if_settled(ledger.mark())
        deadline = time.monotonic() + 5
        while not got and time.monotonic() < deadline:
            time.sleep(0.01)
        decoded = Status.decode(got[0])
        assert decoded.seq == 1
        assert decoded.sent == {ODOM_NOTE: 1}
        assert decoded.subs == [(keys.robot_watch(keys.ODOM), {ODOM: 1})]
    finally:
        watcher.undeclare()


def test_a_sender_only_ledger_counts_no_receipts(session: object) -> None:
    led = Ledger(session, "navbench", "n-1", receipts=False)  # type: ignore[arg-type]
    try:
        assert led.tally(keys.SIM_CLOCK) is None
        sub = bus.subscribe_threaded(session, keys.SIM_CLOCK, lambda k, p: None, ledger=led)  # type: ignore[arg-type]
        sub.undeclare()
        assert led.tallies == []
    finally:
        led.close()


def test_only_what_is_handed_the_ledger_counts_on_it(session: object, ledger: Ledger) -> None:
    got: list[str] = []
    counted = bus.subscribe_threaded(
        session,  # type: ignore[arg-type]
        ODOM,
        lambda k, p: got.append("counted"),
        ledger=ledger,
    )
    plain = bus.subscribe_threaded(session, ODOM, lambda k, p: got.append("plain"))  # type: ignore[arg-type]
    try:
        session.put(ODOM, b"x")  # type: ignore[attr-defined]
        deadline = time.monotonic() + 5
        while len(got) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert sorted(got) == ["counted", "plain"]
        assert [t.counts for t in ledger.tallies] == [{ODOM: 1}]
        bus.Notifier(session).notify(keys.ODOMETRY, "r1", 7)  # type: ignore[arg-type]
        assert ledger.sent == {}
    finally:
        counted.undeclare()
        plain.undeclare()


async def test_a_runtime_in_lockstep_counts_the_sim_clock_on_its_ledger(
    zenoh_settings: ZenohSettings,
) -> None:
    config = ServiceConfig(
        service="planner",
        database_url="postgresql://unused",
        zenoh=zenoh_settings,
        instance="p-9",
        lockstep=("planner",),
    )
    runtime = await Runtime.open(config, with_db=False)
    try:
        ledger = runtime.ledger
        assert ledger is not None and ledger.service == "planner"
        runtime.zenoh.put(keys.SIM_CLOCK, bus.pack({"stamp": 1.5, "rate": 0.0}))
        await eventually(lambda: ledger.mark() == 1)
        assert runtime.clock.now() == 1.5  # the clock moved before the receipt counted
        assert [(t.key_expr, t.counts) for t in ledger.tallies] == [
            (keys.SIM_CLOCK, {keys.SIM_CLOCK: 1})
        ]
    finally:
        await runtime.close()
    assert runtime.ledger is None
    plain = await Runtime.open(replace(config, lockstep=()), with_db=False)
    try:
        assert plain.ledger is None
    finally:
        await plain.close()


def test_a_malformed_status_is_refused() -> None:
    with pytest.raises(ValueError):
        Status.decode(b"\x93\x01")


# -- the sim's barrier ----------------------------------------------------------------------------
@pytest.fixture
def barrier(session: object) -> Iterator[Barrier]:
    b = Barrier(session, ("bridge", "planner"), timeout_s=0.3, start_timeout_s=5)  # type: ignore[arg-type]
    try:
        yield b
    finally:
        b.close()


BRIDGE = keys.lockstep_key("bridge", "b-1")
PLANNER = keys.lockstep_key("planner", "p-1")
ODOM_SUBS = keys.robot_watch(keys.ODOM)
NOTE_SUBS = keys.notify_watch(keys.ODOMETRY)


def test_quiet_needs_every_expected_service_to_have_reported(barrier: Barrier) -> None:
    barrier._on_status(BRIDGE, status(1, {}, [(ODOM_SUBS, {})]))
    assert not barrier.quiet()  # planner: never heard of
    barrier._on_status(PLANNER, status(1, {}, [(NOTE_SUBS, {})]))
    assert barrier.quiet()


def test_a_reading_is_in_flight_until_its_whole_chain_of_handling_is_reported(
    barrier: Barrier,
) -> None:
    barrier._on_status(BRIDGE, status(1, {}, [(ODOM_SUBS, {})]))
    barrier._on_status(PLANNER, status(1, {}, [(NOTE_SUBS, {})]))
    barrier.published(ODOM)  # the sim sends a reading
    assert not barrier.quiet()  # bridge: received 0 of 1
    barrier._on_status(BRIDGE, status(2, {ODOM_NOTE: 1}, [(ODOM_SUBS, {ODOM: 1})]))
    assert not barrier.quiet()  # the row's notification: the planner has not handled it
    barrier._on_status(PLANNER, status(2, {}, [(NOTE_SUBS, {ODOM_NOTE: 1})]))
    assert barrier.quiet()


def test_a_receipt_reported_before_its_sender_reports_the_send_is_not_waited_for(
    barrier: Barrier,
) -> None:
    barrier._on_status(BRIDGE, status(1, {}, [(ODOM_SUBS, {})]))
    barrier._on_status(PLANNER, status(1, {}, [(NOTE_SUBS, {ODOM_NOTE: 1})]))
    assert barrier.quiet()  # received more than anyone says was sent: nothing owed


def test_an_older_status_arriving_late_is_ignored(barrier: Barrier) -> None:
    barrier._on_status(BRIDGE, status(1, {}, [(ODOM_SUBS, {})]))
    barrier._on_status(PLANNER, status(1, {}, [(NOTE_SUBS, {})]))
    barrier.published(ODOM)
    barrier._on_status(BRIDGE, status(3, {}, [(ODOM_SUBS, {ODOM: 1})]))
    barrier._on_status(BRIDGE, status(2, {}, [(ODOM_SUBS, {})]))
    assert barrier.quiet()


def test_the_sim_waits_for_the_commands_the_bridge_sent(barrier: Barrier) -> None:
    barrier._on_status(BRIDGE, status(1, {CMD_VEL: 1}, [(ODOM_SUBS, {})]))
    barrier._on_status(PLANNER, status(1, {}, [(NOTE_SUBS, {})]))
    barrier.started = True  # past the start: a cmd_vel is owed to the sim
    assert not barrier.quiet()
    barrier.on_cmd_vel(CMD_VEL)
    assert barrier.quiet()


def test_a_message_still_lacking_in_a_report_half_a_second_later_was_never_received(
    barrier: Barrier, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("services.sim.lockstep_barrier.LOST_AFTER_S", 0.05)
    barrier._on_status(BRIDGE, status(1, {ODOM_NOTE: 3}, [(ODOM_SUBS, {})]))
    barrier.started = True
    barrier._on_status(PLANNER, status(1, {}, [(NOTE_SUBS, {})]))  # subscribed after 3 notes
    assert not barrier.quiet()  # it may yet get them: a report a moment later still lacks
    barrier._on_status(PLANNER, status(2, {}, [(NOTE_SUBS, {})]))
    assert not barrier.quiet()
    time.sleep(0.06)
    barrier._on_status(PLANNER, status(3, {}, [(NOTE_SUBS, {})]))  # quiet, and still lacks
    assert barrier.quiet() and barrier.lost == 3
    barrier._on_status(BRIDGE, status(2, {ODOM_NOTE: 4}, [(ODOM_SUBS, {})]))
    assert not barrier.quiet()  # but the fourth is its own
    barrier._on_status(PLANNER, status(4, {}, [(NOTE_SUBS, {ODOM_NOTE: 1})]))
    assert barrier.quiet()


def test_the_hold_nudges_until_everyone_expected_is_there_and_quiet(
    barrier: Barrier, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("services.sim.lockstep_barrier.LOST_AFTER_S", 0.1)
    stop = threading.Event()
    nudges = 0

    def nudge() -> None:
        # each clock makes every participant there report; the planner comes up after the
        # first clock went out, so it never gets that one
        nonlocal nudges
        nudges += 1
        barrier.published(keys.SIM_CLOCK)
        barrier._on_status(BRIDGE, status(nudges, {}, [(keys.SIM_CLOCK, {keys.SIM_CLOCK: nudges})]))
        if nudges >= 2:
            handled = {keys.SIM_CLOCK: nudges - 1}
            barrier._on_status(PLANNER, status(nudges, {}, [(keys.SIM_CLOCK, handled)]))

    assert barrier.hold(stop, nudge)
    # the planner's first reports lack the first clock; LOST_AFTER_S later it is forgiven
    assert 2 < nudges < 10 and barrier.missed_at_start == 1 and barrier.lost == 0
    assert barrier.started and barrier.timeouts == 0


def test_wait_returns_when_quiet_and_times_out_on_a_lost_message(barrier: Barrier) -> None:
    stop = threading.Event()
    barrier._on_status(BRIDGE, status(1, {}, [(ODOM_SUBS, {})]))
    barrier._on_status(PLANNER, status(1, {}, [(NOTE_SUBS, {})]))
    assert barrier.wait(stop) and barrier.timeouts == 0
    barrier.published(ODOM)
    threading.Timer(
        0.05, barrier._on_status, (BRIDGE, status(2, {}, [(ODOM_SUBS, {ODOM: 1})]))
    ).start()
    assert barrier.wait(stop)  # the bridge reports while the sim waits
    barrier.published(ODOM)  # lost: the bridge reports the clock's handling, not this
    threading.Timer(
        0.05, barrier._on_status, (BRIDGE, status(3, {}, [(ODOM_SUBS, {ODOM: 1})]))
    ).start()
    assert not barrier.wait(stop)
    assert barrier.timeouts == 1
    assert barrier.quiet()  # counted lost, not waited for again
    barrier.published(ODOM)
    assert not barrier.quiet()  # but the next one is
    barrier._on_status(BRIDGE, status(4, {}, [(ODOM_SUBS, {ODOM: 2})]))
    assert barrier.quiet()


def test_a_participant_silent_through_a_timeout_is_forgotten_until_it_reports(
    barrier: Barrier,
) -> None:
    stop = threading.Event()
    barrier._on_status(BRIDGE, status(1, {}, [(ODOM_SUBS, {})]))
    barrier._on_status(PLANNER, status(1, {}, [(NOTE_SUBS, {})]))
    barrier.wait(stop)
    barrier._on_status(BRIDGE, status(2, {ODOM_NOTE: 1}, [(ODOM_SUBS, {})]))
    assert not barrier.wait(stop)  # the planner owes the note and says nothing
    assert barrier.quiet() and barrier.expected == {"bridge"}
    barrier._on_status(PLANNER, status(2, {}, [(NOTE_SUBS, {})]))  # back: joins anew
    barrier._on_status(BRIDGE, status(3, {ODOM_NOTE: 2}, [(ODOM_SUBS, {})]))
    assert not barrier.quiet()  # and owes what comes after
    barrier._on_status(PLANNER, status(3, {}, [(NOTE_SUBS, {ODOM_NOTE: 1})]))
    assert barrier.quiet()


# -- the engine in lockstep -----------------------------------------------------------------------
class Counter(Rule):
    """A meta rule that counts its runs."""

    meta = True
    scenario = "count"

    def __init__(self, runs: list[float], clock: list[float]) -> None:
        self.runs = runs
        self.clock = clock

    def actions(self) -> None:
        self.runs.append(self.clock[0])

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


async def test_engine_in_lockstep_runs_on_notes_and_on_sim_time_and_reports_when_quiet(
    ledger: Ledger,
) -> None:
    sim_now = [0.0]
    runs: list[float] = []
    engine = Engine(
        EngineSettings(period_s=0.05),
        name="t",
        trigger=LockstepTrigger(ledger),
        clock=lambda: sim_now[0],
    )
    engine.add_meta(lambda: Counter(runs, sim_now))
    clock_tally = ledger.tally(keys.SIM_CLOCK)
    note_tally = ledger.tally(NOTE_SUBS)
    assert clock_tally is not None and note_tally is not None
    task = asyncio.create_task(engine.run())
    try:
        await eventually(lambda: ledger.reports >= 1)
        assert runs == [0.0]  # the first activation, then quiet: one report
        reports = ledger.reports

        # a clock message 0.02 s later: F (0.05 s of sim time) is not due; quiet again
        sim_now[0] = 0.02
        ledger.received(clock_tally, keys.SIM_CLOCK)
        await eventually(lambda: ledger.reports > reports)
        assert runs == [0.0]
        reports = ledger.reports

        # 0.05 s: F is due on sim time, an activation, then a report
        sim_now[0] = 0.05
        ledger.received(clock_tally, keys.SIM_CLOCK)
        await eventually(lambda: ledger.reports > reports)
        assert runs == [0.0, 0.05]
        reports = ledger.reports

        # a notification (flag set, then counted): an activation at the same sim time
        engine.wake_threadsafe()
        ledger.received(note_tally, ODOM_NOTE)
        await eventually(lambda: ledger.reports > reports)
        assert runs == [0.0, 0.05, 0.05]

        # no wall-clock period: nothing runs while sim time stands still
        await asyncio.sleep(0.2)
        assert runs == [0.0, 0.05, 0.05]
    finally:
        engine.stop()
        await asyncio.wait_for(task, 5)


class CountingService(ScenarioService):
    service = "planner"

    def __init__(self, runtime: Runtime, runs: list[float]) -> None:
        super().__init__(runtime)
        self.runs = runs

    def seed(self) -> None:
        clock = self.runtime.clock
        self.engine.add_meta(lambda: SimStamp(self.runs, clock.now))


class SimStamp(Rule):
    """A meta rule that notes the sim time of each of its runs."""

    meta = True
    scenario = "count"

    def __init__(self, runs: list[float], now: Callable[[], float]) -> None:
        self.runs = runs
        self.now = now

    def actions(self) -> None:
        self.runs.append(self.now())

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


async def test_a_service_in_lockstep_runs_its_engine_on_sim_clock_messages_and_reports(
    zenoh_settings: ZenohSettings,
) -> None:
    config = ServiceConfig(
        service="planner",
        database_url="postgresql://unused",
        zenoh=zenoh_settings,
        engine=EngineSettings(period_s=0.05),
        instance="p-7",
        lockstep=("planner",),
    )
    runtime = await Runtime.open(config, with_db=False)
    runs: list[float] = []
    service = CountingService(runtime, runs)
    service.seed()
    task = asyncio.create_task(service.engine.run())
    try:
        ledger = runtime.ledger
        assert ledger is not None
        await eventually(lambda: ledger.reports >= 1)
        assert runs == [0.0]
        runtime.zenoh.put(keys.SIM_CLOCK, bus.pack({"stamp": 0.02, "rate": 0.0}))
        await eventually(lambda: ledger.reports >= 2)  # F not due at 0.02 s: quiet again
        assert runs == [0.0]
        runtime.zenoh.put(keys.SIM_CLOCK, bus.pack({"stamp": 0.05, "rate": 0.0}))
        await eventually(lambda: ledger.reports >= 3)
        assert runs == [0.0, 0.05]  # F is due on sim time: an activation, then a report
        await asyncio.sleep(0.2)
        assert runs == [0.0, 0.05]  # no wall-clock period
    finally:
        service.engine.stop()
        await asyncio.wait_for(task, 5)
        await runtime.close()
