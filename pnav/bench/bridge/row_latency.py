"""What the latencies are made of: the notifications received, the rows read back, and the
statistics (see the package docstring for how a message is matched to its row)."""

from __future__ import annotations

import math
import threading
import time
from collections import defaultdict

import asyncpg
import zenoh

from common import bus
from common.contract import keys
from pnav.bench.bridge.player import Player

Arrivals = list[tuple[float, str, str, int]]  # (monotonic, table, robot, id)
Rows = dict[tuple[str, int], tuple[str, int, float]]  # (table, id) -> (robot, seq, received_at)
Latencies = dict[str, list[float]]  # topic -> seconds

SENSOR_TABLES = (keys.ODOMETRY, keys.LASER_SCAN)


class Notifications:
    """The change notifications of the sensor rows, each with the time it arrived here."""

    def __init__(self, session: zenoh.Session) -> None:
        self._lock = threading.Lock()  # Zenoh's threads append, the benchmark reads
        self._arrivals: Arrivals = []
        self._subs = [
            bus.subscribe_threaded(session, keys.notify_watch(t), self._on) for t in SENSOR_TABLES
        ]

    def _on(self, key: str, body: bytes) -> None:
        t = time.monotonic()
        note = bus.Notification.decode(key, body)
        if note.robot is not None and note.id is not None:
            with self._lock:
                self._arrivals.append((t, note.table, note.robot, note.id))

    def snapshot(self) -> Arrivals:
        with self._lock:
            return list(self._arrivals)

    def take(self) -> Arrivals:
        """Every arrival so far; the next call starts afresh."""
        with self._lock:
            arrivals, self._arrivals = self._arrivals, []
        return arrivals

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def latencies(
    player: Player,
    arrivals: Arrivals,
    rows: Rows,
    first_seq: dict[tuple[str, str], int] | None = None,
) -> tuple[Latencies, Latencies]:
    """Per topic: notification latencies and received_at latencies (see the package
    docstring). Only messages from ``first_seq[(topic, robot)]`` on count (default: all)."""
    topic_of = {keys.ODOMETRY: keys.ODOM, keys.LASER_SCAN: keys.SCAN}
    visible: Latencies = defaultdict(list)
    inserted: Latencies = defaultdict(list)
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


async def read_rows(conn: asyncpg.Connection, since: dict[str, int]) -> Rows:
    rows: Rows = {}
    for table in SENSOR_TABLES:
        for r in await conn.fetch(
            f"SELECT id, robot_id, seq, extract(epoch FROM received_at)::float8 AS at"
            f" FROM {table} WHERE id > $1",
            since.get(table, 0),
        ):
            rows[(table, r["id"])] = (r["robot_id"], r["seq"], r["at"])
    return rows


async def max_ids(conn: asyncpg.Connection) -> dict[str, int]:
    return {t: await conn.fetchval(f"SELECT coalesce(max(id), 0) FROM {t}") for t in SENSOR_TABLES}


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
