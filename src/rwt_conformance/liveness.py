"""Whether a server reads and answers at all: one verdict instead of a table of failures.

The runner asks before the first case, and again after a case that failed with
nothing from the server (no frame on any of its connections, or a send the
server did not take, ``CaseResult.unanswered``). One fresh connection sends a
few frames any rosbridge server answers: ``subscribe``, ``advertise`` and
``publish`` on a private topic (the server echoes the message back, as a case's
``sync`` relies on) and a ``call_service`` to ``/rosapi/get_ros_version``
(answered, or refused with a ``service_response``, by rosbridge_suite 0.11, 2.x
and rwt); the ``publish`` is resent every ``_RESEND_S`` seconds, for servers
whose subscriptions take a moment to connect (ROS 1). The first frame received,
whatever it is, means the server answers.

Everything is bounded (``bounds``): connecting and the handshake by twice the
wait, the wait for a first frame (the sends included) by ``timeout_s``, the
close by ``CLOSE_TIMEOUT_S``. So a server that never reads, reads a byte a second,
answers the handshake and then nothing, or closes at once is told within a few
seconds (docs/conformance.md, "Against a hostile server").
"""

from __future__ import annotations

import json
import secrets
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

import anyio

from rwt_client.connectors import Connection, ConnectionClosedError, connect

from .bounds import MAX_FRAME_BYTES, close_within
from .frames import auth_op

if TYPE_CHECKING:
    import ssl

    from .pace import RoundTrips

__all__ = ["check_answers"]

_RESEND_S = 0.5
_SERVER_CLOSED = (": closed by the server", ": connection closed", ": connection lost")
"""How a ``ConnectionClosedError`` says the server ended the connection; any other
reason is the client refusing what the server sent (a frame over the limit, not
UTF-8, ...): the server did answer, and the cases say what was wrong with it."""
_NEEDS_AUTH = " (a server with rosauth answers only after a valid auth: --auth-secret-file)"


async def check_answers(
    url: str,
    ssl_context: ssl.SSLContext | None = None,
    timeout_s: float = 3.0,
    auth_secret: str | None = None,
    max_frame_bytes: int = MAX_FRAME_BYTES,
    *,
    round_trips: RoundTrips | None = None,
) -> str | None:
    """Whether the server at ``url`` reads and answers; why not, in one line.

    Args:
        url: the server (``ws://``, ``wss://``, ``tcp://``, ``tcp+tls://``).
        ssl_context: TLS settings, as for the run.
        timeout_s: seconds the first answer, and each send, may take;
            connecting (with the WebSocket handshake) may take twice as long.
        auth_secret: the server's rosauth secret (D23): the connection
            authenticates first.
        max_frame_bytes: largest frame taken from the server, bytes.
        round_trips: takes the time from the first send to the first answer, a
            round trip (the runner's first measure of the server, ``pace``).

    Returns:
        None when the server answered; else the verdict, such as ``the server
        does not answer: nothing received within 3 s of sending 867 bytes``.
        Never raises for what the server does.
    """
    connect_s = 2 * timeout_s
    try:
        conn = await connect(
            url, timeout_s=connect_s, max_message_size=max_frame_bytes, ssl_context=ssl_context
        )
    except ConnectionClosedError as exc:
        text = exc.message
        if "CERTIFICATE_VERIFY_FAILED" in text:
            text += " (trust its authority with --cafile FILE, or skip the check with --insecure)"
        return text
    except TimeoutError:
        handshake = " and its WebSocket handshake" if urlsplit(url).scheme in ("ws", "wss") else ""
        return (
            f"cannot connect to {url}: the server does not answer"
            f" (connecting{handshake} took over {connect_s:g} s)"
        )
    probe = _Probe(conn, timeout_s)
    try:
        verdict = await probe.run(_frames(url, auth_secret))
    finally:
        await close_within(conn)
    if probe.answered_s is not None and round_trips is not None:
        round_trips.add(probe.answered_s)
    if verdict is not None and auth_secret is None and "does not answer" in verdict:
        verdict += _NEEDS_AUTH
    return verdict


def _frames(url: str, auth_secret: str | None) -> list[str]:
    """What the probe sends: [auth,] subscribe, advertise, call, publish (resent last)."""
    topic = f"/rwt_conformance_probe_{secrets.token_hex(4)}"
    base = {"topic": topic, "type": "std_msgs/String", "id": "rwt_conformance_probe"}
    frames = [
        json.dumps({"op": "subscribe", **base}),
        json.dumps({"op": "advertise", **base}),
        json.dumps(
            {
                "op": "call_service",
                "service": "/rosapi/get_ros_version",
                "args": {},
                "id": "rwt_conformance_probe",
            }
        ),
        json.dumps({"op": "publish", "topic": topic, "msg": {"data": "probe"}}),
    ]
    if auth_secret is not None:
        host = urlsplit(url).hostname or ""
        frames.insert(0, json.dumps(auth_op(auth_secret, {}, host)))
    return frames


class _Probe:
    """One connection's question: does a first frame come back within ``timeout_s``?"""

    def __init__(self, conn: Connection, timeout_s: float) -> None:
        self.conn = conn
        self.timeout_s = timeout_s
        self.sent_bytes = 0
        self.closed: str | None = None
        self.answered_s: float | None = None
        """Seconds from the first send to the first frame received, once answered."""

    async def run(self, frames: list[str]) -> str | None:
        with anyio.move_on_after(self.timeout_s):
            async with anyio.create_task_group() as tasks:
                started = anyio.current_time()
                tasks.start_soon(self._send, frames)
                try:
                    await self.conn.receive()
                except ConnectionClosedError as exc:
                    self.closed = exc.message
                else:
                    self.answered_s = anyio.current_time() - started
                    return None  # whatever came, the server answered
                finally:
                    tasks.cancel_scope.cancel()
        if self.closed is not None:
            if not any(reason in self.closed for reason in _SERVER_CLOSED):
                return None  # the client refused what came: the server answered
            return (
                f"the server closed the connection before answering ({self.closed}),"
                f" after {self.sent_bytes} bytes were sent"
            )
        # a server that does not read does not answer either: its probe's few hundred
        # bytes fit in the sockets' buffers, so no send waits (a case's big send would)
        return (
            f"the server does not answer: nothing received within {self.timeout_s:g} s"
            f" of sending {self.sent_bytes} bytes"
        )

    async def _send(self, frames: list[str]) -> None:
        """Send ``frames``, then resend the last (the publish) until cancelled."""
        try:
            for frame in frames:
                await self._send_one(frame)
            while True:
                await anyio.sleep(_RESEND_S)
                await self._send_one(frames[-1])
        except ConnectionClosedError as exc:
            self.closed = self.closed or exc.message

    async def _send_one(self, frame: str) -> None:
        await self.conn.send(frame)  # bounded by the probe's wait (``run``)
        self.sent_bytes += len(frame.encode())
