"""The Zenoh side of the contract (CONTRACT.md, *Zenoh key expressions*), by hand.

- ``pnav/db/{table}/{robot}``: a change notification, published after a committed write,
  msgpack ``{"table", "robot", "id"}``; ``{robot}`` is ``_`` for tables without a robot.
- ``pnav/sim/clock``: sim time, msgpack ``{"stamp", "rate"}``, at 20 Hz or more.
- ``pnav/alive/{service}/{instance}``: the liveliness token of a running service.

Zenoh calls our callbacks on its own threads: they only store a value or hand a call to the
event loop (``call_soon_threadsafe``), never touch asyncio objects directly.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import Callable
from typing import Any

import msgpack
import zenoh

from examples.sql_controller.environment import Settings

logger = logging.getLogger("sql_controller.zenoh")

SIM_CLOCK = "pnav/sim/clock"
# Between two clock messages sim time runs on at the advertised rate, but never more than
# this much wall time ahead of the last message: a stalled sim must not look alive.
MAX_EXTRAPOLATION_S = 0.1
# A stamp this far behind the last one is a restarted sim, not a late message.
RESTART_JUMP_S = 1.0


def notify_key(table: str, robot: str | None) -> str:
    return f"pnav/db/{table}/{robot or '_'}"


def notify_watch(table: str) -> str:
    return f"pnav/db/{table}/*"


def alive_key(service: str, instance: str) -> str:
    return f"pnav/alive/{service}/{instance}"


def open_session(settings: Settings) -> zenoh.Session:
    """A session configured the way every proactive-nav service configures its own: the
    PNAV_ZENOH_CONFIG file first (if any), the other PNAV_ZENOH_* variables on top."""
    if settings.zenoh_config_file:
        config = zenoh.Config.from_file(settings.zenoh_config_file)
    else:
        config = zenoh.Config()
    config.insert_json5("mode", json.dumps(settings.zenoh_mode))
    # Scouting off unless asked for: the contract's deployments name their router.
    config.insert_json5("scouting/multicast/enabled", json.dumps(settings.zenoh_multicast))
    if settings.zenoh_mode != "router" or settings.zenoh_connect:
        config.insert_json5("connect/endpoints", json.dumps(list(settings.zenoh_connect)))
    if settings.zenoh_listen:
        config.insert_json5("listen/endpoints", json.dumps(list(settings.zenoh_listen)))
    if settings.zenoh_user and settings.zenoh_password:
        auth = {"user": settings.zenoh_user, "password": settings.zenoh_password}
        config.insert_json5("transport/auth/usrpwd", json.dumps(auth))
    return zenoh.open(config)


def publish_change(
    session: zenoh.Session, table: str, robot: str | None, row_id: int | None
) -> None:
    """The change notification for a write that has committed (call it after COMMIT)."""
    body = msgpack.packb({"table": table, "robot": robot, "id": row_id}, use_bin_type=True)
    # express: a hint is worth most when it is early; do not batch it with other traffic.
    session.put(notify_key(table, robot), body, express=True)


def on_any_sample(
    loop: asyncio.AbstractEventLoop, call: Callable[[], None]
) -> Callable[[zenoh.Sample], None]:
    """A Zenoh callback that schedules ``call()`` on ``loop`` for every sample."""

    def callback(_sample: zenoh.Sample) -> None:
        try:
            loop.call_soon_threadsafe(call)
        except RuntimeError:
            pass  # the loop is closed: we are shutting down

    return callback


class SimClock:
    """Sim time: the newest ``pnav/sim/clock`` stamp, run on at its rate for a moment."""

    def __init__(self) -> None:
        # (stamp, rate, monotonic receive time), replaced as one tuple: a reader on the loop
        # never sees a stamp with another message's receive time.
        self._last: tuple[float, float, float] | None = None

    def on_sample(self, sample: zenoh.Sample) -> None:
        try:
            body: Any = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
            stamp, rate = float(body["stamp"]), float(body.get("rate", 1.0))
        except Exception:
            return  # not a clock message we understand: ignore it, keep the last good one
        last = self._last
        if last is not None and stamp < last[0] and last[0] - stamp < RESTART_JUMP_S:
            return  # reordered
        self._last = (stamp, rate, time.monotonic())

    def now(self) -> float | None:
        """Sim time now, or None before the first clock message (then nothing is fresh)."""
        last = self._last
        if last is None:
            return None
        stamp, rate, received = last
        if rate <= 0:  # "as fast as possible": no wall-time relation to extrapolate with
            return stamp
        elapsed = min(max(time.monotonic() - received, 0.0), MAX_EXTRAPOLATION_S)
        return stamp + elapsed * rate
