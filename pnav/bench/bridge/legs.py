"""The measured legs: sensors steady and in a burst (sim -> row visible), commands
(command2robot notification -> cmd_vel), and one bare Zenoh hop for scale."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import asyncpg
import zenoh

from common import bus
from common.config import ZenohSettings
from common.contract import keys
from pnav.bench.bridge.player import Player
from pnav.bench.bridge.row_latency import (
    Notifications,
    latencies,
    max_ids,
    read_rows,
    summary_ms,
)

# a burst is over when the last row is notified, or when no notification came for this long
# (some messages were lost: what arrived is measured)
BURST_QUIET_S = 2.0


async def steady(
    conn: asyncpg.Connection,
    player: Player,
    notes: Notifications,
    seconds: float,
    odom_hz: float = 30.0,
    scan_hz: float = 5.0,
) -> dict[str, Any]:
    """Odometry and scans at their rates per robot for ``seconds``, after a warm-up."""
    # Warm-up, not measured: the first sample of a new publisher costs Zenoh a few ms
    # more (measured 6-40 ms on this machine), once per stream.
    for robot in player.robots:
        for topic in (keys.ODOM, keys.SCAN):
            player.publish(robot, topic)
    await asyncio.sleep(0.5)
    warm = dict(player.seq)
    await asyncio.to_thread(player.steady, seconds, odom_hz, scan_hz)
    await asyncio.sleep(0.5)
    rows = await read_rows(conn, {})
    visible, inserted = latencies(player, notes.take(), rows, warm)
    return {
        "seconds": seconds,
        "odom_hz": odom_hz,
        "scan_hz": scan_hz,
        "odom_to_notification": summary_ms(visible[keys.ODOM]),
        "scan_to_notification": summary_ms(visible[keys.SCAN]),
        "odom_to_received_at": summary_ms(inserted[keys.ODOM]),
        "scan_to_received_at": summary_ms(inserted[keys.SCAN]),
    }


async def burst(
    conn: asyncpg.Connection, player: Player, notes: Notifications, messages: int
) -> dict[str, Any]:
    """``messages`` odometry messages back to back: throughput and batching."""
    before = await max_ids(conn)
    first_seq = dict(player.seq)
    t0 = time.monotonic()
    await asyncio.to_thread(player.burst, messages)
    await _until_notified(notes, before[keys.ODOMETRY] + messages)
    arrivals = notes.snapshot()
    seconds = max((a[0] for a in arrivals), default=t0) - t0
    rows = await read_rows(conn, before)
    visible, _ = latencies(player, arrivals, rows, first_seq)
    return {
        "messages": messages,
        "rows": len(rows),
        "seconds": round(seconds, 3),
        "rows_per_s": round(len(rows) / seconds, 1) if seconds else None,
        "notifications": len(arrivals),
        "odom_to_notification": summary_ms(visible[keys.ODOM]),
    }


async def _until_notified(notes: Notifications, row_id: int) -> None:
    """Until a notification names ``row_id`` (or a newer row), or they stop coming."""
    last_count, quiet_since = -1, time.monotonic()
    while True:
        arrivals = notes.snapshot()
        if any(a[3] >= row_id for a in arrivals):
            return
        if len(arrivals) != last_count:
            last_count, quiet_since = len(arrivals), time.monotonic()
        elif time.monotonic() - quiet_since > BURST_QUIET_S:
            return
        await asyncio.sleep(0.01)


async def commands(
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
