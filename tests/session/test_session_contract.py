"""Every protocol's session meets the connection runtime's contract; the graph meets its port's.

The pump drives any ``rwt_protocol.runtime.contract.ServerSession`` and a
protocol front end types against ``rwt_graph.port.GraphFront``
(docs/architecture.md, "One connection runtime"). mypy checks the places that
assign one to the other; this checks every member each contract names, on the
real objects, so a member added to a contract and forgotten by a protocol (or
one renamed in a session) fails here at once, whatever typing sees.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

import pytest

from rwt_foxglove import FoxgloveSession
from rwt_graph.graph import Graph
from rwt_graph.port import GraphFront
from rwt_protocol.ports import GraphPort
from rwt_protocol.runtime.contract import Job, ServerSession
from rwt_protocol.server.pngout import PngPublishJob
from rwt_protocol.server.session import Session, SessionConfig


def _members(protocol: type) -> set[str]:
    """The names a ``typing.Protocol`` declares (methods, properties, attributes)."""
    names = {
        name
        for klass in protocol.__mro__
        if klass.__module__ not in ("typing", "builtins", "typing_extensions")
        for name, value in vars(klass).items()
        if not name.startswith("_") and (callable(value) or isinstance(value, property))
    }
    for klass in protocol.__mro__:
        names |= {n for n in getattr(klass, "__annotations__", {}) if not n.startswith("_")}
    return names


def test_the_contracts_name_what_the_runtime_uses() -> None:
    assert {"receive_frame", "frames_to_send", "get_timer", "handle_timer", "on_timer"} <= (
        _members(ServerSession)
    )
    assert {"feed", "registry", "subscribe", "publish_serialized"} <= _members(GraphFront)
    assert {"ready_at", "run"} <= _members(Job)


def _foxglove(graph: Graph) -> FoxgloveSession:
    return FoxgloveSession(graph.port, "client#1", session_id="s1", config=SessionConfig())


def _rosbridge(graph: Graph) -> Session:
    return Session(graph.port, "client#1", config=SessionConfig())


@pytest.mark.parametrize("make", [_rosbridge, _foxglove], ids=["rosbridge", "foxglove"])
def test_each_protocols_session_has_every_member_of_the_contract(
    make: Callable[[Graph], Session | FoxgloveSession],
) -> None:
    session = make(Graph())
    missing = sorted(name for name in _members(ServerSession) if not hasattr(session, name))
    assert missing == []
    for name in _members(ServerSession):  # methods stay methods, values stay values
        declared = inspect.getattr_static(ServerSession, name, None)
        if inspect.isfunction(declared):
            assert callable(getattr(session, name)), name
    session.close()


def test_the_graph_core_is_a_front_and_a_port() -> None:
    port = Graph().port
    for protocol in (GraphFront, GraphPort):
        missing = sorted(name for name in _members(protocol) if not hasattr(port, name))
        assert missing == [], protocol.__name__


def test_a_background_job_has_what_the_pump_runs() -> None:
    fields = set(PngPublishJob.__dataclass_fields__)  # ``ready_at`` lives on instances
    assert all(name in fields or callable(getattr(PngPublishJob, name)) for name in _members(Job))
