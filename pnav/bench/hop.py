"""One hop of the stack, stage by stage: ``python -m pnav.bench.hop``.

A hop (docs/BENCHMARKS.md, "Where a hop's milliseconds go") is what every service does
between a row committed upstream and its own row committed: a change notification through
Zenoh, the service's subscription, the engine's wake, a rule, an INSERT with its commit, the
notification of the new row. This runs exactly that path with the stack's own pieces, in a
uvloop process like a service's, and stamps every stage on CLOCK_MONOTONIC (shared by the
processes of the machine):

- ``sent``: a separate process publishes a notification (express, as a Notifier does);
- ``thread``: the subscriber's Zenoh callback starts (Zenoh's thread);
- ``loop``: the handler runs on the event loop (``bus.subscribe``, as ``ScenarioService.watch``
  subscribes), decodes the notification and wakes the engine for its robot;
- ``rule``: the woken rule's data acquisition starts (the engine's trigger and activation);
- ``insert``: its INSERT ... RETURNING id has committed (asyncpg, pooled, embedded Postgres,
  synchronous commit as for a recommendation or a command);
- ``notified``: the new row's notification has been handed to Zenoh (``Notifier.notify``).

``--direct``: the publisher connects to the subscriber peer to peer instead of through the
router (the stack always goes through the launcher's router; here the router runs in a
process of its own, as the launcher is).
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import uvloop

from common import bus
from common.bus import Notification, Notifier
from common.config import EngineSettings, ZenohSettings
from common.contract import keys
from common.db import create_pool
from common.engine import Engine, Rule
from pnav.bench.engine_rate import drive
from pnav.run.embedded_postgres import EmbeddedPostgres, free_port

TABLE = "hop_probe"
STAGES = ("thread", "loop", "rule", "insert", "notified")
CREATE = f"CREATE TABLE IF NOT EXISTS {TABLE} (id bigserial PRIMARY KEY, robot_id text, v float8)"
INSERT = f"INSERT INTO {TABLE} (robot_id, v) VALUES ($1, $2) RETURNING id"

Stamps = dict[int, dict[str, int]]


class HopProbe(Rule):
    """Meta rule: stamps its start, writes one row, notifies it, stamps each step."""

    scenario = "bench"
    meta = True
    watches = (TABLE,)

    def __init__(self, ctx: dict[str, Any], stamps: Stamps) -> None:
        self.ctx, self.stamps = ctx, stamps
        self.pending: list[int] = []

    def data_acquisition(self) -> None:
        now = time.monotonic_ns()
        inbox: list[int] = self.ctx["inbox"]
        self.pending = inbox[:]
        inbox.clear()
        for i in self.pending:
            self.stamps[i]["rule"] = now

    async def actions(self) -> None:
        if not self.pending:
            return
        pool, notifier = self.ctx["pool"], self.ctx["notifier"]
        if pool is not None:
            row_id = await pool.fetchval(INSERT, "r1", 0.5)
        else:
            row_id = self.pending[-1]
        now = time.monotonic_ns()
        for i in self.pending:
            self.stamps[i]["insert"] = now
        notifier.notify("hop_out", "r1", row_id, {"id": row_id, "robot_id": "r1", "v": 0.5})
        now = time.monotonic_ns()
        for i in self.pending:
            self.stamps[i]["notified"] = now

    def rule_generation(self) -> list[Rule]:
        return [self.clone()]


async def hop(
    settings: ZenohSettings,
    sender: ZenohSettings,
    dsn: str | None,
    count: int,
    gap_s: float,
    sync_commit: bool = True,
) -> Stamps:
    """Run ``count`` notifications from a publisher process (on ``sender``) through the hop."""
    stamps: Stamps = {}
    session = bus.open_session(settings)
    sync = {"synchronous_commit": "on" if sync_commit else "off"}
    pool = await create_pool(dsn, server_settings=sync) if dsn else None
    if pool is not None:
        await pool.execute(CREATE)
    ctx: dict[str, Any] = {"inbox": [], "pool": pool, "notifier": Notifier(session)}
    engine = Engine(EngineSettings(period_s=1.0), name="hop")
    engine.add_meta(lambda: HopProbe(ctx, stamps))

    def on_thread(key: str, payload: bytes) -> None:
        body = bus.unpack(payload)
        stamps.setdefault(body["id"], {}).update(sent=body["sent_ns"], thread=time.monotonic_ns())

    def on_loop(key: str, payload: bytes) -> None:
        note = Notification.decode(key, payload)
        assert note.id is not None
        stamps.setdefault(note.id, {})["loop"] = time.monotonic_ns()
        ctx["inbox"].append(note.id)
        engine.wake(note.robot)

    watch = keys.notify_watch(TABLE)
    subs = [
        bus.subscribe_threaded(session, watch, on_thread),
        bus.subscribe(session, watch, on_loop),
    ]
    await drive(engine, sender, count, gap_s, TABLE, 0.2, subs)
    ctx["notifier"].close()
    session.close()
    if pool is not None:
        await pool.close()
    return stamps


def report(stamps: Stamps, label: str) -> None:
    done = [s for s in stamps.values() if all(k in s for k in STAGES)]
    print(f"{label}: {len(done)} samples; ms p50 / p99 (mean) of each stage from the one before")
    before = "sent"
    for stage in STAGES:
        values = sorted((s[stage] - s[before]) / 1e6 for s in done)
        p99 = values[min(len(values) - 1, int(len(values) * 0.99))]
        mean = statistics.fmean(values)
        print(
            f"  {before:>8} -> {stage:<8} {values[len(values) // 2]:7.3f} / {p99:7.3f} ({mean:.3f})"
        )
        before = stage
    total = sorted((s["notified"] - s["sent"]) / 1e6 for s in done)
    p50, p99 = total[len(total) // 2], total[int(len(total) * 0.99)]
    print(f"  {'sent':>8} -> notified {p50:7.3f} / {p99:7.3f}")


ROUTER = (
    "import sys, time; from common.bus import start_router; "
    "router = start_router((sys.argv[1],)); time.sleep(3600)"
)


@contextlib.contextmanager
def router_process() -> Iterator[ZenohSettings]:
    """A Zenoh router in a process of its own, as the launcher's is to a service."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = subprocess.Popen([sys.executable, "-c", ROUTER, endpoint])
    try:
        time.sleep(1.0)
        yield ZenohSettings(mode="client", connect=(endpoint,))
    finally:
        router.terminate()
        router.wait(5)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--gap-ms", type=float, default=5.0)
    parser.add_argument("--no-db", action="store_true", help="skip Postgres (no INSERT)")
    parser.add_argument("--direct", action="store_true", help="peer to peer, no router")
    parser.add_argument("--async-commit", action="store_true", help="synchronous_commit off")
    args = parser.parse_args(argv)
    sync = not args.async_commit  # --async-commit: as the bridge writes sensor rows
    pg = None if args.no_db else EmbeddedPostgres()
    dsn = pg.start() if pg is not None else None
    try:
        if args.direct:
            endpoint = f"tcp/127.0.0.1:{free_port()}"
            listen = ZenohSettings(mode="peer", connect=(), listen=(endpoint,), multicast=False)
            sender = ZenohSettings(mode="peer", connect=(endpoint,), listen=(), multicast=False)
            stamps = uvloop.run(hop(listen, sender, dsn, args.count, args.gap_ms / 1000, sync))
        else:
            with router_process() as settings:
                gap_s = args.gap_ms / 1000
                stamps = uvloop.run(hop(settings, settings, dsn, args.count, gap_s, sync))
    finally:
        if pg is not None:
            pg.stop()
    report(stamps, "peer to peer" if args.direct else "through a router")
    return 0


if __name__ == "__main__":
    sys.exit(main())
