"""The inbound check of a publish frame as the session does it (for B14)."""

from __future__ import annotations

from collections.abc import Callable

from rwt_graph.graph import Graph
from rwt_protocol.codecs.json import decode_json, decode_publish, parse_object


def validator(graph: Graph) -> Callable[[bytes], object]:
    """What ``Session.receive_frame`` does to a publish frame before delivering it.

    Decode and check the op (the msgspec hot path when there is one, else the
    general path), then convert the message against the topic's type.
    """

    def validate(frame: bytes) -> object:
        op = decode_publish(frame)
        if op is None:
            op = parse_object(decode_json(frame))  # type: ignore[assignment]
        return graph.port.convert_publish(op.topic, op.msg, path="$.msg")  # type: ignore[union-attr]

    return validate
