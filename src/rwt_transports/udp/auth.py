"""UDP authentication: a peer gets a session with its ``auth`` op, not before (D23, D31).

A stream connection exists before its first op, so the server can send it the
auth challenge and refuse a first op that is not ``auth`` by closing it. A UDP
session begins with the first datagram served from an address, so with an
authenticator (``--auth-secret-file``) that datagram must be the ``auth`` op:

- an ``auth`` op opens the session, which decides it as every session does (a
  refused one closes it);
- anything else is answered as a session answers a first op that is not
  ``auth`` (an error status, and a failure reply for a call or goal, D4) and
  opens nothing: a peer that does not authenticate holds no state, however many
  datagrams it sends.

With ``--auth-bind-connection`` the client must sign the challenge before that
first op, so the challenge cannot come from the session: it is the address's
(``AddressValidator.auth_challenge``, an HMAC of the address and the 30 s token
epoch, so nothing is stored for it) and goes out with the address validation and
with every refusal. What the client does (docs/server.md, authentication):

1. Validate the address (``validation``): the answer to the probe is the
   token, then ``{"op":"status","level":"info","id":"auth_challenge","msg":NONCE}``.
2. Have ``NONCE`` signed as ``rand`` (``rwt_protocol.auth.bound_mac``) and send
   the ``auth`` op as the first datagram with the token.
3. Any other op first gets the error status and the challenge again.
"""

from __future__ import annotations

from dataclasses import dataclass

from rwt_protocol.codecs.cbor import decode_cbor
from rwt_protocol.codecs.json import decode_json, encode_op, parse_object, peek_id
from rwt_protocol.errors import RwtError
from rwt_protocol.ops import Auth, OpModel, Status
from rwt_protocol.runtime.inframes import FramerEvent, FramingError
from rwt_protocol.server.gates import AUTH_REQUIRED, FIRST_OP_NOT_AUTH
from rwt_protocol.server.replies import failure_reply

__all__ = ["Refusal", "UdpAuth", "read_first"]


@dataclass(frozen=True, slots=True)
class UdpAuth:
    """What a UDP peer must send before it gets a session.

    Attributes:
        required: the first op must be an ``auth`` op (an authenticator is set,
            ``--auth-secret-file``).
        bound: its ``rand`` must be the address's auth challenge, sent with the
            address validation and every refusal (``--auth-bind-connection``).
    """

    required: bool = False
    bound: bool = False


@dataclass(frozen=True, slots=True)
class Refusal:
    """The answer to a first datagram that is not an ``auth`` op.

    Attributes:
        frames: the datagrams to send: a failure reply for a call or goal (D4),
            then the error status.
        reason: what the datagram was, for the log line.
    """

    frames: list[bytes]
    reason: str


def read_first(event: FramerEvent) -> Auth | Refusal:
    """Read the first datagram of a peer that must authenticate.

    Args:
        event: the datagram as the UDP channel classifies it.

    Returns:
        The ``auth`` op it holds (its MAC not checked yet: the session does),
        or the answer refusing it, with the texts a session gives.
    """
    if isinstance(event, FramingError):
        return _refusal(f"{AUTH_REQUIRED}: {event.message}", None, None, "an unreadable datagram")
    op_id: str | int | None = None
    try:
        obj = decode_cbor(event.data) if event.binary else decode_json(event.data)
        op_id = peek_id(obj)
        op = parse_object(obj)
    except RwtError as exc:
        text = exc.message  # worded as the session words it (``Session._refused``)
        if "authentication" not in text:
            text = f"{AUTH_REQUIRED}: {text}"
        return _refusal(text, None, op_id, "an invalid op")
    if isinstance(op, Auth):
        return op
    name: str = op.op
    return _refusal(f"{name}: {FIRST_OP_NOT_AUTH}", op, op_id, f"first op was {name}")


def _refusal(text: str, op: OpModel | None, op_id: str | int | None, reason: str) -> Refusal:
    frames = []
    reply = failure_reply(op, AUTH_REQUIRED) if op is not None else None
    if reply is not None:
        frames.append(encode_op(reply))
    frames.append(encode_op(Status(level="error", msg=text, id=op_id)))
    return Refusal(frames, reason)
