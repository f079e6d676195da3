"""Zenoh plumbing: sessions from settings, notifications, and subscriptions for asyncio code.

Zenoh runs callbacks on its own threads. :func:`subscribe` hands every sample to the event
loop with ``call_soon_threadsafe`` so handlers run on the loop like any other asyncio code.

In a lockstep run (common.lockstep) the process's ledger is handed to every subscription
and to the :class:`Notifier` (``ledger=``, ``Runtime.ledger``): they count on it. Without a
ledger nothing is counted.
"""

from __future__ import annotations

import asyncio
import contextvars
import json
import logging
import secrets
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import msgpack
import zenoh

from common.config import DATA_QUEUE_BATCHES, ZenohSettings
from common.contract import acl, keys
from common.errors import ConfigError, ConnectionFailure

if TYPE_CHECKING:
    from common.lockstep import Ledger

log = logging.getLogger(__name__)

Handler = Callable[[str, bytes], None]

# Zenoh 1.x puts every payload over 3 KB (scans, maps, the world) in a 16 MB shared-memory
# pool of the publishing process (/dev/shm/*.zenoh), which the router and each receiver map
# too: 5-8 MB of every process's PSS a few seconds after start, growing towards the pool's
# size, to spare a copy of a few kilobytes over loopback (docs/BENCHMARKS.md, "Start-up:
# where the seconds and megabytes went"). A config file (PNAV_ZENOH_CONFIG) may turn it on.
SHARED_MEMORY = False


def zenoh_config(settings: ZenohSettings) -> zenoh.Config:
    """A Zenoh config: the file (if any) first, then the settings on top of it."""
    if settings.config_file:
        try:
            config = zenoh.Config.from_file(settings.config_file)
        except Exception as exc:
            raise ConfigError(f"PNAV_ZENOH_CONFIG={settings.config_file!r}: {exc}") from exc
    else:
        config = zenoh.Config()
        config.insert_json5("transport/shared_memory/enabled", json.dumps(SHARED_MEMORY))
    config.insert_json5("mode", json.dumps(settings.mode))
    config.insert_json5("scouting/multicast/enabled", json.dumps(settings.multicast))
    if settings.mode != "router" or settings.connect:
        config.insert_json5("connect/endpoints", json.dumps(list(settings.connect)))
    if settings.listen:
        config.insert_json5("listen/endpoints", json.dumps(list(settings.listen)))
    auth: dict[str, str] = {}
    if settings.user and settings.password:
        auth = {"user": settings.user, "password": settings.password}
    if settings.users_file:
        auth["dictionary_file"] = settings.users_file
    if auth:
        config.insert_json5("transport/auth/usrpwd", json.dumps(auth))
    config.insert_json5("transport/link/tx/queue/size/data", json.dumps(settings.data_queue))
    return config


def open_session(settings: ZenohSettings) -> zenoh.Session:
    """Open a Zenoh session; raises ConnectionFailure if no router/peer answers."""
    try:
        return zenoh.open(zenoh_config(settings))
    except ConfigError:
        raise
    except Exception as exc:
        where = ",".join(settings.connect or settings.listen) or "(no endpoint)"
        raise ConnectionFailure(
            f"cannot open a Zenoh {settings.mode} session on {where}: {exc}"
        ) from exc


def start_router(
    listen: tuple[str, ...],
    users_file: str | None = None,
    *,
    data_queue: int = DATA_QUEUE_BATCHES,
    ros_domains: tuple[int, ...] = (),
    hosts: tuple[str, ...] = acl.DEFAULT_HOSTS,
) -> zenoh.Session:
    """Run a Zenoh router inside this process, listening on ``listen`` endpoints. With
        ``users_file`` it is the compose router (common.contract.acl.router_config, one source):
        it accepts only sessions whose user/password is in that file, and lets each user put only
        its own keys (and, in ``ros_domains``, the ROS 2 identities speak ROS 2; ``hosts``: the
    host identities it knows, acl.host_identity). Without, it
        checks nothing (a test's or a benchmark's loopback router)."""
    if users_file is None:
        settings = ZenohSettings(mode="router", connect=(), listen=listen, data_queue=data_queue)
        config = zenoh_config(settings)
    else:
        acl_config = acl.router_config(listen, users_file, data_queue, ros_domains, hosts)
        config = zenoh.Config.from_json5(json.dumps(acl_config))
        config.insert_json5("transport/shared_memory/enabled", json.dumps(SHARED_MEMORY))
    # Opening a router waits scouting's delay (500 ms) for peers to scout; this one scouts
    # none (multicast off, nothing to connect to): the processes connect to it.
    config.insert_json5("scouting/delay", "0")
    try:
        return zenoh.open(config)
    except Exception as exc:
        raise ConnectionFailure(f"cannot open a Zenoh router on {','.join(listen)}: {exc}") from exc


def subscribe(
    session: zenoh.Session,
    key_expr: str,
    handler: Handler,
    loop: asyncio.AbstractEventLoop | None = None,
    *,
    ledger: Ledger | None = None,
) -> zenoh.Subscriber[None]:
    """Call ``handler(key, payload)`` on ``loop`` for every sample on ``key_expr``.

    Keep the returned subscriber referenced; call ``undeclare()`` on it to stop. With a
    ``ledger`` (lockstep) a message counts as received once ``handler`` returned.
    """
    loop = loop or asyncio.get_running_loop()
    handler = _counted(key_expr, handler, ledger)
    # the subscriber's context: a hosted service's handler logs under its name (common.log)
    context = contextvars.copy_context()

    def on_sample(sample: zenoh.Sample) -> None:
        # Runs on a Zenoh thread: copy out of the sample, then cross over to the loop.
        key = str(sample.key_expr)
        payload = sample.payload.to_bytes()
        try:
            loop.call_soon_threadsafe(handler, key, payload, context=context)
        except RuntimeError:
            pass  # the loop is closed: the service is shutting down

    return session.declare_subscriber(key_expr, on_sample)


def subscribe_threaded(
    session: zenoh.Session, key_expr: str, handler: Handler, *, ledger: Ledger | None = None
) -> zenoh.Subscriber[None]:
    """Call ``handler(key, payload)`` directly on Zenoh's thread (must be thread-safe, quick).
    With a ``ledger`` (lockstep) a message counts as received once ``handler`` returned."""
    handler = _counted(key_expr, handler, ledger)

    def on_sample(sample: zenoh.Sample) -> None:
        handler(str(sample.key_expr), sample.payload.to_bytes())

    return session.declare_subscriber(key_expr, on_sample)


def _counted(key_expr: str, handler: Handler, ledger: Ledger | None) -> Handler:
    """``handler``, counting each message on ``ledger`` after it (common.lockstep)."""
    tally = ledger.tally(key_expr) if ledger is not None else None
    if ledger is None or tally is None:
        return handler
    received = ledger.received

    def counted(key: str, payload: bytes) -> None:
        try:
            handler(key, payload)
        finally:
            received(tally, key)

    return counted


def pack(message: dict[str, Any]) -> bytes:
    """msgpack bytes of a contract message."""
    data: bytes = msgpack.packb(message, use_bin_type=True)
    return data


def unpack(payload: bytes) -> Any:
    """Decode msgpack bytes; raises ValueError (not msgpack's own types) on bad input."""
    try:
        return msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except Exception as exc:
        raise ValueError(f"malformed msgpack payload: {exc}") from exc


@dataclass(frozen=True)
class Notification:
    """A change hint: ``table`` changed for ``robot`` (None: not robot-scoped), newest ``id``.

    Since contract version 3 (docs/ARCHITECTURE.md) a notification may carry ``row``, the image
    of the committed row ``id`` (its contract columns, CONTRACT.md "Row images"), so a reader
    can act on it and skip its query. ``src`` names the publisher (one per process) and ``seq``
    counts its notifications on this key: a reader that sees a ``seq`` skip (or no image)
    reads the table. The table stays the source of truth.
    """

    table: str
    robot: str | None
    id: int | None
    row: Mapping[str, Any] | None = None
    src: str | None = None
    seq: int | None = None

    def encode(self) -> bytes:
        body: dict[str, Any] = {"table": self.table, "robot": self.robot, "id": self.id}
        if self.row is not None:
            body["row"] = dict(self.row)
        if self.src is not None:
            body["src"], body["seq"] = self.src, self.seq
        return pack(body)

    @classmethod
    def decode(cls, key: str, payload: bytes) -> Notification:
        table, robot = keys.parse_notify_key(key)
        body = unpack(payload) if payload else {}
        if not isinstance(body, dict):
            return cls(table, robot, None)
        row_id = body.get("id")
        row_id = row_id if isinstance(row_id, int) else None
        row = body.get("row")
        src, seq = body.get("src"), body.get("seq")
        return cls(
            table,
            robot,
            row_id,
            # an image is only an image of the row it names
            row
            if isinstance(row, dict) and row_id is not None and row.get("id") == row_id
            else None,
            src if isinstance(src, str) else None,
            seq if isinstance(seq, int) else None,
        )


class Notifier:
    """Publishes change notifications as express session puts that are never dropped
    (congestion control BLOCK); each one counted as sent on ``ledger`` in a lockstep run.

    ``images=False`` publishes no row images (PNAV_NOTIFY_IMAGES=off): every reader then
    falls back on its query, which is what a contract test checks.
    """

    def __init__(
        self, session: zenoh.Session, ledger: Ledger | None = None, *, images: bool = True
    ) -> None:
        self._session = session
        self._ledger = ledger
        self.images = images
        self.src = secrets.token_hex(4)
        self._seqs: dict[str, int] = {}
        self._lock = threading.Lock()

    def notify(
        self,
        table: str,
        robot: str | None,
        row_id: int | None,
        row: Mapping[str, Any] | None = None,
    ) -> None:
        """Publish that ``table`` changed for ``robot``; call only after the commit.

        ``row``: the committed row ``row_id``'s image (its contract columns, with ``id``).
        """
        key = keys.notify_key(table, robot)
        with self._lock:
            seq = self._seqs[key] = self._seqs.get(key, 0) + 1
        if self._ledger is not None:
            self._ledger.sent_on(key)
        image = row if self.images and row is not None and row_id is not None else None
        body = Notification(table, robot, row_id, image, self.src, seq).encode()
        # A session-level put, not a declared publisher: a client's freshly declared
        # publisher drops its puts until the router has answered its interest in matching
        # subscribers (writer-side filtering), and so would every robot's first notification
        # on a table (measured: 163 of 300 first puts arrived; a put through a declared
        # publisher key, even via the session, lost 100 to 170 of 300). A session put is
        # routed without that filter (300 of 300) and costs the same here (31 us).
        # Congestion control BLOCK: an express put is a batch of its own, so a link's queue
        # (16 batches) holds 16 notifications; with DROP, a fleet's burst (50 robots' rows
        # of one batch, to each reader) lost every one that found the queue full for 1 ms
        # while the link's thread waited for a core, here and again in the router (600 to
        # 1,420 per service at 50 robots). BLOCK waits for room instead, in the router too
        # (the put carries its congestion control); Zenoh closes a link blocked 5 s.
        self._session.put(key, body, express=True, congestion_control=zenoh.CongestionControl.BLOCK)

    def close(self) -> None:
        """Nothing to undeclare (notifications are session puts); kept for the callers that
        close what they opened."""
        return None
