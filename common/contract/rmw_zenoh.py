"""ROS 2 names as rmw_zenoh puts them on Zenoh: key expressions, liveliness tokens, attachments.

A ROS 2 node on rmw_zenoh (ros2/rmw_zenoh, docs/design.md) publishes a topic on

    ``<domain_id>/<fully qualified name, no leading slash>/<DDS type name>/<RIHS01 hash>``

with a CDR payload and a 33-byte attachment (sequence number, source timestamp, publisher
GID), and announces every node, publisher and subscription with a liveliness token under the
hermetic prefix ``@ros2_lv/<domain_id>/...``; ``ros2 node list`` and ``ros2 topic list`` are
built from those tokens. This module is that mapping and nothing else (no Zenoh, no CDR): the
bridge's ROS 2 link and the sim's ROS 2 wire both take their keys from here, as every pnav key
comes from :mod:`common.contract.keys`. Its tests are the design document's own examples.
"""

from __future__ import annotations

import hashlib
import re
import struct
from dataclasses import dataclass
from typing import Final

ADMIN_SPACE: Final = "@ros2_lv"
# entity kinds of a liveliness token
NODE: Final = "NN"
PUBLISHER: Final = "MP"
SUBSCRIPTION: Final = "MS"
SERVICE_SERVER: Final = "SS"
SERVICE_CLIENT: Final = "SC"
KINDS: Final = (NODE, PUBLISHER, SUBSCRIPTION, SERVICE_SERVER, SERVICE_CLIENT)

# ROS_DOMAIN_ID: DDS allows 0..232 on every platform; rmw_zenoh keeps the same range of use
MAX_DOMAIN_ID: Final = 232
GID_BYTES: Final = 16
# rmw's RMW_DURATION_INFINITE as (sec, nsec): int64 max nanoseconds
INFINITE: Final = (9_223_372_036_854, 775_807)
ATTACHMENT_BYTES: Final = 8 + 8 + 1 + GID_BYTES

# a ROS 2 name's tokens (design.ros2.org, "Topic and Service name mapping"): alphanumerics
# and underscores, not starting with a digit, separated by single slashes
_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_NAME = re.compile(rf"^/?{_TOKEN}(/{_TOKEN})*$")
_NAMESPACE = re.compile(rf"^(/|(/{_TOKEN})+)$")
# an action's services and feedback are named under its package's ``action`` kind
_TYPE = re.compile(rf"^({_TOKEN})/(msg|srv|action)/({_TOKEN})$")
_DDS_TYPE = re.compile(rf"^({_TOKEN})::(msg|srv|action)::dds_::({_TOKEN})_$")
_HASH = re.compile(r"^RIHS01_[0-9a-f]{64}$")


def check_domain(domain_id: int) -> int:
    if isinstance(domain_id, bool) or not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise ValueError(f"ROS domain id {domain_id!r} must be 0 to {MAX_DOMAIN_ID}")
    return domain_id


def namespace_of(namespace: str) -> str:
    """``""``, ``"/"``, ``"robot1"``, ``"/robot1/"`` -> ``"/"``, ``"/"``, ``"/robot1"``..."""
    ns = "/" + namespace.strip("/")
    if not _NAMESPACE.match(ns):
        raise ValueError(f"not a ROS 2 namespace: {namespace!r}")
    return ns


def fully_qualified(namespace: str, name: str) -> str:
    """The fully qualified name of ``name`` in ``namespace``: an absolute ``name`` (``/tf``)
    ignores the namespace, a relative one (``scan``) goes under it (``/robot1/scan``)."""
    if not _NAME.match(name):
        raise ValueError(f"not a ROS 2 topic name: {name!r}")
    if name.startswith("/"):
        return name
    ns = namespace_of(namespace)
    return f"{ns}/{name}" if ns != "/" else f"/{name}"


def mangle(name: str) -> str:
    """A name inside one key chunk: each ``/`` becomes ``%``; the empty name is ``%``."""
    return name.replace("/", "%") if name else "%"


def _type_parts(pattern: re.Pattern[str], type_name: str, what: str) -> tuple[str, str, str]:
    """(package, kind, name) of ``type_name`` as ``pattern`` reads it; ValueError if it is
    not ``what``. The two spellings of a type differ only in their separators."""
    match = pattern.match(type_name)
    if match is None:
        raise ValueError(f"not {what}: {type_name!r}")
    package, kind, name = match.groups()
    return package, kind, name


def dds_type(ros_type: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs::msg::dds_::String_`` (the type name in keys)."""
    package, kind, name = _type_parts(_TYPE, ros_type, "a ROS 2 type name")
    return f"{package}::{kind}::dds_::{name}_"


def ros_type(dds_name: str) -> str:
    """The inverse of :func:`dds_type`."""
    package, kind, name = _type_parts(_DDS_TYPE, dds_name, "a DDS type name")
    return f"{package}/{kind}/{name}"


def topic_key(domain_id: int, topic: str, type_name: str, type_hash: str) -> str:
    """The key expression of a topic (``topic`` fully qualified, ``type_name`` as
    ``pkg/msg/Name``): the same for its publishers and its subscriptions."""
    if not _HASH.match(type_hash):
        raise ValueError(f"not a RIHS01 type hash: {type_hash!r}")
    name = fully_qualified("/", topic).strip("/")
    return f"{check_domain(domain_id)}/{name}/{dds_type(type_name)}/{type_hash}"


@dataclass(frozen=True)
class QoS:
    """A ROS 2 QoS profile with rmw's enum values; the defaults are rmw_zenoh's
    (RELIABLE, VOLATILE, KEEP_LAST 42, infinite durations, AUTOMATIC liveliness)."""

    reliability: int = 1  # 1 RELIABLE, 2 BEST_EFFORT
    durability: int = 2  # 1 TRANSIENT_LOCAL, 2 VOLATILE
    history: int = 1  # 1 KEEP_LAST, 2 KEEP_ALL
    depth: int = 42
    deadline: tuple[int, int] = INFINITE
    lifespan: tuple[int, int] = INFINITE
    liveliness: int = 1  # 1 AUTOMATIC
    lease: tuple[int, int] = INFINITE

    def chunk(self) -> str:
        """The QoS in a token's last chunk: each field that differs from rmw_zenoh's default,
        empty where it is the default (``::,10:,:,:,,`` is the default with depth 10)."""
        d = QoS()

        def field(value: object, default: object) -> str:
            return "" if value == default else str(value)

        def pair(value: tuple[int, int], default: tuple[int, int]) -> str:
            return f"{field(value[0], default[0])},{field(value[1], default[1])}"

        return ":".join(
            (
                field(self.reliability, d.reliability),
                field(self.durability, d.durability),
                f"{field(self.history, d.history)},{field(self.depth, d.depth)}",
                pair(self.deadline, d.deadline),
                pair(self.lifespan, d.lifespan),
                f"{field(self.liveliness, d.liveliness)},{pair(self.lease, d.lease)}",
            )
        )


TRANSIENT_LOCAL: Final = 1  # QoS.durability
RELIABLE: Final = QoS(depth=10)
SENSOR_DATA: Final = QoS(reliability=2, depth=5)  # rclcpp's SensorDataQoS
LATCHED: Final = QoS(durability=1, depth=1)  # a map server's /map


@dataclass(frozen=True)
class NodeName:
    domain_id: int
    session_id: str  # the Zenoh session id, as hex
    node_id: int  # the node's number within its session
    namespace: str
    name: str
    enclave: str = ""


def node_token(node: NodeName) -> str:
    """The liveliness token announcing a node (``ros2 node list``)."""
    return "/".join(_node_chunks(node, node.node_id, NODE))


def entity_token(
    node: NodeName,
    entity_id: int,
    kind: str,
    topic: str,
    type_name: str,
    type_hash: str,
    qos: QoS,
) -> str:
    """The liveliness token of a publisher, subscription, service server or client of
    ``node`` (``topic`` fully qualified or relative to the node's namespace)."""
    if kind not in KINDS or kind == NODE:
        raise ValueError(f"not an endpoint kind: {kind!r}")
    if not _HASH.match(type_hash):
        raise ValueError(f"not a RIHS01 type hash: {type_hash!r}")
    fqn = fully_qualified(node.namespace, topic)
    chunks = [*_node_chunks(node, entity_id, kind), mangle(fqn), dds_type(type_name)]
    return "/".join([*chunks, type_hash, qos.chunk()])


def _node_chunks(node: NodeName, entity_id: int, kind: str) -> list[str]:
    if not re.match(rf"^{_TOKEN}$", node.name):
        raise ValueError(f"not a ROS 2 node name: {node.name!r}")
    if not re.match(r"^[0-9a-f]+$", node.session_id):
        raise ValueError(f"not a Zenoh session id: {node.session_id!r}")
    ns = namespace_of(node.namespace)
    return [
        ADMIN_SPACE,
        str(check_domain(node.domain_id)),
        node.session_id,
        str(node.node_id),
        str(entity_id),
        kind,
        mangle(node.enclave.strip("/") and "/" + node.enclave.strip("/")),
        mangle("" if ns == "/" else ns),
        node.name,
    ]


@dataclass(frozen=True)
class Token:
    """A liveliness token read back (the graph as ``ros2 node list`` sees it)."""

    domain_id: int
    session_id: str
    node_id: int
    entity_id: int
    kind: str
    namespace: str  # "/" for none
    node: str
    topic: str | None = None  # fully qualified
    type_name: str | None = None  # pkg/msg/Name
    type_hash: str | None = None


def parse_token(key: str) -> Token:
    """A liveliness key -> :class:`Token`; ValueError if it is not one of rmw_zenoh's."""
    parts = key.split("/")
    if len(parts) not in (9, 13) or parts[0] != ADMIN_SPACE or parts[5] not in KINDS:
        raise ValueError(f"not an rmw_zenoh liveliness token: {key!r}")
    if (len(parts) == 9) != (parts[5] == NODE):
        raise ValueError(f"entity kind {parts[5]} with {len(parts)} chunks: {key!r}")
    try:
        domain, node_id, entity_id = int(parts[1]), int(parts[3]), int(parts[4])
    except ValueError:
        raise ValueError(f"non-numeric ids in {key!r}") from None
    ns = parts[7].replace("%", "/") if parts[7] != "%" else "/"
    if len(parts) == 9:
        return Token(domain, parts[2], node_id, entity_id, NODE, ns, parts[8])
    return Token(
        domain,
        parts[2],
        node_id,
        entity_id,
        parts[5],
        ns,
        parts[8],
        topic=parts[9].replace("%", "/"),
        type_name=ros_type(parts[10]),
        type_hash=parts[11],
    )


def graph_watch(domain_id: int) -> str:
    """Every liveliness token of a domain (a hermetic prefix: ``**`` alone never matches)."""
    return f"{ADMIN_SPACE}/{check_domain(domain_id)}/**"


def gid_of(token: str) -> bytes:
    """A stable 16-byte GID for the entity a token names. rmw_zenoh hashes the token too
    (xxHash3-128); a GID need only be unique and stable, so ours is BLAKE2b's."""
    return hashlib.blake2b(token.encode(), digest_size=GID_BYTES).digest()


@dataclass(frozen=True)
class Attachment:
    """What rides with every sample: the publisher's sequence number, the source timestamp
    (ns since the Unix epoch) and the publisher's GID, little-endian, 33 bytes."""

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes

    def encode(self) -> bytes:
        if len(self.gid) != GID_BYTES:
            raise ValueError(f"a GID has {GID_BYTES} bytes, not {len(self.gid)}")
        head = struct.pack("<qqB", self.sequence_number, self.source_timestamp_ns, GID_BYTES)
        return head + self.gid

    @classmethod
    def decode(cls, data: bytes) -> Attachment:
        """ValueError unless ``data`` is one attachment (a GID of 16 bytes, nothing more)."""
        if len(data) != ATTACHMENT_BYTES:
            raise ValueError(f"an attachment has {ATTACHMENT_BYTES} bytes, not {len(data)}")
        seq, stamp, gid_len = struct.unpack_from("<qqB", data)
        if gid_len != GID_BYTES:
            raise ValueError(f"attachment GID length {gid_len}, not {GID_BYTES}")
        return cls(seq, stamp, bytes(data[17:]))
