"""Every protocol's session meets the connection runtime's contract; the graph meets its port's.

The pump drives any ``rwt_protocol.runtime.contract.ServerSession`` and a
protocol front end types against ``rwt_graph.port.GraphFront``
(docs/architecture.md, "One connection runtime"). mypy checks the places that
assign one to the other; this checks every member each contract names, on the
real objects, so a member added to a contract and forgotten by a protocol (or
one renamed in a session) fails here at once, whatever typing sees.

Containment is the runtime's (``SessionBase.contain``), for every protocol: a
timer or a job that fails is reported to the peer in its protocol's own words
(rosbridge's ``status`` op, over WebRTC too, Foxglove's ``status`` message, an HTTP
event stream's ``status`` event, nothing for an MCP agent, which hears of problems as
tool errors, the test double's text line) and the connection stays open
(docs/limits.md, containment). The five sessions the server makes (rosbridge,
Foxglove, rosbridge on WebRTC with its lossy lane, an HTTP request, an MCP session)
and the test double are checked alike.
"""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable
from dataclasses import dataclass

import pytest

from rwt_foxglove import FoxgloveSession
from rwt_foxglove.protocol import StatusLevel as FoxgloveLevel
from rwt_graph.graph import Graph
from rwt_graph.port import GraphFront
from rwt_http import HttpSession, parse_route
from rwt_protocol.ports import GraphPort
from rwt_protocol.runtime.connection import SessionBase
from rwt_protocol.runtime.contract import ServerSession
from rwt_protocol.runtime.jobs import Job
from rwt_protocol.runtime.request import SessionRequest
from rwt_protocol.runtime.rules import ClientRules
from rwt_protocol.server.pngout import PngPublishJob
from rwt_protocol.server.session import Session, SessionConfig
from tests.support.echo import EchoSession


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


def _webrtc(graph: Graph) -> Session:
    """A rosbridge session as a WebRTC peer's: its lossy lane open (D36)."""
    session = _rosbridge(graph)
    session.open_lossy_lane(0, lambda: None)
    return session


def _http(graph: Graph) -> HttpSession:
    """An HTTP request's session: an event stream (what stays open), its request taken."""
    graph.create_publisher("/chatter", "std_msgs/msg/String")
    route = parse_route("GET", "/api/topics/chatter/events")
    session = HttpSession(graph.port, "http:127.0.0.1:5000#1", route, config=ClientRules())
    session.start(0.0)
    session.receive_frame(b"", 0.0)  # the request's body: the stream's head is queued
    return session


def _mcp(graph: Graph) -> SessionBase:
    pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")
    from rwt_mcp.session import McpSession  # noqa: PLC0415 (after the skip)

    return McpSession(graph.port, "mcp:127.0.0.1:5000#1", config=ClientRules())


SESSIONS = [
    pytest.param(_rosbridge, id="rosbridge"),
    pytest.param(_foxglove, id="foxglove"),
    pytest.param(_webrtc, id="webrtc"),
    pytest.param(_http, id="http"),
    pytest.param(_mcp, id="mcp"),
]
"""The sessions the server makes, one of each front end's."""


@pytest.mark.parametrize("make", SESSIONS)
def test_each_protocols_session_has_every_member_of_the_contract(
    make: Callable[[Graph], SessionBase],
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


def _echo(graph: Graph) -> EchoSession:
    request = SessionRequest(
        graph.port, "client#1", "memory", "", SessionConfig(), lambda: None, lambda _: None
    )
    return EchoSession(request)


def _rosbridge_words(told: list[bytes]) -> bool:
    error = {"op": "status", "level": "error", "msg": "internal error"}
    return len(told) == 1 and json.loads(told[0]) == error


def _foxglove_words(told: list[bytes]) -> bool:
    message = json.loads(told[0]) if len(told) == 1 else {}
    return message.get("op") == "status" and (message["level"], message["message"]) == (
        int(FoxgloveLevel.ERROR),
        "internal error",
    )


def _http_words(told: list[bytes]) -> bool:
    return told == [b'event: status\ndata: {"level":"error","text":"internal error"}\n\n']


def _mcp_words(told: list[bytes]) -> bool:
    return told == []  # a tool's caller hears of a problem as a tool error, never a frame


def _echo_words(told: list[bytes]) -> bool:
    return told == [b"error: internal error"]


PROTOCOLS = [
    pytest.param(_rosbridge, _rosbridge_words, id="rosbridge"),
    pytest.param(_foxglove, _foxglove_words, id="foxglove"),
    pytest.param(_webrtc, _rosbridge_words, id="webrtc"),
    pytest.param(_http, _http_words, id="http"),
    pytest.param(_mcp, _mcp_words, id="mcp"),
    pytest.param(_echo, _echo_words, id="test-double"),
]


def _fresh(make: Callable[[Graph], SessionBase]) -> SessionBase:
    session = make(Graph())
    session.start(0.0)
    session.frames_to_send()  # its greeting (Foxglove's serverInfo, ...)
    return session


def _told(session: SessionBase) -> list[bytes]:
    return [bytes(frame.data) for frame in session.frames_to_send()]


def _still_open(session: SessionBase) -> bool:
    ran: list[float] = []
    session.call_at(session.now + 1.0, ran.append)
    session.handle_timer(session.now + 1.0)  # a later timer still runs
    return not session.closing and session.commands_to_run() == [] and ran != []


def _boom(now: float) -> None:
    raise ZeroDivisionError(now)  # a bug in a timer


@dataclass
class _FailingJob:
    ready_at: float = 0.0

    def run(self) -> object:
        raise ZeroDivisionError  # a bug in a job


@pytest.mark.parametrize(("make", "words"), PROTOCOLS)
def test_a_failing_timer_is_contained_and_told_in_the_protocols_words(
    make: Callable[[Graph], SessionBase], words: Callable[[list[bytes]], bool]
) -> None:
    session = _fresh(make)
    session.call_at(1.0, _boom)
    session.handle_timer(1.0)  # does not raise
    told = _told(session)
    assert words(told), told
    assert _still_open(session)
    session.close()


@pytest.mark.parametrize(("make", "words"), PROTOCOLS)
@pytest.mark.parametrize("background", [False, True], ids=["input-job", "background-job"])
def test_a_failing_job_is_contained_and_told_in_the_protocols_words(
    make: Callable[[Graph], SessionBase], words: Callable[[list[bytes]], bool], background: bool
) -> None:
    session = _fresh(make)
    session.jobs.transport_runs = True
    session.add_job(_FailingJob(), background=background)
    job = session.jobs.take_background() if background else session.jobs.take()
    assert job is not None
    try:
        outcome: object = job.run()
    except ZeroDivisionError as exc:  # as the pump hands it back
        outcome = exc
    session.finish_job(job, outcome, 1.0)  # does not raise
    told = _told(session)
    assert words(told), told
    assert _still_open(session)
    session.close()


def test_the_shared_rules_are_what_rosbridges_settings_extend() -> None:
    rules = ClientRules()
    settings = SessionConfig(max_subscriptions=3, max_pending_goals=5)
    assert isinstance(settings, ClientRules)
    assert settings.max_subscriptions == 3 and rules.max_subscriptions == 1000
    assert not hasattr(rules, "max_pending_goals")  # rosbridge's own stay rosbridge's
