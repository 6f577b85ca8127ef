"""How ROS 2 entities appear on Zenoh, as rmw_zenoh writes them (sans-IO).

Followed: ros2/rmw_zenoh, ``rmw_zenoh_cpp/src/detail/`` at rolling commit
bfc065f8 (2024-10-16) for key expressions, liveliness tokens, QoS strings and
entity GIDs (``liveliness_utils.cpp``, ``qos.cpp``, ``type_support_common.cpp``),
all unchanged in its Zenoh 1.x line but the session id in tokens, which that line
prints as Zenoh does (``zid_text``); and the Zenoh 1.x attachment of
``attachment_helpers.cpp`` (sequence number, source timestamp, source GID in the
Zenoh serialization format). docs/zenoh.md
shows each form with an example; tests/zenoh/test_wire.py pins them.

- A topic's data key: ``<domain>/<topic without leading or trailing />/<dds type>/<type hash>``,
  e.g. ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...``.
- A liveliness token: ``@ros2_lv/<domain>/<zid>/<nid>/<eid>/<kind>/<enclave>/<namespace>/<node>``
  and, for publishers, subscriptions, services and clients, ``/<topic>/<dds type>/<hash>/<qos>``;
  each name has its ``/`` replaced by ``%`` (so ``/`` alone becomes ``%``).
- A QoS string: ``<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan
  s>,<ns>:<liveliness>,<lease s>,<ns>``, each field empty when it equals rmw_zenoh's default
  (reliable, volatile, keep last 42, infinite durations, automatic liveliness).

rmw_zenoh's default durability changed in March 2025 (rmw_zenoh 0.6 on Jazzy and later,
backported to Humble): before, it was transient local, so an empty durability field meant
transient local; since, it means volatile. ``RmwCompat`` picks which of the two a link
writes and reads (docs/zenoh.md, "Which rmw_zenoh").
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum, StrEnum

from rwt_graph.link import DEFAULT_DEPTH, LATCHED_DEPTH
from rwt_protocol.errors import RemoteProtocolError

__all__ = [
    "ADMIN_SPACE",
    "DEFAULT_QOS",
    "INFINITE",
    "LATCHED_QOS",
    "PRE_2025_DEFAULT_QOS",
    "SERVICES_QOS",
    "VOLATILE_QOS",
    "Attachment",
    "Durability",
    "Entity",
    "EntityKind",
    "History",
    "Liveliness",
    "QoS",
    "Reliability",
    "RmwCompat",
    "WireError",
    "attachment_gid",
    "attachment_source",
    "dds_type_name",
    "demangle",
    "gid_of",
    "mangle",
    "pack_attachment",
    "qos_from_keyexpr",
    "qos_to_keyexpr",
    "reply_attachment",
    "ros_type_name",
    "topic_keyexpr",
]

ADMIN_SPACE = "@ros2_lv"
"""The key prefix of every liveliness token (liveliness_utils.cpp ``ADMIN_SPACE``)."""

INFINITE = (9223372036, 854775807)
"""``RMW_DURATION_INFINITE`` as (seconds, nanoseconds), rmw_zenoh's default durations."""

GID_SIZE = 16
"""``RMW_GID_STORAGE_SIZE`` in bytes."""


class WireError(RemoteProtocolError):
    """A key expression, token, QoS string or attachment that is not rmw_zenoh's form.

    A peer on the Zenoh network sent it: the sample or token is ignored, never trusted.
    """


class EntityKind(StrEnum):
    """The entity field of a liveliness token."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


class Reliability(IntEnum):
    """``rmw_qos_reliability_policy_e`` (rmw/types.h)."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class Durability(IntEnum):
    """``rmw_qos_durability_policy_e``: transient local keeps samples for late joiners."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class History(IntEnum):
    """``rmw_qos_history_policy_e``."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2
    UNKNOWN = 3


class Liveliness(IntEnum):
    """``rmw_qos_liveliness_policy_e``."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_NODE = 2
    MANUAL_BY_TOPIC = 3
    UNKNOWN = 4
    BEST_AVAILABLE = 5


Duration = tuple[int, int]


@dataclass(frozen=True)
class QoS:
    """A QoS profile as rmw_zenoh encodes it in a token (durations as (s, ns))."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 42
    deadline: Duration = INFINITE
    lifespan: Duration = INFINITE
    liveliness: Liveliness = Liveliness.AUTOMATIC
    liveliness_lease: Duration = INFINITE


DEFAULT_QOS = QoS()
"""rmw_zenoh's defaults (qos.cpp): reliable, volatile, keep last 42, infinite durations."""

PRE_2025_DEFAULT_QOS = QoS(durability=Durability.TRANSIENT_LOCAL)
"""rmw_zenoh's defaults before March 2025: the same, but transient local."""


class RmwCompat(StrEnum):
    """Which rmw_zenoh's token defaults a link writes and reads (``--zenoh-rmw-compat``).

    ``current``: rmw_zenoh since March 2025 (Jazzy, Kilted, Rolling, and Humble's
    backport), whose empty durability field is volatile. ``pre-2025``: the releases
    before it, whose empty field is transient local. Both sides of a link must agree:
    otherwise a volatile topic looks latched to one of them and a latched one volatile.
    """

    CURRENT = "current"
    PRE_2025 = "pre-2025"

    @property
    def defaults(self) -> QoS:
        """The profile whose fields a token leaves empty."""
        return DEFAULT_QOS if self is RmwCompat.CURRENT else PRE_2025_DEFAULT_QOS


VOLATILE_QOS = QoS(durability=Durability.VOLATILE, depth=DEFAULT_DEPTH)
"""A plain topic's profile and an action's feedback's (``rmw_qos_profile_default``,
rmw/qos_profiles.h): reliable, volatile, keep last 10."""

SERVICES_QOS = QoS(durability=Durability.VOLATILE, depth=DEFAULT_DEPTH)
"""A service's, a client's and an action's services' profile (``rmw_qos_profile_services_default``,
rmw/qos_profiles.h): reliable, volatile, keep last 10."""

LATCHED_QOS = QoS(durability=Durability.TRANSIENT_LOCAL, depth=LATCHED_DEPTH)
"""A latched topic's profile and an action's status's
(``rcl_action_qos_profile_status_default``): reliable, transient local, keep last 1."""


def qos_to_keyexpr(qos: QoS, defaults: QoS = DEFAULT_QOS) -> str:
    """Encode ``qos`` as rmw_zenoh's token field: defaults are left empty (``qos_to_keyexpr``)."""

    def part(value: int, default: int) -> str:
        return "" if value == default else str(int(value))

    d = defaults
    return ":".join(
        [
            part(qos.reliability, d.reliability),
            part(qos.durability, d.durability),
            f"{part(qos.history, d.history)},{part(qos.depth, d.depth)}",
            f"{part(qos.deadline[0], d.deadline[0])},{part(qos.deadline[1], d.deadline[1])}",
            f"{part(qos.lifespan[0], d.lifespan[0])},{part(qos.lifespan[1], d.lifespan[1])}",
            ",".join(
                [
                    part(qos.liveliness, d.liveliness),
                    part(qos.liveliness_lease[0], d.liveliness_lease[0]),
                    part(qos.liveliness_lease[1], d.liveliness_lease[1]),
                ]
            ),
        ]
    )


def qos_from_keyexpr(text: str, defaults: QoS = DEFAULT_QOS) -> QoS:
    """Decode a token's QoS field (``keyexpr_to_qos``); empty fields take ``defaults``.

    Raises:
        WireError: too few fields, or a value that is not a known policy or a number.
    """
    parts = text.split(":")
    if len(parts) < 6:
        raise WireError(f"qos {text!r}: expected 6 fields separated by ':'")
    history, deadline, lifespan, liveliness = (p.split(",") for p in parts[2:6])
    if min(len(history), len(deadline), len(lifespan)) < 2 or len(liveliness) < 3:
        raise WireError(f"qos {text!r}: a field lacks its ',' parts")
    d = defaults
    try:
        return QoS(
            reliability=Reliability(_int(parts[0], d.reliability)),
            durability=Durability(_int(parts[1], d.durability)),
            history=History(_int(history[0], d.history)),
            depth=_int(history[1], d.depth),
            deadline=(_int(deadline[0], d.deadline[0]), _int(deadline[1], d.deadline[1])),
            lifespan=(_int(lifespan[0], d.lifespan[0]), _int(lifespan[1], d.lifespan[1])),
            liveliness=Liveliness(_int(liveliness[0], d.liveliness)),
            liveliness_lease=(
                _int(liveliness[1], d.liveliness_lease[0]),
                _int(liveliness[2], d.liveliness_lease[1]),
            ),
        )
    except ValueError as exc:
        raise WireError(f"qos {text!r}: {exc}") from None


def _int(text: str, default: int) -> int:
    if not text:
        return int(default)
    if not text.isdigit():  # strtoul: digits only, no sign
        raise ValueError(f"{text!r} is not a number")
    return int(text)


def mangle(name: str) -> str:
    """Replace each ``/`` by ``%``: names become one key chunk (``mangle_name``)."""
    return name.replace("/", "%")


def demangle(name: str) -> str:
    """Undo ``mangle`` (``demangle_name``)."""
    return name.replace("%", "/")


def dds_type_name(ros_type: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs::msg::dds_::String_`` (``_create_type_name``).

    Raises:
        WireError: ``ros_type`` is not ``pkg/kind/Name``.
    """
    parts = ros_type.split("/")
    if len(parts) != 3 or not all(parts):
        raise WireError(f"type {ros_type!r}: expected pkg/msg/Name (or srv, action)")
    package, kind, name = parts
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_name(dds_type: str) -> str:
    """``std_msgs::msg::dds_::String_`` -> ``std_msgs/msg/String`` (graph_cache's demangling).

    Raises:
        WireError: ``dds_type`` is not in rmw_zenoh's form.
    """
    namespace, sep, name = dds_type.partition("::dds_::")
    if not sep or not name.endswith("_") or "::" not in namespace:
        raise WireError(f"type {dds_type!r}: expected pkg::msg::dds_::Name_")
    return f"{namespace.replace('::', '/')}/{name[:-1]}"


def topic_keyexpr(domain_id: int, topic: str, dds_type: str, type_hash: str) -> str:
    """The data key of a topic (or service): ``<domain>/<topic>/<type>/<hash>`` (``TopicInfo``).

    The topic name loses one leading and one trailing ``/``; its inner ``/`` stay,
    so a namespace is a key hierarchy.
    """
    name = topic[1:] if topic.startswith("/") else topic
    name = name[:-1] if name.endswith("/") else name
    return f"{domain_id}/{name}/{dds_type}/{type_hash}"


@dataclass(frozen=True)
class Topic:
    """What a token says of a publisher's, subscription's, service's or client's topic."""

    name: str
    dds_type: str
    type_hash: str
    qos: QoS = field(default=DEFAULT_QOS)


@dataclass(frozen=True)
class Entity:
    """One liveliness token's content.

    Attributes:
        domain_id: the ROS domain (``ROS_DOMAIN_ID``).
        zid: the Zenoh session id, as rmw_zenoh prints it (lowercase hex).
        nid: the node's id within the session (decimal).
        eid: the entity's id within the session (decimal; a node's is its nid).
        kind: node, publisher, subscription, service or client.
        enclave: the node's enclave (``/`` by default).
        namespace: the node's namespace (``/`` for none).
        node: the node's name.
        topic: the topic, type and QoS, for every kind but a node.
        compat: whose defaults the token's QoS field leaves empty.
        received: the token as a peer declared it, for a parsed entity: its GID is
            the hash of that text, whatever this side would write for it.
    """

    domain_id: int
    zid: str
    nid: int
    eid: int
    kind: EntityKind
    namespace: str
    node: str
    enclave: str = "/"
    topic: Topic | None = None
    compat: RmwCompat = field(default=RmwCompat.CURRENT, compare=False)
    received: str | None = field(default=None, compare=False, repr=False)

    def token(self) -> str:
        """The liveliness key expression (``Entity::Entity``: empty parts end it)."""
        parts = [
            ADMIN_SPACE,
            str(self.domain_id),
            self.zid,
            str(self.nid),
            str(self.eid),
            str(self.kind),
            mangle(self.enclave),
            mangle(self.namespace),
            mangle(self.node),
        ]
        if self.topic is not None:
            t = self.topic
            parts += [
                mangle(t.name),
                mangle(t.dds_type),
                mangle(t.type_hash),
                qos_to_keyexpr(t.qos, self.compat.defaults),
            ]
        return "/".join(parts)

    def gid(self) -> bytes:
        """The entity's 16-byte GID: ``gid_of`` its token, as received when it was.

        Raises:
            ModuleNotFoundError: ``xxhash`` (the ``zenoh`` extra) is not installed.
        """
        return gid_of(self.received if self.received is not None else self.token())

    @classmethod
    def parse(cls, token: str, compat: RmwCompat = RmwCompat.CURRENT) -> Entity:
        """Read a liveliness token (``Entity::make(keyexpr)``); empty QoS fields per ``compat``.

        Raises:
            WireError: not under ``@ros2_lv``, an empty or unknown part, or a
                non-node token without its topic parts.
        """
        parts = token.split("/")
        if len(parts) < 9 or parts[0] != ADMIN_SPACE or not all(parts):
            raise WireError(f"token {token!r}: expected {ADMIN_SPACE}/<domain>/... with 9+ parts")
        try:
            kind = EntityKind(parts[5])
            domain_id, nid, eid = int(parts[1]), int(parts[3]), int(parts[4])
        except ValueError as exc:
            raise WireError(f"token {token!r}: {exc}") from None
        topic = None
        if kind is not EntityKind.NODE:
            if len(parts) < 13:
                raise WireError(f"token {token!r}: a {kind.name.lower()} needs its topic parts")
            topic = Topic(
                demangle(parts[9]),
                demangle(parts[10]),
                demangle(parts[11]),
                qos_from_keyexpr(parts[12], compat.defaults),
            )
        return cls(
            domain_id,
            parts[2],
            nid,
            eid,
            kind,
            demangle(parts[7]),
            demangle(parts[8]),
            enclave=demangle(parts[6]),
            topic=topic,
            compat=compat,
            received=token,
        )


def gid_of(text: str) -> bytes:
    """A 16-byte GID as rmw_zenoh derives an entity's from its token.

    XXH3-128 of ``text`` (UTF-8), low then high 64 bits, little endian
    (liveliness_utils.cpp ``Entity::Entity``).

    Raises:
        ModuleNotFoundError: ``xxhash`` (the ``zenoh`` extra) is not installed.
    """
    import xxhash  # noqa: PLC0415 - only the Zenoh link needs GIDs

    digest = xxhash.xxh3_128_intdigest(text.encode())
    return struct.pack("<QQ", digest & (2**64 - 1), digest >> 64)


def zid_text(zid: bytes) -> str:
    """Print a Zenoh id as Zenoh does (``zenoh::Id::to_string``, ``str(zid)`` in Python).

    rmw_zenoh's Zenoh 1.x line writes this form in its tokens (liveliness_utils.cpp
    ``Entity::make``, at 3411fdec): the little-endian u128 in lowercase hex,
    without leading zeros. (The Zenoh 0.11 line, at bfc065f8, printed each byte
    without its leading zero.)
    """
    return f"{int.from_bytes(zid, 'little'):x}"


@dataclass(frozen=True)
class Attachment:
    """What rmw_zenoh attaches to each sample and query (``AttachmentData``).

    Attributes:
        sequence_number: the publisher's count, from 1.
        source_timestamp: nanoseconds since the epoch when it was sent.
        source_gid: the sender's 16-byte GID (``Entity.gid``).
    """

    sequence_number: int
    source_timestamp: int
    source_gid: bytes

    def encode(self) -> bytes:
        """Serialize as ``serialize_to_zbytes`` does, in the Zenoh serialization format.

        Two int64 (little endian), then the GID as a sequence: LEB128 length 16,
        then its bytes.

        Raises:
            WireError: the GID is not 16 bytes.
        """
        return pack_attachment(self.sequence_number, self.source_timestamp, self.source_gid)

    @classmethod
    def decode(cls, data: bytes) -> Attachment:
        """Read an attachment.

        Raises:
            WireError: not 33 bytes of that layout.
        """
        if len(data) != _ATTACHMENT.size or data[16] != GID_SIZE:
            raise WireError(f"attachment of {len(data)} bytes is not rmw_zenoh's")
        sequence_number, source_timestamp, _, gid = _ATTACHMENT.unpack(data)
        return cls(sequence_number, source_timestamp, gid)


_ATTACHMENT = struct.Struct(f"<qqB{GID_SIZE}s")
"""The attachment's layout: two int64, the GID's LEB128 length (one byte), the GID."""


def pack_attachment(sequence_number: int, source_timestamp: int, source_gid: bytes) -> bytes:
    """``Attachment(...).encode()`` without building the object (once per sample sent).

    Raises:
        WireError: the GID is not 16 bytes.
    """
    if len(source_gid) != GID_SIZE:
        raise WireError(f"gid of {len(source_gid)} bytes (expected {GID_SIZE})")
    return _ATTACHMENT.pack(sequence_number, source_timestamp, GID_SIZE, source_gid)


def reply_attachment(request: bytes | None, source_timestamp: int) -> bytes:
    """The attachment of a service's reply to a request carrying ``request``.

    rmw_zenoh's service answers with the request's sequence number and its client's
    GID, and its own source timestamp (rmw_service_data.cpp ``send_response``); a
    ROS 2 client pairs the response with its call by that sequence number
    (rmw_client_data.cpp ``take_response``) and refuses a reply without an
    attachment. A request without rmw_zenoh's attachment (a plain Zenoh ``get``)
    is answered with sequence number 0 and a zero GID.
    """
    try:
        asked = Attachment.decode(request) if request is not None else None
    except WireError:
        asked = None
    if asked is None:
        return pack_attachment(0, source_timestamp, bytes(GID_SIZE))
    return pack_attachment(asked.sequence_number, source_timestamp, asked.source_gid)


def attachment_source(data: bytes) -> tuple[int, bytes]:
    """The sequence number and source GID of an attachment (``Attachment.decode``, cheaper).

    Raises:
        WireError: not 33 bytes of rmw_zenoh's layout.
    """
    if len(data) != _ATTACHMENT.size or data[16] != GID_SIZE:
        raise WireError(f"attachment of {len(data)} bytes is not rmw_zenoh's")
    return _SEQUENCE.unpack_from(data)[0], data[17:]


_SEQUENCE = struct.Struct("<q")


def attachment_gid(data: bytes) -> bytes:
    """The source GID of an attachment (``Attachment.decode(data).source_gid``, cheaper).

    Raises:
        WireError: not 33 bytes of rmw_zenoh's layout.
    """
    if len(data) != _ATTACHMENT.size or data[16] != GID_SIZE:
        raise WireError(f"attachment of {len(data)} bytes is not rmw_zenoh's")
    return data[17:]
