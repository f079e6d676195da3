"""``pnav bench engine``: rule executions per second, and notification-to-rule-start latency.

Throughput: a population of trivial self-cloning rules (every step present, each doing a
comparison or an increment) runs in back-to-back activations on one core; we count rule
executions per second, for plain steps and for ``async def`` steps.

Wake latency: a separate process publishes change notifications through an in-process Zenoh
router on loopback, each stamped with CLOCK_MONOTONIC (shared by all processes of the
machine). The engine, waiting with a period F of 1 s, is woken one loop hop after Zenoh's
callback, as a service is (``wake_on_notifications``); a meta rule notes the clock when its
data acquisition starts.
Latency = rule start - publish time.
"""

from __future__ import annotations

import asyncio
import os
import sys
import textwrap
import time
from collections.abc import Sequence
from typing import Any

import uvloop

from common import bus
from common.config import EngineSettings, ZenohSettings
from common.contract import keys
from common.engine import Engine, Rule
from common.service import wake_on_notifications
from pnav._testing import loopback_zenoh
from pnav.bench.figures import emit, machine, percentiles

BENCH_TABLE = keys.GOAL  # any watched table will do; no database is involved


class Trivial(Rule):
    scenario = "bench"

    def __init__(self) -> None:
        self.count = 0

    def data_acquisition(self) -> None:
        self.value = self.count

    def activation_guards(self) -> bool:
        return self.value >= 0

    def conditions(self) -> bool:
        return True

    def actions(self) -> None:
        self.count += 1

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


class TrivialAsync(Rule):
    scenario = "bench"

    def __init__(self) -> None:
        self.count = 0

    async def data_acquisition(self) -> None:
        self.value = self.count

    def activation_guards(self) -> bool:
        return self.value >= 0

    async def actions(self) -> None:
        self.count += 1

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


async def throughput(
    rule_type: type[Trivial] | type[TrivialAsync], population: int, seconds: float
) -> float:
    engine = Engine(EngineSettings(period_s=3600.0, max_rules=population * 10))
    for _ in range(population):
        engine.add(rule_type())
    await engine.activation()  # warm-up
    ran = 0
    started = time.perf_counter()
    while time.perf_counter() - started < seconds:
        ran += await engine.activation()
    return ran / (time.perf_counter() - started)


PUBLISHER = textwrap.dedent(
    """
    import os, random, sys, time
    from common import bus
    from common.config import ZenohSettings
    from common.contract import keys
    count, gap = int(sys.argv[1]), float(sys.argv[2])
    session = bus.open_session(ZenohSettings.from_env())
    publisher = session.declare_publisher(keys.notify_key(sys.argv[3], "r1"), express=True)
    time.sleep(0.5)
    for i in range(count):
        publisher.put(bus.pack({"table": sys.argv[3], "robot": "r1", "id": i,
                                "sent_ns": time.monotonic_ns()}))
        time.sleep(gap * random.uniform(0.5, 1.5))
    time.sleep(0.2)
    session.close()
    """
)


class WakeProbe(Rule):
    """Meta rule: on each run, pair its start time with the newest notification not yet seen."""

    scenario = "bench"
    meta = True
    watches = (BENCH_TABLE,)

    def __init__(self, inbox: dict[int, int], latencies: list[float]) -> None:
        self.inbox, self.latencies = inbox, latencies

    def data_acquisition(self) -> None:
        now = time.monotonic_ns()
        while self.inbox:
            _, sent = self.inbox.popitem()
            self.latencies.append((now - sent) / 1e6)

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


async def wake_latency(count: int, gap_s: float) -> list[float]:
    latencies: list[float] = []
    inbox: dict[int, int] = {}
    with loopback_zenoh() as settings:
        session = bus.open_session(settings)
        engine = Engine(EngineSettings(period_s=1.0), name="bench")
        engine.add_meta(lambda: WakeProbe(inbox, latencies))

        def record(key: str, payload: bytes) -> None:
            body = bus.unpack(payload)
            inbox[body["id"]] = body["sent_ns"]  # dict writes are atomic under the GIL

        subscribers = wake_on_notifications(session, engine, engine.watched_tables, record)
        code = await drive(engine, settings, count, gap_s, BENCH_TABLE, 0.1, subscribers)
        session.close()
    if code != 0:
        raise RuntimeError(f"the publisher process failed with code {code}")
    return latencies


async def drive(
    engine: Engine,
    sender: ZenohSettings,
    count: int,
    gap_s: float,
    table: str,
    settle_s: float,
    subscribers: Sequence[Any],
) -> int | None:
    """Run ``engine`` while a publisher process (on ``sender``) sends ``count`` notifications
    of ``table`` ``gap_s`` apart; give the last ``settle_s`` to arrive, stop the engine and
    undeclare its ``subscribers``; the publisher's exit code."""
    task = asyncio.create_task(engine.run())
    env = {**os.environ, **sender.to_env()}
    publisher = await asyncio.create_subprocess_exec(
        sys.executable, "-c", PUBLISHER, str(count), str(gap_s), table, env=env
    )
    await publisher.wait()
    await asyncio.sleep(settle_s)
    engine.stop()
    await task
    for sub in subscribers:
        sub.undeclare()
    return publisher.returncode


def run(json_path: str | None = None, seconds: float = 3.0, notifications: int = 1000) -> int:
    result: dict[str, Any] = {"benchmark": "engine", "machine": machine()}

    async def measure() -> None:
        sync_rate = await throughput(Trivial, 1000, seconds)
        async_rate = await throughput(TrivialAsync, 1000, seconds)
        latencies = await wake_latency(notifications, 0.005)
        result["rules_per_s"] = {"sync_steps": round(sync_rate), "async_steps": round(async_rate)}
        result["wake_latency_ms"] = {k: round(v, 4) for k, v in percentiles(latencies).items()}
        result["wake_samples"] = len(latencies)

    uvloop.run(measure())
    rates, wake = result["rules_per_s"], result["wake_latency_ms"]
    print("Proactive Engine benchmark (one core, uvloop)")
    print(f"  trivial rules, plain steps : {rates['sync_steps']:>10,} rule executions/s")
    print(f"  trivial rules, async steps : {rates['async_steps']:>10,} rule executions/s")
    print(
        f"  notification -> rule start : p50 {wake['p50']:.3f} ms  p95 {wake['p95']:.3f} ms  "
        f"p99 {wake['p99']:.3f} ms  max {wake['max']:.3f} ms  ({result['wake_samples']} samples)"
    )
    print("  targets: >= 100,000 rules/s; p99 wake < 2 ms")
    emit(result, json_path)
    return 0
