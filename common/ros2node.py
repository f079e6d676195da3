"""A ROS 2 node on Zenoh as rmw_zenoh makes one: liveliness tokens, keys, attachments.

No ROS installation: a plain Zenoh session whose node, publishers and subscriptions announce
themselves with rmw_zenoh's liveliness tokens (so ``ros2 node list`` and ``ros2 topic list``
on an rmw_zenoh machine list them), whose samples are CDR with rmw_zenoh's 33-byte
attachment; a service server is a complete queryable whose replies carry the request's
sequence number and client GID. The names come from :mod:`common.contract.rmw_zenoh`, the
types from :mod:`common.ros2types`. Used by the bridge's ROS 2 link, by the sim as a ROS 2
robot and by the action servers (:mod:`common.ros2action`).

A subscription here takes any type on its topic (``<domain>/<topic>/*/*``) and reports what
the key names, so a publisher of the wrong type or type hash is counted, not silently unmatched.
"""

from __future__ import annotations

import contextlib
import itertools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh
import zenoh.ext as zenoh_ext

from common import ros2types
from common.contract import rmw_zenoh as rz

# a transient-local publisher's heartbeat, which lets subscriptions see a missed last sample
HEARTBEAT_S = 1.0
# (key, payload, attachment or None), on Zenoh's thread
SampleHandler = Callable[[str, bytes, bytes | None], None]


@dataclass
class ServiceCall:
    """One request to a service server: its CDR payload and rmw_zenoh attachment (None when
    the client sent none, or not 33 bytes of one). :meth:`reply` answers it, once, at any
    time and from any thread; :meth:`drop` lets it go unanswered."""

    key: str
    payload: bytes
    attachment: rz.Attachment | None
    _query: Any
    _lock: threading.Lock

    def reply(self, payload: bytes) -> bool:
        """Send the response (CDR). Its attachment carries the request's sequence number and
        the client's GID, as rmw_zenoh's server's, by which the client matches it to the
        request. False if the call was answered or dropped already."""
        with self._lock:
            query, self._query = self._query, None
        if query is None:
            return False
        att = self.attachment
        seq, gid = (0, bytes(rz.GID_BYTES)) if att is None else (att.sequence_number, att.gid)
        try:
            query.reply(
                query.key_expr, payload, attachment=rz.Attachment(seq, time.time_ns(), gid).encode()
            )
        except Exception:  # the querier is gone or the session closed: nothing to answer
            return False
        finally:
            with contextlib.suppress(Exception):
                query.drop()
        return True

    def drop(self) -> None:
        with self._lock:
            query, self._query = self._query, None
        if query is not None:
            with contextlib.suppress(Exception):
                query.drop()


# a service request, on Zenoh's thread
ServiceHandler = Callable[[ServiceCall], None]


@dataclass
class Publisher:
    key: str
    gid: bytes
    type_name: str
    _session: zenoh.Session
    _token: Any
    _seq: itertools.count[int]
    _lock: threading.Lock
    # a transient-local publisher's: keeps its last samples for late subscriptions
    _advanced: Any = None

    def put(self, msg: Any, *, reliable: bool = False) -> int:
        """Send ``msg`` (a rosbags message of this publisher's type) as CDR; returns the
        sequence number its attachment carries."""
        return self.put_cdr(ros2types.encode(self.type_name, msg), reliable=reliable)

    def put_cdr(self, payload: bytes, *, reliable: bool = False) -> int:
        with self._lock:
            seq = next(self._seq)
        attachment = rz.Attachment(seq, time.time_ns(), self.gid).encode()
        if self._advanced is not None:
            self._advanced.put(payload, attachment=attachment)
            return seq
        # session puts, not a declared publisher: a client's fresh publisher drops its first
        # puts until the router has answered its interest (common/bus.py, Notifier)
        self._session.put(
            self.key,
            payload,
            attachment=attachment,
            congestion_control=(
                zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
            ),
            express=True,
        )
        return seq


class Ros2Node:
    """One ROS 2 node on ``session`` (the session is the caller's; :meth:`close` undeclares
    only what the node declared)."""

    def __init__(
        self, session: zenoh.Session, domain_id: int, name: str, namespace: str = "/"
    ) -> None:
        self.session = session
        self.domain_id = rz.check_domain(domain_id)
        self.name = rz.NodeName(domain_id, str(session.info.zid()), 0, namespace, name)
        self._entity_ids = itertools.count(1)
        self._entities: list[Any] = [session.liveliness().declare_token(rz.node_token(self.name))]

    def topic(self, name: str) -> str:
        return rz.fully_qualified(self.name.namespace, name)

    def key(self, topic: str, type_name: str) -> str:
        t = ros2types.ros_type(type_name)
        return rz.topic_key(self.domain_id, self.topic(topic), t.name, t.hash)

    def _token(self, kind: str, topic: str, type_name: str, qos: rz.QoS) -> tuple[str, Any]:
        t = ros2types.ros_type(type_name)
        token = rz.entity_token(self.name, next(self._entity_ids), kind, topic, t.name, t.hash, qos)
        declared = self.session.liveliness().declare_token(token)
        self._entities.append(declared)
        return token, declared

    def publisher(self, topic: str, type_name: str, qos: rz.QoS = rz.RELIABLE) -> Publisher:
        """A publisher; a TRANSIENT_LOCAL one (a map server's ``/map``) keeps its last
        ``depth`` samples for subscriptions that come later, as rmw_zenoh's does (Zenoh's
        advanced publisher: a cache, and publisher detection)."""
        token, declared = self._token(rz.PUBLISHER, topic, type_name, qos)
        key = self.key(topic, type_name)
        advanced = None
        if qos.durability == rz.TRANSIENT_LOCAL:
            advanced = zenoh_ext.declare_advanced_publisher(
                self.session,
                key,
                cache=zenoh_ext.CacheConfig(max(qos.depth, 1)),
                # sequence numbers, as rmw_zenoh's reliable transient-local publisher: the
                # cache then needs no timestamping in the session's configuration
                sample_miss_detection=zenoh_ext.MissDetectionConfig(
                    heartbeat=HEARTBEAT_S, sporadic_heartbeat=None
                ),
                publisher_detection=True,
            )
            self._entities.append(advanced)
        return Publisher(
            key,
            rz.gid_of(token),
            type_name,
            self.session,
            declared,
            itertools.count(1),
            threading.Lock(),
            advanced,
        )

    def subscription(
        self, topic: str, type_name: str, handler: SampleHandler, qos: rz.QoS = rz.RELIABLE
    ) -> str:
        """Subscribe ``topic`` announced as ``type_name``; ``handler`` gets every sample on
        the topic whatever type its key names (see :func:`type_of_key`). Returns the key
        expression a sample of the right type arrives on."""
        self._token(rz.SUBSCRIPTION, topic, type_name, qos)
        fqn = self.topic(topic).strip("/")

        def on_sample(sample: zenoh.Sample) -> None:
            attachment = sample.attachment
            handler(
                str(sample.key_expr),
                sample.payload.to_bytes(),
                None if attachment is None else attachment.to_bytes(),
            )

        key_expr = f"{self.domain_id}/{fqn}/*/*"
        if qos.durability == rz.TRANSIENT_LOCAL:
            # a late joiner: asks every transient-local publisher, now and later, for what it
            # kept (rmw_zenoh's transient-local subscription is this advanced subscriber)
            history = zenoh_ext.HistoryConfig(
                detect_late_publishers=True, max_samples=max(qos.depth, 1)
            )
            subscriber: Any = zenoh_ext.declare_advanced_subscriber(
                self.session, key_expr, on_sample, history=history, subscriber_detection=True
            )
        else:
            subscriber = self.session.declare_subscriber(key_expr, on_sample)
        self._entities.append(subscriber)
        return self.key(topic, type_name)

    def service(
        self, name: str, type_name: str, handler: ServiceHandler, qos: rz.QoS = rz.RELIABLE
    ) -> str:
        """A service server (``type_name``: the service type, ``pkg/srv/Name`` or an action's
        ``pkg/action/Name_SendGoal``): a complete queryable on the service's key, announced
        with an ``SS`` token, as rmw_zenoh declares one. Returns the key."""
        self._token(rz.SERVICE_SERVER, name, type_name, qos)
        key = self.key(name, type_name)

        def on_query(query: zenoh.Query) -> None:
            payload = b"" if query.payload is None else query.payload.to_bytes()
            raw = query.attachment
            try:
                attachment = None if raw is None else rz.Attachment.decode(raw.to_bytes())
            except ValueError:
                attachment = None
            handler(ServiceCall(str(query.key_expr), payload, attachment, query, threading.Lock()))

        self._entities.append(self.session.declare_queryable(key, on_query, complete=True))
        return key

    def close(self) -> None:
        for entity in reversed(self._entities):
            try:
                entity.undeclare()
            except Exception:  # the session is closed already
                pass
        self._entities.clear()


def type_of_key(key: str) -> tuple[str, str]:
    """The (DDS type name, type hash) chunks a topic key ends with."""
    parts = key.rsplit("/", 2)
    if len(parts) != 3:
        raise ValueError(f"not a topic key: {key!r}")
    return parts[1], parts[2]
