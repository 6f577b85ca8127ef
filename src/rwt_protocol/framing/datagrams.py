"""Splitting outgoing messages for datagram transports (UDP, D22).

A datagram carries one message; a message larger than a datagram-safe size goes
out as ``fragment`` ops (spec 3.1.1, D19): consecutive pieces of its JSON text,
integer ``num`` from 0 and integer ``total``, each fragment op itself within the
size. Clients reassemble them as they do for ``fragment_size``.
"""

from __future__ import annotations

from ..codecs.json import encode_json, encode_op
from ..errors import ConfigError
from ..ops import Fragment

__all__ = ["fragment_datagrams"]

_MIN_DATAGRAM = 128


def fragment_datagrams(data: bytes, max_bytes: int, message_id: str) -> list[bytes]:
    """Split one JSON frame into ``fragment`` ops of at most ``max_bytes`` bytes each.

    Args:
        data: the message as UTF-8 JSON text.
        max_bytes: the largest datagram to produce, in bytes (at least 128).
        message_id: the ``id`` every fragment carries (fresh per message, D19).

    Returns:
        ``[data]`` when it fits already; else the encoded fragment ops, in order.

    Raises:
        ConfigError: ``max_bytes`` is too small to carry any fragment.
    """
    if len(data) <= max_bytes:
        return [data]
    if max_bytes < _MIN_DATAGRAM:
        raise ConfigError(f"a datagram of {max_bytes} bytes cannot carry fragments")
    text = data.decode("utf-8", "replace")
    envelope = Fragment(id=message_id, data="", num=len(text), total=len(text))
    budget = max_bytes - len(encode_op(envelope))
    if budget < 8:
        raise ConfigError(f"a datagram of {max_bytes} bytes cannot carry fragment {message_id!r}")
    pieces: list[str] = []
    start = 0
    while start < len(text):
        count = budget
        while True:  # escaping (quotes) and UTF-8 make a piece larger than its length
            piece = text[start : start + count]
            size = len(encode_json(piece)) - 2
            if size <= budget or count == 1:
                break
            count = max(1, min(count - 1, count * budget // size))
        pieces.append(piece)
        start += len(piece)
    total = len(pieces)
    return [
        encode_op(Fragment(id=message_id, data=p, num=i, total=total)) for i, p in enumerate(pieces)
    ]
