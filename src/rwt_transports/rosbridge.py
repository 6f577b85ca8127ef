"""rosbridge as a front end of the server: its labels, and what the transports ask of it.

rosbridge is the default front end (a WebSocket client that offers no other
subprotocol, a TCP, UDP or stdio connection): ``rosbridge_frontend`` makes it for
the server, whose own factory makes its session (``rwt_protocol.server.Session``,
under rosbridge's ``SessionConfig``). The transports speak no protocol: what one
needs to know of rosbridge's frames is a hook of this front end (``FrontEnd``):

- ``first_topic``: the topic a connection's first message names, by which
  ``--placement topic`` moves the connection to the worker owning it (D57);
- ``split_text``: a JSON frame too large for a WebRTC data channel's message, cut
  into ``fragment`` ops its client reassembles (spec 3.1.1, D19).

Its WebRTC data channels are labelled ``rosbridge`` (``DATA_CHANNEL_LABEL``) and
``rosbridge-lossy`` (``LOSSY_CHANNEL_LABEL``, D36).
"""

from __future__ import annotations

import itertools
import json
from typing import TYPE_CHECKING

from rwt_protocol.framing.datagrams import fragment_datagrams

from .frontends import AuthMode, FrontEnd

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.inframes import FramerEvent
    from rwt_protocol.runtime.request import SessionRequest

__all__ = [
    "DATA_CHANNEL_LABEL",
    "LOSSY_CHANNEL_LABEL",
    "PLACED_OPS",
    "first_topic",
    "rosbridge_frontend",
    "split_text",
]

DATA_CHANNEL_LABEL = "rosbridge"
"""The label of the reliable, ordered data channel that carries a rosbridge session."""

LOSSY_CHANNEL_LABEL = "rosbridge-lossy"
"""The label of a rosbridge session's lossy channel (``ordered: false, maxRetransmits`` 0 or
1; D36, D73)."""

PLACED_OPS = frozenset({"subscribe", "advertise", "publish"})
"""First ops whose topic places a connection (rosbridge v2 protocol sections 3.4.2-3.4.4)."""

_ids = itertools.count(1)


def first_topic(frame: FramerEvent) -> str | None:
    """The topic a connection's first message places it by, or None (it stays; D57).

    Only a JSON text of one of ``PLACED_OPS`` with a string ``topic`` counts; anything
    else (CBOR, another op, JSON the session will refuse) stays, and its session answers
    it as ever.
    """
    data = getattr(frame, "data", None)
    if not isinstance(data, bytes) or getattr(frame, "binary", True):
        return None
    try:
        message = json.loads(data)
    except ValueError:
        return None
    if not isinstance(message, dict) or message.get("op") not in PLACED_OPS:
        return None
    topic = message.get("topic")
    return topic if isinstance(topic, str) and topic else None


def split_text(data: bytes, max_bytes: int) -> list[bytes]:
    """``data`` (a JSON frame) as ``fragment`` ops of at most ``max_bytes`` each (D19).

    A frame within ``max_bytes`` is one part, itself.
    """
    return fragment_datagrams(data, max_bytes, f"webrtc:{next(_ids)}")


def rosbridge_frontend(make_session: Callable[[SessionRequest], ServerSession]) -> FrontEnd:
    """rosbridge, the default front end: no subprotocol, its labels, the auth op, its hooks."""
    return FrontEnd(
        "rosbridge",
        (),
        make_session,
        AuthMode.OP,
        labels=(DATA_CHANNEL_LABEL,),
        lossy_labels=(LOSSY_CHANNEL_LABEL,),
        first_topic=first_topic,
        split_text=split_text,
    )
