"""What a protocol's session is made from: one admitted connection's request.

The server admits a connection once, whatever its protocol (docs/architecture.md,
"One connection runtime"), then asks the connection's front end for its session
with a ``SessionRequest``: the graph, the connection's identity and the shared
per-client rules (``rules.ClientRules``). What only one protocol bounds is its own
section, which its front end holds beside the request (rosbridge's
``SessionConfig``, the Foxglove protocol's ``FoxgloveLimits``, the HTTP API's
options); nothing here names one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from ..ports import GraphPort
    from .memory import MemoryBudget
    from .rules import ClientRules

__all__ = ["SessionRequest"]


@dataclass(frozen=True, slots=True)
class SessionRequest:
    """What a front end gets to make the session of an admitted connection.

    Attributes:
        graph: the served graph's port.
        client_id: the connection's id in the graph (``ws:127.0.0.1:5000#3``).
        transport: ``ws``, ``tcp``, ``tls``, ``udp``, ``webrtc``, ``http``, ``mcp``,
            ``stdio`` or ``memory``.
        peer: the peer's address (``HOST:PORT``).
        rules: the per-client rules of every protocol for this transport
            (``ClientRules``: the send buffer, the caps, the idle timeout, the
            access rules; docs/limits.md, "Per connection").
        on_output: the pump's wake-up (the session's ``on_output``).
        on_closed: the server's bookkeeping when the session closes.
        auth_nonce: the connection's auth challenge when the transport sent it
            (UDP with ``--auth-bind-connection``); None: the session makes one if
            its protocol asks for one.
        authenticated: the connection proved who it is at its entry already (a
            URL token, a bearer token; ``rwt_protocol.credentials``).
        memory: the server's memory budget every session is charged to (D44).
    """

    graph: GraphPort
    client_id: str
    transport: str
    peer: str
    rules: ClientRules
    on_output: Callable[[], None]
    on_closed: Callable[[str], None]
    auth_nonce: str | None = None
    authenticated: bool = False
    memory: MemoryBudget | None = None
