"""Admission without a session: a ticket holds a slot until a session takes it or it goes."""

from __future__ import annotations

from rwt_transports.server import RosbridgeServer, ServerConfig


def test_a_ticket_holds_a_slot_until_a_session_takes_it_or_it_is_released() -> None:
    server = RosbridgeServer(config=ServerConfig(port=None, tf=False, max_connections=2))
    first = server.admit("webrtc", "10.0.0.1:5000")
    second = server.admit("webrtc", "10.0.0.2:5000")
    assert first is not None and second is not None
    assert server.admit("ws", "10.0.0.3:5000") is None  # full: tickets count
    assert server.open_session("ws", "10.0.0.3:5000", lambda: None) is None

    session = server.open_session("ignored", "ignored", lambda: None, ticket=first)
    assert session is not None and session.client_id == first.client_id
    assert first.client_id.startswith("webrtc:10.0.0.1:5000#")
    assert server.open_session("ws", "x:1", lambda: None, ticket=first) is None  # used
    assert server.admit("ws", "10.0.0.3:5000") is None  # still full

    server.release(second)
    server.release(second)  # once only
    third = server.admit("ws", "10.0.0.3:5000")
    assert third is not None
    assert server.admit("ws", "10.0.0.4:5000") is None
    session.close()
    assert server.admit("ws", "10.0.0.4:5000") is not None
