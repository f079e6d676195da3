"""The design's floor: the stack's sense-to-act path with no rules in it.

``python -m pnav.bench.chain [--robots 1,10,50] [--seconds 10]``

``pnav bench latency`` measures the stack; this measures what any implementation of the
design pays on the same path before its first line of navigation code, with the stack's own
pieces (``bus.subscribe``, ``Notification``, ``Notifier``, ``Engine`` with per-robot wakes,
``common.db.create_pool`` on an embedded Postgres, a Zenoh router in a process of its own as
the launcher's is). A *sim* process publishes one message per robot every period (20 Hz, all
robots at once, as the sim's step does) and stamps when each comes back:

- **bridge** (one process, two relays): the sensor message -> one multi-row INSERT of every
  robot pending (``synchronous_commit`` off, as the bridge writes sensor rows) -> a row
  notification with its image; and a command notification -> a put to the robot (no
  database: the bridge relays commands from their image);
- **planner**: a row notification -> its engine's activation -> one multi-row INSERT of every
  robot pending, committed -> a notification per row, with its image;
- **decision**: the same, from those rows to the command rows.

So one sample crosses Zenoh five times, commits three times and passes four event loops,
as a sample of ``pnav bench latency`` does, and nothing else: no rule reads a table, no row
has more than two columns, and no lidar travels (the real stack's scans and their
controller double its traffic). Whatever the stack's services are made of, its p99 cannot
go below this chain's on the same machine.
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import math
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

import psutil
import uvloop

from common import bus
from common.bus import Notification, Notifier
from common.config import EngineSettings, ZenohSettings
from common.contract import keys
from common.db import create_pool
from common.engine import Engine, Rule
from pnav.bench.figures import emit, machine, percentiles
from pnav.bench.hop import router_process
from pnav.run.embedded_postgres import EmbeddedPostgres
from pnav.run.local_stack import LocalZenoh

PERIOD_S = 0.05  # 20 Hz, as `pnav bench latency` drives its robots
WARMUP_S = 2.0


@dataclass(frozen=True)
class Relay:
    """Read notifications of ``watch``; write rows of ``emit`` (``commit``: sync, async or
    none, none publishing the upstream image onward without a row)."""

    watch: str
    emit: str
    commit: str


# the stack's sample path, process by process
PROCESSES: dict[str, tuple[Relay, ...]] = {
    "bridge": (
        Relay("chain_sensor", "chain_row", "async"),
        Relay("chain_command", "chain_cmd", "none"),
    ),
    "planner": (Relay("chain_row", "chain_rec", "sync"),),
    "decision": (Relay("chain_rec", "chain_command", "sync"),),
}


class RelayRule(Rule):
    """Meta rule: every robot's pending message in one INSERT, then one notification each."""

    scenario = "chain"
    meta = True

    def __init__(self, relay: Relay, inbox: list[tuple[str, int]], pool: Any, out: Notifier):
        self.relay, self.inbox, self.pool, self.out = relay, inbox, pool, out
        self.pending: list[tuple[str, int]] = []

    def data_acquisition(self) -> None:
        self.pending = self.inbox[:]
        self.inbox.clear()

    async def actions(self) -> None:
        if not self.pending:
            return
        robots = [robot for robot, _ in self.pending]
        stamps = [sent for _, sent in self.pending]
        rows = await self.pool.fetch(
            f"INSERT INTO {self.relay.emit} (robot_id, sent_ns) "
            "SELECT * FROM unnest($1::text[], $2::bigint[]) RETURNING id, robot_id, sent_ns",
            robots,
            stamps,
        )
        for row in rows:
            self.out.notify(self.relay.emit, row["robot_id"], row["id"], dict(row))

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


async def run_process(name: str, dsn: str) -> None:
    """One process of the chain, until SIGTERM."""
    session = bus.open_session(ZenohSettings.from_env())
    out = Notifier(session)
    engine = Engine(EngineSettings(period_s=1.0), name=name)
    pools: list[Any] = []
    subs = []
    # an engine keeps one meta rule per rule type: one relay with a database per process
    assert sum(relay.commit != "none" for relay in PROCESSES[name]) <= 1
    for relay in PROCESSES[name]:
        if relay.commit == "none":
            subs.append(
                bus.subscribe(session, keys.notify_watch(relay.watch), _forward(relay, out))
            )
            continue
        pool = await create_pool(
            dsn, server_settings={"synchronous_commit": "on" if relay.commit == "sync" else "off"}
        )
        pools.append(pool)
        inbox: list[tuple[str, int]] = []
        engine.add_meta(functools.partial(RelayRule, relay, inbox, pool, out))
        subs.append(bus.subscribe(session, keys.notify_watch(relay.watch), _enqueue(inbox, engine)))
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, engine.stop)
    print("ready", flush=True)
    await engine.run()
    for sub in subs:
        sub.undeclare()
    for pool in pools:
        await pool.close()
    session.close()


def _enqueue(inbox: list[tuple[str, int]], engine: Engine) -> bus.Handler:
    def on_note(key: str, payload: bytes) -> None:
        note = Notification.decode(key, payload)
        if note.row is not None and note.robot is not None:
            inbox.append((note.robot, int(note.row["sent_ns"])))
            engine.wake(note.robot)

    return on_note


def _forward(relay: Relay, out: Notifier) -> bus.Handler:
    def on_note(key: str, payload: bytes) -> None:
        note = Notification.decode(key, payload)
        if note.row is not None:
            out.notify(relay.emit, note.robot, note.id, note.row)

    return on_note


COMMITTED = tuple(r.emit for relays in PROCESSES.values() for r in relays if r.commit != "none")


async def _tables(dsn: str, sql: str) -> dict[str, int]:
    """Run ``sql`` (``{table}`` filled in) on every table the chain commits to."""
    pool = await create_pool(dsn)
    try:
        return {table: await pool.fetchval(sql.format(table=table)) for table in COMMITTED}
    finally:
        await pool.close()


CREATE = (
    "CREATE TABLE IF NOT EXISTS {table} "
    "(id bigserial PRIMARY KEY, robot_id text NOT NULL, sent_ns bigint NOT NULL)"
)


def measure(
    robots: int, seconds: float, settings: ZenohSettings, cpu: dict[str, psutil.Process | None]
) -> dict[str, Any]:
    """Drive ``robots`` at 20 Hz for ``seconds`` after the warm-up; latencies and CPU."""
    session = bus.open_session(settings)
    out = Notifier(session)
    got: list[tuple[int, int]] = []  # (sent_ns, received_ns)
    lock = threading.Lock()

    def on_cmd(key: str, payload: bytes) -> None:
        now = time.monotonic_ns()
        note = Notification.decode(key, payload)
        if note.row is not None:
            with lock:
                got.append((int(note.row["sent_ns"]), now))

    sub = bus.subscribe_threaded(session, keys.notify_watch("chain_cmd"), on_cmd)
    names = [f"r{i}" for i in range(robots)]
    seq = 0
    start = time.monotonic()
    measuring_from_ns = None
    before: dict[str, float] = {}
    tick = start
    while True:
        now = time.monotonic()
        if measuring_from_ns is None and now - start >= WARMUP_S:
            measuring_from_ns = time.monotonic_ns()
            before = {role: _cpu(p) for role, p in cpu.items()}
        if now - start >= WARMUP_S + seconds:
            break
        for robot in names:
            seq += 1
            out.notify("chain_sensor", robot, seq, {"id": seq, "sent_ns": time.monotonic_ns()})
        tick += PERIOD_S
        time.sleep(max(0.0, tick - time.monotonic()))
    time.sleep(0.5)  # the last samples come home
    after = {role: _cpu(p) for role, p in cpu.items()}
    sub.undeclare()
    session.close()
    assert measuring_from_ns is not None
    latencies = [(r - s) / 1e6 for s, r in got if s >= measuring_from_ns]
    spread = percentiles(latencies)  # {} when no sample came back
    sent = int(seconds / PERIOD_S) * robots
    by_role = {role: round((after[role] - before[role]) / seconds * 100, 1) for role in cpu}
    return {
        "robots": robots,
        "samples": len(latencies),
        "sent": sent,
        **{f"{p}_ms": round(spread.get(p, math.nan), 3) for p in ("p50", "p95", "p99")},
        "cpu_pct": round(sum(by_role.values()), 1),
        "cpu_pct_by_role": by_role,
    }


def _cpu(process: psutil.Process | None) -> float:
    """CPU seconds of ``process`` and its children (Postgres' backends); None: this one,
    alone (the sim, whose children are the chain's other processes)."""
    if process is None:
        t = psutil.Process().cpu_times()
        return t.user + t.system
    total = 0.0
    for p in [process, *process.children(recursive=True)]:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except psutil.NoSuchProcess:
            pass
    return total


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="1,10,50", help="robot counts, comma-separated")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument(
        "--zenoh", choices=("client", "peer"), default="client", help="as PNAV_LOCAL_ZENOH"
    )
    parser.add_argument("--json", help="write the figures here too")
    parser.add_argument("--process", help=argparse.SUPPRESS)  # a chain process (internal)
    parser.add_argument("--dsn", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.process:
        uvloop.run(run_process(args.process, args.dsn))
        return 0
    try:
        counts = [int(n) for n in args.robots.split(",")]
    except ValueError:
        parser.error(f"--robots {args.robots!r}: robot counts, comma-separated (1,10,50)")
    if min(counts) < 1 or args.seconds <= 0:
        parser.error("every robot count is at least 1, and --seconds is positive")
    pg = EmbeddedPostgres()
    dsn = pg.start()
    results = []
    try:
        asyncio.run(_tables(dsn, CREATE))
        with router_process() as routed:
            # client: every message through the router, as the stack's default; peer: the
            # processes find each other through it and send directly (PNAV_LOCAL_ZENOH=peer)
            settings = LocalZenoh(mode=args.zenoh).settings(routed.connect[0])
            env = {**os.environ, **settings.to_env()}
            procs = {
                name: subprocess.Popen(
                    [sys.executable, "-m", "pnav.bench.chain", "--process", name, "--dsn", dsn],
                    env=env,
                    stdout=subprocess.PIPE,
                    text=True,
                )
                for name in PROCESSES
            }
            try:
                for p in procs.values():
                    assert p.stdout is not None
                    p.stdout.readline()  # "ready"
                cpu: dict[str, psutil.Process | None] = {"sim": None}
                cpu.update({name: psutil.Process(p.pid) for name, p in procs.items()})
                pg_pid = pg.pid()
                if pg_pid is not None:
                    cpu["postgres"] = psutil.Process(pg_pid)
                ours = {p.pid for p in procs.values()} | {pg_pid}
                for child in psutil.Process().children():
                    if child.pid not in ours:
                        cpu["router"] = child
                for robots in counts:
                    results.append(measure(robots, args.seconds, settings, cpu))
                    _print(results[-1])
            finally:
                for p in procs.values():
                    p.terminate()
                for p in procs.values():
                    p.wait(10)
        # every sample (warm-ups included) committed once in each table: the path was whole
        rows = asyncio.run(_tables(dsn, "SELECT count(*) FROM {table}"))
    finally:
        pg.stop()
    print(f"rows committed: {rows}")
    figures = {"benchmark": "chain", "machine": machine(), "period_s": PERIOD_S}
    figures |= {"seconds": args.seconds, "zenoh": args.zenoh, "rows": rows, "runs": results}
    emit(figures, args.json)
    return 0


def _print(r: dict[str, Any]) -> None:
    roles = ", ".join(f"{k} {v}" for k, v in r["cpu_pct_by_role"].items())
    print(
        f"{r['robots']:>3} robots: {r['samples']}/{r['sent']} samples, ms p50 {r['p50_ms']} "
        f"p95 {r['p95_ms']} p99 {r['p99_ms']}; CPU {r['cpu_pct']} % of a core ({roles})",
        flush=True,
    )


if __name__ == "__main__":
    sys.exit(main())
