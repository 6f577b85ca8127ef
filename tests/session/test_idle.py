"""The idle rule in the sans-IO session (``idle.IdleWatch``, ``--idle-timeout``).

The transports' own tests (tests/hardening/test_idle.py) run it over real sockets;
these drive the session's clock by hand.
"""

from __future__ import annotations

import json

from rwt_graph.graph import Graph
from rwt_protocol.server.session import CloseCode, Session, SessionConfig


def _session(graph: Graph) -> Session:
    session = Session(graph.port, "idle", config=SessionConfig(idle_timeout_s=10.0))
    session.start(100.0)
    return session


def test_a_silent_session_holding_nothing_is_closed_after_the_timeout() -> None:
    session = _session(Graph())
    session.handle_timer(109.9)
    assert session.close_request is None
    session.handle_timer(110.0)
    close = session.close_request
    assert close is not None and close.code is CloseCode.NORMAL
    assert close.reason == "idle: no input for 10 s and nothing held"


def test_input_or_a_subscription_keeps_the_session_open() -> None:
    session = _session(Graph())
    session.receive_frame(json.dumps({"op": "set_level", "level": "info"}), 105.0)
    session.handle_timer(110.0)  # input at 105: the count starts again from there
    assert session.close_request is None
    session.receive_frame(
        json.dumps({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/msg/String"}), 114.0
    )
    session.handle_timer(200.0)  # silent for long, but it holds a subscription
    assert session.close_request is None
    session.receive_frame(json.dumps({"op": "unsubscribe", "topic": "/chatter"}), 201.0)
    session.handle_timer(211.0)  # ten seconds after the last input, holding nothing
    assert session.close_request is not None
