"""The inbound check of a publish frame as the session does it (for B14)."""

from __future__ import annotations

from collections.abc import Callable

from rwt_graph.graph import Graph
from rwt_protocol.codec import decode_json, parse_object


def validator(graph: Graph) -> Callable[[bytes], object]:
    """A function doing what ``Session.receive_frame`` does to a publish frame before delivery."""

    def validate(frame: bytes) -> object:
        op = parse_object(decode_json(frame))
        entry = graph.topics[op.topic]  # type: ignore[attr-defined]
        return entry.msgtype.from_json(op.msg, path="$.msg", now=0.0)  # type: ignore[attr-defined]

    return validate
