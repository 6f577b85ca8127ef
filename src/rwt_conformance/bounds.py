"""What the runner allows a server under test, and the helpers that hold it to that.

The runner is a client of untrusted servers (docs/conformance.md, "Against a
hostile server"): a server may never read, send frames of any size or nesting,
or keep sending. Every wait of the runner is therefore bounded in time, every
frame in size and nesting, and what a case keeps of its frames in bytes; a
server that breaks a bound fails the case at hand with a reason, and the run
goes on to the next case, unless the server does not answer at all
(``liveness``). The whole run is bounded too.

The defaults are named here once; ``RunOptions`` and the command line
(``--case-timeout``, ``--run-timeout``, ``--max-frame-bytes``,
``--case-budget-bytes``) take them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import anyio

from rwt_protocol.codecs.json import MAX_NESTING
from rwt_protocol.errors import TransportError

if TYPE_CHECKING:
    from rwt_client.connectors import Connection

__all__ = [
    "CASE_BUDGET_BYTES",
    "CASE_TIMEOUT_S",
    "CLOSE_TIMEOUT_S",
    "MAX_FRAME_BYTES",
    "MAX_NESTING",
    "RUN_TIMEOUT_S",
    "SendTimeoutError",
    "close_within",
    "send_within",
]

MiB = 1024 * 1024

MAX_FRAME_BYTES = 16 * MiB
"""Largest frame the runner takes from a server, bytes (``--max-frame-bytes``).

The suite's largest expected frame is ``connections.large-image``'s echo (about
1.6 MB); a bigger frame closes the connection (WebSocket: close 1009) and fails
the case."""

CASE_BUDGET_BYTES = 64 * MiB
"""Bytes of received frames one case may hold unconsumed at once, all its
connections together (``--case-budget-bytes``); more fails the case."""

CASE_TIMEOUT_S = 20.0
"""Seconds one whole case may take, closing its connections aside (``--case-timeout``)."""

RUN_TIMEOUT_S = 600.0
"""Seconds the whole run may take (``--run-timeout``): checking the server, asking
its dialect and every case. The suite takes about a second against a local
server; 600 s leaves a slow server room, while a run of cases that each wait out
``CASE_TIMEOUT_S`` (over half an hour for the suite's 101) is cut, saying where."""

CLOSE_TIMEOUT_S = 2.0
"""Seconds the runner waits for a clean close (its close frame sent) before it
cuts the connection: a server that never reads must not hold a close forever."""

# Nesting: the runner refuses frames nested deeper than the server core does
# (rwt_protocol.codecs.json.MAX_NESTING): ROS messages nest a few levels, and matching
# and reporting walk values recursively.


class SendTimeoutError(TransportError):
    """A frame could not be sent in time: the server does not read."""


async def send_within(conn: Connection, frame: str | bytes, timeout_s: float) -> None:
    """Send ``frame`` on ``conn`` within ``timeout_s`` seconds.

    Raises:
        SendTimeoutError: the frame did not go out in time (the server stopped
            reading and the socket's buffers are full).
        ConnectionClosedError: the connection is gone.
    """
    with anyio.move_on_after(timeout_s) as scope:
        await conn.send(frame)
    if scope.cancelled_caught:
        raise SendTimeoutError(f"send timed out after {timeout_s:g} s (the server does not read)")


async def close_within(conn: Connection, timeout_s: float = CLOSE_TIMEOUT_S) -> None:
    """Close ``conn`` cleanly if that takes at most ``timeout_s`` seconds, else cut it.

    Shielded: it runs to the end even in a cancelled scope (the close after a
    case that timed out). Never raises. Cancelling a close cuts the socket
    (anyio aborts the transport), so nothing is left open either way.
    """
    with anyio.CancelScope(shield=True) as scope:
        scope.deadline = anyio.current_time() + timeout_s
        await conn.aclose()
