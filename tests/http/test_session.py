"""The HTTP API's session without I/O: containment and the slow-consumer rule are the runtime's."""

from __future__ import annotations

import json

import pytest

from rwt_graph.graph import Graph
from rwt_http import HttpSession, Route, RouteKind
from rwt_http import session as session_module
from rwt_protocol.runtime.rules import ClientRules


def _body(frames: list[bytes]) -> tuple[str, object]:
    head, _, body = b"".join(frames).partition(b"\r\n\r\n")
    return head.split(b"\r\n", 1)[0].decode(), json.loads(body)


def test_a_bug_in_a_handler_is_a_500_and_the_session_closes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def broken(session: HttpSession, route: Route, frame: object) -> None:
        raise ZeroDivisionError

    monkeypatch.setitem(session_module._HANDLERS, RouteKind.TOPICS, broken)
    session = HttpSession(Graph().port, "http:t#1", Route(RouteKind.TOPICS), config=ClientRules())
    session.start(0.0)
    session.receive_frame(b"", 0.0)
    status, body = _body([frame.data for frame in session.frames_to_send()])
    assert (status, body) == ("HTTP/1.1 500 Internal Server Error", {"error": "internal error"})
    assert session.close_request is not None
    session.close()


def test_a_stream_past_its_queue_length_drops_the_oldest_messages() -> None:
    graph = Graph()
    publisher = graph.create_publisher("/t", "std_msgs/msg/String")
    route = Route(RouteKind.EVENTS, "/t", queue_length=3)
    session = HttpSession(graph.port, "http:t#1", route, config=ClientRules())
    session.start(0.0)
    session.receive_frame(b"", 0.0)
    for n in range(10):
        publisher.publish({"data": str(n)})
    frames = [frame.data for frame in session.frames_to_send()]
    assert frames[0].startswith(b"HTTP/1.1 200 OK")
    data = [f for f in frames[1:] if f.startswith(b"data: ")]
    assert data == [b'data: {"data":"%d"}\n\n' % n for n in (7, 8, 9)]
    assert session.stats.dropped_frames == 7
    session.close()
