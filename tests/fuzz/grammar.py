"""The rosbridge op grammar as data, and seeded generators of valid and hostile frames.

Plain ``random.Random`` functions, so the hypothesis strategies (``strategies.py``)
and the one-million-frame benchmark (``benchmarks/fuzz.py``, B18) share one grammar.
Fields follow ``src/rwt_protocol/ops/`` (spec 3.1-3.3); every op of the spec appears.
"""

from __future__ import annotations

import json
import random
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cbor2

Gen = Callable[[random.Random], Any]

RESERVED_NAMES = (
    "/rosapi/topics",
    "/rosapi/get_param",
    "/rosapi/services",
    "/tf2_web_republisher",
    "/republish_tfs",
    "/client_count",
    "/connected_clients",
)
BAD_ROS_NAMES = ("", "/", "//a", "a b", "1abc", "/a/", "~", "/a//b", "/a-b", "/ä", "/a/../b")


@dataclass(frozen=True)
class Raw:
    """Literal JSON text to splice in where ``json`` cannot write it (huge ints, -0)."""

    text: str


def _name(rng: random.Random) -> str:
    return rng.choice(("/fuzz", "/fuzz/a", "fuzz_b", "/chatter", "/rosapi/topics"))


def _type(rng: random.Random) -> str:
    return rng.choice(("std_msgs/String", "std_msgs/msg/Int32", "std_srvs/SetBool"))


def _id(rng: random.Random) -> Any:
    return rng.choice((f"fz{rng.randrange(100)}", rng.randrange(1000)))


def _msg(rng: random.Random) -> Any:
    return rng.choice(({"data": "x"}, {"data": rng.randrange(100)}, {}))


def _compression(rng: random.Random) -> str:
    return rng.choice(("none", "cbor", "cbor-raw", "png"))


def _bool(rng: random.Random) -> bool:
    return rng.random() < 0.5


def _small(rng: random.Random) -> int:
    return rng.randrange(0, 10)


def _positive(rng: random.Random) -> int:
    return rng.randrange(1, 4)


def _const(value: Any) -> Gen:
    return lambda rng: value


# op -> (required fields, optional fields): field -> valid value generator
OPS: dict[str, tuple[dict[str, Gen], dict[str, Gen]]] = {
    "advertise": (
        {"topic": _name, "type": _type},
        {"id": _id, "latch": _bool, "queue_size": _small},
    ),
    "unadvertise": ({"topic": _name}, {"id": _id}),
    "publish": ({"topic": _name, "msg": _msg}, {"id": _id, "latch": _bool}),
    "subscribe": (
        {"topic": _name},
        {
            "type": _type,
            "id": _id,
            "throttle_rate": _small,
            "queue_length": _small,
            "fragment_size": _positive,
            "compression": _compression,
        },
    ),
    "unsubscribe": ({"topic": _name}, {"id": _id}),
    "call_service": (
        {"service": _name},
        {
            "args": _msg,
            "id": _id,
            "fragment_size": _positive,
            "compression": _compression,
            "type": _type,
            "timeout": lambda rng: rng.choice((0.05, 1.0)),
        },
    ),
    "advertise_service": ({"service": _name, "type": _type}, {"id": _id}),
    "unadvertise_service": ({"service": _name}, {"id": _id}),
    "service_response": (
        {"service": _name, "result": _bool},
        {"values": _msg, "id": _id},
    ),
    "send_action_goal": (
        {"action": _name, "action_type": _type},
        {
            "args": _msg,
            "id": _id,
            "feedback": _bool,
            "fragment_size": _positive,
            "compression": _compression,
        },
    ),
    "cancel_action_goal": ({"action": _name, "id": _id}, {}),
    "advertise_action": ({"action": _name, "type": _type}, {"id": _id}),
    "unadvertise_action": ({"action": _name}, {"id": _id}),
    "action_feedback": ({"action": _name, "id": _id}, {"values": _msg}),
    "action_result": (
        {"action": _name, "id": _id, "result": _bool},
        {"values": _msg, "status": lambda rng: rng.choice((4, 6, 2))},
    ),
    "set_level": (
        {"level": lambda rng: rng.choice(("info", "warning", "error", "none"))},
        {"id": _id},
    ),
    "fragment": (
        {
            "id": _id,
            "data": lambda rng: rng.choice(('{"op":"publ', 'ish","topic":"/f"}', "")),
            "num": _small,
            "total": _positive,
        },
        {},
    ),
    "png": (
        {"data": lambda rng: rng.choice(("iVBORw0KGgo=", "AAAA", "not base64!"))},
        {"id": _id, "num": _small, "total": _positive},
    ),
    "auth": (
        {
            "mac": _const("00" * 32),
            "client": _const("127.0.0.1"),
            "dest": _const("127.0.0.1"),
            "rand": _const("r"),
            "t": _const(1.7e9),
            "level": _const("admin"),
            "end": _const(1.8e9),
        },
        {},
    ),
    "status": (
        {"level": lambda rng: rng.choice(("info", "warning", "error")), "msg": _const("m")},
        {"id": _id},
    ),
}
OP_NAMES = tuple(OPS)


def _deep(rng: random.Random) -> Any:
    depth = rng.choice((100, 1000, 5000, 50_000))
    value: Any = "leaf"
    for _ in range(depth):
        value = [value] if rng.random() < 0.5 else {"a": value}
    return value


HOSTILE: tuple[Gen, ...] = (
    _const("\ud800"),  # lone surrogate
    _const("a\udfffb"),
    _const("\U0001f916\U00010000"),  # astral characters
    _const(""),
    lambda rng: "x" * rng.choice((256, 10_000, 200_000)),  # overlong string
    lambda rng: Raw("9" * rng.choice((4301, 5000, 20_000))),  # int over Python's 4300 digits
    lambda rng: Raw("-" + "1" * 4400),
    _const(2**64),
    _const(-(2**63) - 1),
    _const(Raw("-0")),
    _const(-0.0),
    _const(Raw("NaN")),
    _const(Raw("Infinity")),
    _const(Raw("-Infinity")),
    _const(Raw("1e400")),
    _const(None),
    _const(True),
    _const([]),
    _const({}),
    _const([1, "a", None]),
    _const({"op": "publish"}),
    lambda rng: list(range(rng.choice((1000, 50_000)))),  # big arrays, within size limit
    _deep,
    lambda rng: rng.choice(RESERVED_NAMES),
    lambda rng: rng.choice(BAD_ROS_NAMES),
    _const("/rosapi/*"),
    _const("\x00"),
    _const("é" * 3),
)


def _nested_text(rng: random.Random) -> str:
    depth = rng.choice((101, 2000, 100_000))
    return "[" * depth + "]" * depth


# JSON texts of rosapi parameter values (``set_param`` ``value``, ``get_param``
# ``default_value``): what roslibjs sends as ``JSON.stringify(value)``, and worse.
PARAM_TEXTS: tuple[Gen, ...] = (
    _const("1.5"),
    _const('"fast"'),
    _const("[1, 2, 3]"),
    _const('"\\ud800"'),  # a lone surrogate, escaped as JSON writes it
    _const('["ok", "\\udfff"]'),
    _const('{"k": "\\ud83d"}'),
    _nested_text,
    _const(str(2**70)),  # past 64 bits
    lambda rng: "9" * rng.choice((4301, 20_000)),  # past Python's 4300 digits
    _const("NaN"),
    _const("[Infinity, -Infinity]"),
    _const("1e400"),
    lambda rng: json.dumps("x" * rng.choice((10_000, 200_000))),  # giant string
    _const(""),
    _const("not json"),
)
PARAM_NAMES = ("/rosapi:fuzz", "/rosapi:fuzz_b", "/nowhere:p", "bad name")


def param_op(rng: random.Random) -> dict[str, Any]:
    """A rosapi ``set_param`` or ``get_param`` call whose JSON text is from ``PARAM_TEXTS``."""
    name, text = rng.choice(PARAM_NAMES), rng.choice(PARAM_TEXTS)(rng)
    if rng.random() < 0.6:
        service, args = "/rosapi/set_param", {"name": name, "value": text}
    else:
        service, args = "/rosapi/get_param", {"name": name, "default_value": text}
    return {"op": "call_service", "service": service, "args": args, "id": _id(rng)}


def valid_op(rng: random.Random, name: str | None = None) -> dict[str, Any]:
    """A well-formed op ``name`` (random if None), with some of its optional fields."""
    name = name or rng.choice(OP_NAMES)
    required, optional = OPS[name]
    op: dict[str, Any] = {"op": name}
    op |= {field: gen(rng) for field, gen in required.items()}
    op |= {field: gen(rng) for field, gen in optional.items() if rng.random() < 0.4}
    return op


def hostile_value(rng: random.Random) -> Any:
    """One hostile value (see ``HOSTILE``)."""
    return rng.choice(HOSTILE)(rng)


def hostile_op(rng: random.Random, name: str | None = None) -> dict[str, Any]:
    """A valid op with one to three fields (``op`` included, rarely) made hostile."""
    op = valid_op(rng, name)
    fields = [*OPS[op["op"]][0], *OPS[op["op"]][1], "id", "extra"]
    for field in rng.sample(fields, k=min(len(fields), rng.randint(1, 3))):
        op[field] = hostile_value(rng)
    if rng.random() < 0.03:
        op["op"] = hostile_value(rng)
    return op


def to_json(op: Any) -> bytes:
    """JSON text of ``op``: lone surrogates as ``\\ud800`` escapes, ``Raw`` spliced in."""
    raws: list[str] = []

    def splice(value: object) -> str:
        if not isinstance(value, Raw):
            raise TypeError(type(value).__name__)
        raws.append(value.text)
        return f"\x00RAW{len(raws) - 1}\x00"

    try:
        text = json.dumps(op, default=splice, allow_nan=True)
    except RecursionError:
        return b'{"op":"publish","topic":"/fuzz","msg":' + b"[" * 100_000 + b"]" * 100_000 + b"}"
    for index, raw in enumerate(raws):
        text = text.replace(f'"\\u0000RAW{index}\\u0000"', raw)
    return text.encode()


def _cbor_value(value: Any) -> Any:
    if isinstance(value, Raw):
        text = value.text
        if text.lstrip("-").isdigit() and len(text) > 20:
            return cbor2.CBORTag(2 if not text.startswith("-") else 3, b"\xff" * (len(text) // 2))
        return {"-0": -0.0, "NaN": float("nan")}.get(text, float("inf"))
    if isinstance(value, dict):
        return {k: _cbor_value(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_cbor_value(v) for v in value]
    return value


def to_cbor(op: Any) -> bytes:
    """CBOR of ``op`` (``Raw`` huge ints as bignum tags; lone surrogates as text)."""
    try:
        return cbor2.dumps(_cbor_value(op))
    except (RecursionError, ValueError, UnicodeEncodeError, cbor2.CBOREncodeError):
        return b"\xa2bopgpublishcmsg" + b"\x81" * 50_000 + b"\x00"


def raw_frames(rng: random.Random) -> tuple[bytes, bool]:
    """A hostile frame that no encoder writes: (bytes, binary)."""
    choice = rng.randrange(14)
    big = rng.choice((100, 4000))
    frames: list[tuple[bytes, bool]] = [
        (b'{"op":"publish","topic":"/f\xff\xfe","msg":{}}', False),  # invalid UTF-8
        (b'{"op":"set_level","level":"info","id":"\xed\xa0\x80"}', False),  # CESU surrogate
        (bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64))), False),
        (b"not json", False),
        (b'{"op":"publish","topic":', False),  # truncated
        (b"[" * big * 25, False),
        (b'{"op":"call_service","service":"/rosapi/topics","id":' + b"1" * 5000 + b"}", False),
        (b"\xa1bop\xc2\x59\x10\x00" + b"\xff" * 4096, True),  # op: a 4096-byte bignum
        (b"\xa2bopgpublishcmsg" + b"\xd9\xd9\xf7" * big + b"\x00", True),  # stacked tags
        (b"\xa2bopgpublishcmsg" + b"\x81" * big * 25 + b"\x00", True),  # deep arrays
        (b"\xa2bopgpublishcmsg\xa1", True),  # truncated CBOR
        (b"\xbf\x62op\x67publish\xff", True),  # indefinite map
        (b"\xa1\x62op\x7f\x61a\xff", True),  # indefinite text
        (b"\xa1\xfb\x7f\xf8\x00\x00\x00\x00\x00\x00\x01", True),  # NaN key
    ]
    return frames[choice]


def fuzz_frame(rng: random.Random, *, binary_ok: bool = True) -> tuple[bytes, bool]:
    """One fuzzed frame (bytes, binary): valid, parameter, hostile JSON or CBOR op, or raw bytes."""
    kind = rng.random()
    if kind < 0.15:
        op = valid_op(rng)
    elif kind < 0.25:
        op = param_op(rng)
    elif kind < 0.85:
        op = hostile_op(rng)
    else:
        data, binary = raw_frames(rng)
        if binary and not binary_ok:
            return data.hex().encode(), False
        return data, binary
    if binary_ok and rng.random() < 0.2:
        return to_cbor(op), True
    return to_json(op), False


# ---- the bag player's services (docs/record-replay.md) -----------------------

PLAYER_SERVICES = ("/rwt/player/seek", "/rwt/player/pause", "/rwt/player/resume")
PLAYER_TYPES = {
    "/rwt/player/seek": "rwt_msgs/Seek",
    "/rwt/player/pause": "std_srvs/Trigger",
    "/rwt/player/resume": "std_srvs/Trigger",
    "/rwt/player/get_status": "rwt_msgs/GetPlayerStatus",
}
SEEK_OFFSETS: tuple[Gen, ...] = (
    lambda rng: rng.uniform(-1.0, 3.0),
    _const(0.0),
    _const(Raw("NaN")),
    _const(Raw("Infinity")),
    _const(Raw("-Infinity")),
    _const(Raw("1e400")),
    _const(-1e300),
    _const(1e300),
    _const(2**64),
    _const("0.5"),
    _const(None),
    _const([0.5]),
)


def player_call(rng: random.Random) -> dict[str, Any]:
    """A ``call_service`` of a player service: valid, or with a hostile offset or field."""
    service = rng.choice((*PLAYER_SERVICES, "/rwt/player/get_status"))
    args: Any = {}
    if service == "/rwt/player/seek":
        args = {"offset": rng.choice(SEEK_OFFSETS)(rng)}
    op: dict[str, Any] = {"op": "call_service", "service": service, "args": args, "id": _id(rng)}
    if rng.random() < 0.3:
        op["type"] = PLAYER_TYPES[service]
    if rng.random() < 0.2:
        field = rng.choice(("args", "id", "service", "timeout"))
        op[field] = hostile_value(rng)
    return op


# What a hostile server sends a client (the conformance runner's inputs): replies
# shaped like the server ops of the spec with hostile fields, and raw frames
# (deep, undecodable, not UTF-8, lone surrogates).
SERVER_OPS = ("publish", "service_response", "status", "fragment", "action_result", "png")


def server_op(rng: random.Random) -> dict[str, Any]:
    """A server op (``SERVER_OPS``) with one to three fields made hostile."""
    return hostile_op(rng, rng.choice(SERVER_OPS))


def server_raw_frame(rng: random.Random) -> tuple[bytes, bool]:
    """A raw frame no well-behaved server writes: (bytes, binary)."""
    depth = rng.choice((101, 1000, 200_000))
    choice = rng.randrange(8)
    frames: list[tuple[bytes, bool]] = [
        (b"[" * depth + b"]" * depth, False),  # deeper than any limit
        (b'{"op":"publish","msg":' + b'{"a":' * depth + b"1" + b"}" * depth + b"}", False),
        (b"\x81" * depth + b"\x00", True),  # CBOR arrays nested as deep
        (b'{"op":"publish","topic":"/\xff\xfe","msg":{}}', False),  # text not UTF-8
        (b'{"op":"status","level":"error","msg":"\\ud800"}', False),  # a lone surrogate
        (b"NaN", False),
        (bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64))), True),
        (b'{"op":"fragment","id":"x","num":' + b"9" * 5000 + b',"data":"{","total":2}', False),
    ]
    return frames[choice]


def server_frames(rng: random.Random) -> list[tuple[bytes, bool]]:
    """A burst a hostile server answers with: server ops (JSON or CBOR) and raw frames."""
    burst: list[tuple[bytes, bool]] = []
    for _ in range(rng.randint(1, 5)):
        if rng.random() < 0.4:
            burst.append(server_raw_frame(rng))
        else:
            op = server_op(rng)
            burst.append((to_cbor(op), True) if rng.random() < 0.2 else (to_json(op), False))
    return burst


# ---- Zenoh peers ------------------------------------------------------------------
# What a hostile peer on the Zenoh network sends a linked graph: liveliness tokens
# (rmw_zenoh's ``@ros2_lv/...`` keys, wire.Entity) with odd parts, and samples with
# garbage payloads and attachments (docs/limits.md, "Zenoh peers").

ZENOH_KINDS = ("NN", "MP", "MS", "SS", "SC", "XX", "")
ZENOH_TOPICS = ("/fuzz", "/chatter", "/rosapi/topics", "/client_count", "/connected_clients")
STRING_DDS = "std_msgs::msg::dds_::String_"
_ODD_PARTS: tuple[Gen, ...] = (
    _const(""),
    _const("%"),
    _const("%%%"),
    _const("*"),
    _const("**"),
    _const("$*"),
    _const("é" * 3),
    _const("\ud800"),  # a lone surrogate: Zenoh cannot carry it, the link must not see it
    _const("\x00"),
    lambda rng: str(rng.choice((10**40, -1, 2**63, -(2**63) - 1))),
    lambda rng: "a" * rng.choice((256, 5000)),
    lambda rng: rng.choice(BAD_ROS_NAMES).replace("/", "%"),
    lambda rng: ":".join(str(rng.randint(-5, 10**20)) for _ in range(rng.randint(0, 12))),
)


def zenoh_token(rng: random.Random, zid: str, n: int) -> str:
    """A liveliness token of entity ``n`` of session ``zid``: valid, or with odd parts."""
    kind = rng.choice(ZENOH_KINDS[:4])
    topic = rng.choice(ZENOH_TOPICS).replace("/", "%")
    parts = ["@ros2_lv", "0", zid, "1", str(n), kind, "%", "%", "fuzz_node"]
    if kind != "NN":
        parts += [topic, STRING_DDS, "RIHS01_" + "0" * 64, "::,10:,:,:,,"]
    if rng.random() < 0.7:
        for _ in range(rng.randint(1, 3)):
            parts[rng.randrange(1, len(parts))] = rng.choice(_ODD_PARTS)(rng)
    if rng.random() < 0.1:
        parts = parts[: rng.randrange(1, len(parts))]  # cut short
    if rng.random() < 0.1:
        parts.append(rng.choice(_ODD_PARTS)(rng))  # one part too many
    return "/".join(parts)


def _cdr_string(text: bytes) -> bytes:
    # CDR little-endian encapsulation, then a String's length (with its NUL) and bytes
    return b"\x00\x01\x00\x00" + (len(text) + 1).to_bytes(4, "little") + text + b"\x00"


_PAYLOADS: tuple[Gen, ...] = (
    lambda rng: _cdr_string(b"fuzz"),
    _const(b""),
    _const(b"\x00\x01\x00\x00"),
    _const(b"\x00\x01\x00\x00\xff\xff\xff\xff"),  # a length of 4 GiB
    _const(b"\x00\x00\x00\x00\x05\x00\x00\x00abcd\x00"),  # big-endian header
    _const(b"\x00\x01\x00\x00\x05\x00\x00\x00\xff\xfe\xfd\xfc\x00"),  # not UTF-8
    lambda rng: _cdr_string(b"x" * rng.randint(0, 200))[: rng.randint(0, 60)],  # truncated
    lambda rng: rng.randbytes(rng.randint(1, 300)),
    lambda rng: _cdr_string(b"tail") + rng.randbytes(rng.randint(1, 16)),
)
_ATTACHMENTS: tuple[Gen, ...] = (
    _const(None),
    _const(b""),
    lambda rng: rng.randbytes(rng.randint(1, 64)),
    lambda rng: (
        rng.randint(0, 2**63 - 1).to_bytes(8, "little")
        + rng.randint(0, 2**63 - 1).to_bytes(8, "little")
        + bytes([rng.choice((16, 0, 255))])
        + rng.randbytes(16)
    ),
)


def zenoh_sample(rng: random.Random) -> tuple[str, bytes, bytes | None]:
    """A sample a peer puts: (topic, CDR payload or garbage, attachment or garbage)."""
    topic = rng.choice(("/fuzz", "/chatter"))
    return topic, rng.choice(_PAYLOADS)(rng), rng.choice(_ATTACHMENTS)(rng)
