"""Benchmark of the bridge's two legs of the sense-to-act loop; prints figures and JSON.

``python -m services.bridge.bench [--seconds 10] [--robots 1] [--burst 3000] [--json FILE]``

Starts its own embedded Postgres and loopback Zenoh router, runs ``python -m services.bridge``
as a separate process (as deployed), and plays the sim from this process:

1. steady: after one warm-up sample per stream (not measured: a new Zenoh publisher's first
   sample is slow once), odometry at 30 Hz and scans at 5 Hz per robot for ``--seconds``.
   Sensor-to-row latency = arrival of the row's change notification here minus the publish
   time of that message (same machine, same monotonic clock). The contract payload carries
   no send time, so each message is identified by its ``seq``: after the run the rows'
   ``(id, seq)`` are read back, and a notification for id K marks every message up to K's
   seq as visible. ``received_at`` latency is the row's ``received_at`` (Postgres clock)
   minus the publish wall time, i.e. without the commit and the notification hop.
2. burst: ``--burst`` odometry messages back to back, for throughput and batching.
3. commands: a command2robot row + notification at 20 Hz, latency to its cmd_vel.

For scale, ``zenoh_hop`` is the same machine's floor: one small message from one session of
this process to another through the router, at 30 Hz. Every bridge leg above contains two
such hops (sim -> bridge, bridge -> listener); on a shared machine their tail is the
scheduler's, not the bridge's.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import platform
import signal
import sys
import threading
import time
from collections import defaultdict
from typing import Any

import asyncpg
import zenoh

from common import bus
from common.config import ZenohSettings
from common.contract import keys
from common.contract.migrate import apply_migrations
from common.testing import EmbeddedPostgres, free_port

Arrivals = list[tuple[float, str, str, int]]  # (monotonic, table, robot, id)


def percentile(values: list[float], q: float) -> float:
    """Nearest-rank percentile, ``q`` in [0, 100]."""
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[max(0, math.ceil(q / 100 * len(ordered)) - 1)]


def summary_ms(values: list[float]) -> dict[str, float]:
    ms = [v * 1000 for v in values]
    return {
        "n": len(ms),
        "p50_ms": round(percentile(ms, 50), 3),
        "p99_ms": round(percentile(ms, 99), 3),
        "max_ms": round(max(ms), 3) if ms else math.nan,
    }


def world(robots: list[str]) -> dict[str, Any]:
    return {
        "name": "bench",
        "map": {
            "resolution": 0.05,
            "origin": [0.0, 0.0, 0.0],
            "width": 200,
            "height": 200,
            "grid": bytes(200 * 200),
            "source": "bench",
        },
        "robots": [{"robot_id": r, "x": 1.0, "y": 1.0, "yaw": 0.0} for r in robots],
        "charging_stations": [],
    }


def odom(seq: int) -> dict[str, Any]:
    t = seq / 30
    return {"stamp": t, "seq": seq, "x": t, "y": 0.5, "yaw": 0.1, "linear": 0.2, "angular": 0.0}


def scan(seq: int) -> dict[str, Any]:
    ranges = [1.0 + (i % 90) / 100 if i % 7 else math.inf for i in range(360)]
    return {
        "stamp": seq / 5,
        "seq": seq,
        "angle_min": 0.0,
        "angle_increment": math.tau / 360,
        "range_min": 0.12,
        "range_max": 3.5,
        "ranges": ranges,
    }


class Player:
    """Publishes sensors as the sim would and records when each message left."""

    def __init__(self, session: zenoh.Session, robots: list[str]) -> None:
        self.session = session
        self.robots = robots
        # BLOCK, unlike the sim's DROP: the burst must measure the bridge, not lose samples
        # in this process's own queues
        self.pubs = {
            (r, t): session.declare_publisher(
                keys.robot_key(r, t), congestion_control=zenoh.CongestionControl.BLOCK
            )
            for r in robots
            for t in (keys.ODOM, keys.SCAN)
        }
        # (topic, robot, seq) -> (monotonic, wall) send time
        self.sent: dict[tuple[str, str, int], tuple[float, float]] = {}
        self.seq: dict[tuple[str, str], int] = defaultdict(int)

    def publish(self, robot: str, topic: str) -> None:
        seq = self.seq[(topic, robot)]
        self.seq[(topic, robot)] = seq + 1
        payload = bus.pack(odom(seq) if topic == keys.ODOM else scan(seq))
        self.sent[(topic, robot, seq)] = (time.monotonic(), time.time())
        self.pubs[(robot, topic)].put(payload)

    def steady(self, seconds: float, odom_hz: float = 30.0, scan_hz: float = 5.0) -> None:
        start = time.monotonic()
        next_at = {keys.ODOM: start, keys.SCAN: start}
        period = {keys.ODOM: 1 / odom_hz, keys.SCAN: 1 / scan_hz}
        while time.monotonic() - start < seconds:
            topic = min(next_at, key=lambda t: next_at[t])
            delay = next_at[topic] - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            for robot in self.robots:
                self.publish(robot, topic)
            next_at[topic] += period[topic]

    def burst(self, n: int) -> None:
        for _ in range(n):
            self.publish(self.robots[0], keys.ODOM)


def latencies(
    player: Player,
    arrivals: Arrivals,
    rows: dict[tuple[str, int], tuple[str, int, float]],
    first_seq: dict[tuple[str, str], int] | None = None,
) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """Per topic: notification latencies and received_at latencies (see module docstring).

    Only messages from ``first_seq[(topic, robot)]`` on count (default: all).
    """
    topic_of = {keys.ODOMETRY: keys.ODOM, keys.LASER_SCAN: keys.SCAN}
    visible: dict[str, list[float]] = defaultdict(list)
    inserted: dict[str, list[float]] = defaultdict(list)
    done: dict[tuple[str, str], int] = defaultdict(lambda: -1)  # highest seq accounted for
    for key, seq in (first_seq or {}).items():
        done[key] = seq - 1
    for t, table, robot, row_id in sorted(arrivals):
        if (table, row_id) not in rows:
            continue
        topic = topic_of[table]
        _, seq, _ = rows[(table, row_id)]
        for s in range(done[(topic, robot)] + 1, seq + 1):
            sent = player.sent.get((topic, robot, s))
            if sent is not None:
                visible[topic].append(t - sent[0])
        done[(topic, robot)] = max(done[(topic, robot)], seq)
    for (table, _), (robot, seq, received) in rows.items():
        topic = topic_of[table]
        if seq < (first_seq or {}).get((topic, robot), 0):
            continue
        sent = player.sent.get((topic, robot, seq))
        if sent is not None:
            inserted[topic].append(received - sent[1])
    return visible, inserted


def zenoh_hop(settings: ZenohSettings, n: int = 300, hz: float = 30.0) -> list[float]:
    """Latency of one publication through the router, for comparison."""
    a, b = bus.open_session(settings), bus.open_session(settings)
    sent: dict[int, float] = {}
    got: list[float] = []

    def on(key: str, payload: bytes) -> None:
        got.append(time.monotonic() - sent[int(payload)])

    sub = bus.subscribe_threaded(b, "bench/hop", on)
    pub = a.declare_publisher("bench/hop")
    try:
        time.sleep(0.3)
        for i in range(n):
            sent[i] = time.monotonic()
            pub.put(str(i).encode())
            time.sleep(1 / hz)
        time.sleep(0.2)
    finally:
        sub.undeclare()
        pub.undeclare()
        a.close()
        b.close()
    return got


async def read_rows(
    conn: asyncpg.Connection, since: dict[str, int]
) -> dict[tuple[str, int], tuple[str, int, float]]:
    rows: dict[tuple[str, int], tuple[str, int, float]] = {}
    for table in (keys.ODOMETRY, keys.LASER_SCAN):
        for r in await conn.fetch(
            f"SELECT id, robot_id, seq, extract(epoch FROM received_at)::float8 AS at"
            f" FROM {table} WHERE id > $1",
            since.get(table, 0),
        ):
            rows[(table, r["id"])] = (r["robot_id"], r["seq"], r["at"])
    return rows


async def max_ids(conn: asyncpg.Connection) -> dict[str, int]:
    return {
        t: await conn.fetchval(f"SELECT coalesce(max(id), 0) FROM {t}")
        for t in (keys.ODOMETRY, keys.LASER_SCAN)
    }


async def command_leg(
    conn: asyncpg.Connection, session: zenoh.Session, robot: str, seconds: float
) -> list[float]:
    """command2robot row + notification at 20 Hz -> cmd_vel; latency from the notification."""
    notified: dict[int, float] = {}
    got: dict[int, float] = {}

    def on_cmd(key: str, payload: bytes) -> None:
        cid = bus.unpack(payload).get("command_id")
        if isinstance(cid, int):
            got[cid] = time.monotonic()

    sub = bus.subscribe_threaded(session, keys.robot_key(robot, keys.CMD_VEL), on_cmd)
    notifier = bus.Notifier(session)
    await asyncio.sleep(0.3)
    try:
        for i in range(int(seconds * 20)):
            row_id = await conn.fetchval(
                "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps)"
                " VALUES ($1, $2, 0.1, 0.0) RETURNING id",
                robot,
                i / 20,
            )
            notified[row_id] = time.monotonic()
            notifier.notify(keys.COMMAND2ROBOT, robot, row_id)
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.3)
    finally:
        sub.undeclare()
        notifier.close()
    return [got[i] - t for i, t in notified.items() if i in got]


async def run(args: argparse.Namespace) -> dict[str, Any]:
    robots = [f"bench{i}" for i in range(args.robots)]
    pg = EmbeddedPostgres()
    pg.start()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = bus.start_router((endpoint,))
    settings = ZenohSettings(mode="client", connect=(endpoint,))
    child: asyncio.subprocess.Process | None = None
    session = None
    try:
        url = pg.create_database()
        conn = await asyncpg.connect(url)
        await apply_migrations(conn)
        # keep every row of the run: the seqs are read back afterwards
        await conn.execute("UPDATE retention_policy SET keep_rows_per_robot = 1000000")
        session = bus.open_session(settings)
        payload = bus.pack(world(robots))
        queryable = session.declare_queryable(
            keys.SIM_WORLD, lambda q: q.reply(keys.SIM_WORLD, payload)
        )
        env = {**os.environ, "PNAV_DATABASE_URL": url, **settings.to_env()}
        env.setdefault("PNAV_LOG_LEVEL", "WARNING")
        child = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "services.bridge", env=env
        )
        started = time.monotonic()
        while await conn.fetchval("SELECT count(*) FROM robot") < len(robots):
            if time.monotonic() - started > 30:
                raise RuntimeError("the bridge did not write the world in 30 s")
            await asyncio.sleep(0.05)
        ready_s = time.monotonic() - started

        arrivals: Arrivals = []
        lock = threading.Lock()

        def on_note(key: str, body: bytes) -> None:
            t = time.monotonic()
            note = bus.Notification.decode(key, body)
            if note.robot is not None and note.id is not None:
                with lock:
                    arrivals.append((t, note.table, note.robot, note.id))

        subs = [
            bus.subscribe_threaded(session, keys.notify_watch(t), on_note)
            for t in (keys.ODOMETRY, keys.LASER_SCAN)
        ]
        player = Player(session, robots)
        await asyncio.sleep(1.0)  # the bridge's subscriptions are in place
        # Warm-up, not measured: the first sample of a new publisher costs Zenoh a few ms
        # more (measured 6-40 ms on this machine), once per stream.
        for robot in robots:
            for topic in (keys.ODOM, keys.SCAN):
                player.publish(robot, topic)
        await asyncio.sleep(0.5)
        warm = dict(player.seq)

        await asyncio.to_thread(player.steady, args.seconds)
        await asyncio.sleep(0.5)
        steady_rows = await read_rows(conn, {})
        with lock:
            steady_arrivals = list(arrivals)
            arrivals.clear()
        visible, inserted = latencies(player, steady_arrivals, steady_rows, warm)

        before = await max_ids(conn)
        first_seq = dict(player.seq)
        t0 = time.monotonic()
        await asyncio.to_thread(player.burst, args.burst)
        want = before[keys.ODOMETRY] + args.burst
        last_count, quiet_since = -1, time.monotonic()
        while not any(a[3] >= want for a in list(arrivals)):
            if len(arrivals) != last_count:
                last_count, quiet_since = len(arrivals), time.monotonic()
            elif time.monotonic() - quiet_since > 2.0:
                break  # some messages were lost: measure what arrived
            await asyncio.sleep(0.01)
        with lock:
            burst_arrivals = list(arrivals)
        burst_s = max((a[0] for a in burst_arrivals), default=t0) - t0
        burst_rows = await read_rows(conn, before)
        burst_visible, _ = latencies(player, burst_arrivals, burst_rows, first_seq)
        for sub in subs:
            sub.undeclare()

        cmd = await command_leg(conn, session, robots[0], min(args.seconds, 5.0))
        hop = await asyncio.to_thread(zenoh_hop, settings)

        child.send_signal(signal.SIGTERM)
        exit_code = await asyncio.wait_for(child.wait(), 20)
        queryable.undeclare()
        await conn.close()
        return {
            "command": " ".join(["python -m services.bridge.bench", *sys.argv[1:]]),
            "machine": {
                "cpus": os.cpu_count(),
                "platform": platform.platform(),
                "python": platform.python_version(),
            },
            "robots": len(robots),
            "bridge_ready_s": round(ready_s, 3),
            "steady": {
                "seconds": args.seconds,
                "odom_to_notification": summary_ms(visible[keys.ODOM]),
                "scan_to_notification": summary_ms(visible[keys.SCAN]),
                "odom_to_received_at": summary_ms(inserted[keys.ODOM]),
                "scan_to_received_at": summary_ms(inserted[keys.SCAN]),
            },
            "burst": {
                "messages": args.burst,
                "rows": len(burst_rows),
                "seconds": round(burst_s, 3),
                "rows_per_s": round(len(burst_rows) / burst_s, 1) if burst_s else None,
                "notifications": len(burst_arrivals),
                "odom_to_notification": summary_ms(burst_visible[keys.ODOM]),
            },
            "command_notification_to_cmd_vel": summary_ms(cmd),
            "zenoh_hop": summary_ms(hop),
            "bridge_exit_code": exit_code,
        }
    finally:
        if child is not None and child.returncode is None:
            child.kill()
            await child.wait()
        if session is not None:
            session.close()
        router.close()
        pg.stop()


def report(result: dict[str, Any]) -> str:
    def line(name: str, s: dict[str, float]) -> str:
        return (
            f"  {name:28s} n={s['n']:<6} p50={s['p50_ms']:.2f} ms"
            f"  p99={s['p99_ms']:.2f} ms  max={s['max_ms']:.2f} ms"
        )

    st, bu = result["steady"], result["burst"]
    return "\n".join(
        [
            f"bridge benchmark: {result['robots']} robot(s), {result['machine']['cpus']} CPUs",
            f"steady ({st['seconds']} s, odom 30 Hz + scan 5 Hz per robot):",
            line("odom -> notification", st["odom_to_notification"]),
            line("scan -> notification", st["scan_to_notification"]),
            line("odom -> received_at", st["odom_to_received_at"]),
            line("scan -> received_at", st["scan_to_received_at"]),
            f"burst: {bu['rows']} rows in {bu['seconds']} s = {bu['rows_per_s']} rows/s,"
            f" {bu['notifications']} notifications (one per batch)",
            line("burst odom -> notification", bu["odom_to_notification"]),
            "commands (20 Hz):",
            line("notification -> cmd_vel", result["command_notification_to_cmd_vel"]),
            "for scale, one Zenoh publication through the router (30 Hz):",
            line("zenoh hop", result["zenoh_hop"]),
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m services.bridge.bench", description=__doc__)
    parser.add_argument("--seconds", type=float, default=10.0, help="steady phase length")
    parser.add_argument("--robots", type=int, default=1)
    parser.add_argument("--burst", type=int, default=3000, help="odometry messages in the burst")
    parser.add_argument("--json", help="also write the JSON result to this file")
    args = parser.parse_args(argv)
    result = asyncio.run(run(args))
    print(report(result))
    text = json.dumps(result, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text + "\n")
    return 0 if result["bridge_exit_code"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
