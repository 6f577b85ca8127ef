"""Helpers for the rosapi tests: a graph with rosapi, clients as the server makes them."""

from __future__ import annotations

from typing import Any

from rwt_graph.graph import Graph
from tests.conftest import Peer


def connect(graph: Graph, name: str, host: str | None = None) -> Peer:
    """A client session that is a node of its own, as ``RosbridgeServer`` makes it."""
    peer = Peer(graph, name)
    graph.nodes.attach(name, host=host)
    return peer


def call(peer: Peer, service: str, /, **args: object) -> dict[str, Any]:
    """Call ``service`` and return its response values; the call must succeed."""
    reply = call_raw(peer, service, **args)
    assert reply["result"] is True, reply
    values = reply["values"]
    assert isinstance(values, dict)
    return values


def call_raw(peer: Peer, service: str, /, **args: object) -> dict[str, Any]:
    """Call ``service`` and return the whole ``service_response`` frame."""
    peer.send(op="call_service", service=service, args=args, id="q")
    [reply] = [m for m in peer.received() if m["op"] == "service_response"]
    assert reply["id"] == "q" and reply["service"] == service
    return reply
