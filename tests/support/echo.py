"""A third protocol of a few lines, the test double of a front end (docs/architecture.md).

"How to add a protocol": a session that subclasses ``SessionBase`` and a
``FrontEnd`` that makes it. ``sub TOPIC`` subscribes (its messages come as
their text), ``boom`` is a bug in a handler, anything else comes back; a
problem is told as ``LEVEL: TEXT``. It restates none of the server's rules:
tests/transports/test_frontends.py shows it gets them, and
tests/session/test_session_contract.py that its bugs are contained.
"""

from __future__ import annotations

from rwt_protocol.levels import StatusLevel
from rwt_protocol.ports import MessageEvent
from rwt_protocol.runtime.access import Family
from rwt_protocol.runtime.connection import SessionBase
from rwt_protocol.runtime.outbox import OutFrame
from rwt_protocol.runtime.request import SessionRequest
from rwt_transports.frontends import FrontEnd

ECHO = "rwt.test.echo"


class EchoSession(SessionBase):
    """The whole protocol (the module's text)."""

    protocol = "echo"

    def __init__(self, request: SessionRequest) -> None:
        super().__init__(
            request.graph,
            request.client_id,
            config=request.rules,
            on_output=request.on_output,
            peer=request.peer,
            on_closed=request.on_closed,
        )
        self.topics: set[str] = set()

    def handle_frame(self, frame: bytes | str, now: float, binary: bool) -> None:
        text = frame.decode() if isinstance(frame, bytes) else frame
        if text == "boom":
            raise ZeroDivisionError  # a bug in a handler
        if text.startswith("sub "):
            self._subscribe(text[4:])
        else:
            self.send_frames((OutFrame(text.encode()),))

    def _subscribe(self, topic: str) -> None:
        self.require_access(Family.TOPICS, topic, "sub")
        self.check_cap(len(self.topics), self.config.max_subscriptions, "subscriptions")
        self.graph.subscribe(self.client_id, topic, "std_msgs/msg/String", _Sink(self))
        self.topics.add(topic)

    def status_frames(
        self, level: StatusLevel, text: str, op_id: str | int | None = None
    ) -> tuple[OutFrame, ...]:
        return (OutFrame(f"{level.wire}: {text}".encode()),)

    def holds_anything(self) -> bool:
        return bool(self.topics)


class _Sink:
    def __init__(self, session: EchoSession) -> None:
        self._session = session

    def on_message(self, event: MessageEvent) -> None:
        frame = OutFrame(str(event.msg["data"]).encode(), False, True)
        self._session.queue_run((frame,), None, event.now)


FRONTEND = FrontEnd("echo", (ECHO,), EchoSession)
