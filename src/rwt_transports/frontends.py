"""The protocols a server speaks, each a front end on the one connection runtime.

A front end names how a connection chooses it (a WebSocket subprotocol in the
handshake, a WebRTC data channel's label), how its session is made, and how its
clients authenticate; an HTTP front end (``HttpFrontEnd``) names the paths it
answers on the WebSocket port and makes the endpoint that answers them. The
listeners consult the registry (``FrontEnds``, and the server's HTTP front ends,
``frontends_registry.HTTP_FRONTENDS``) and nothing else: admission (``--max-connections``, the
host shares, ``/connected_clients``), the per-client limits, flow control, the
idle timeout and the slow-consumer rule are the server's and the pump's, the same
for every front end (docs/architecture.md, "How to add a protocol").
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Sequence

    from rwt_protocol.framing.fragments import FragmentBudget
    from rwt_protocol.ports import GraphPort
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.memory import MemoryBudget
    from rwt_protocol.server.session import SessionConfig

    from .server import RosbridgeServer
    from .websocket import HttpEndpoint

__all__ = ["AuthMode", "FrontEnd", "FrontEnds", "HttpFrontEnd", "SessionRequest"]


class AuthMode(Enum):
    """How a front end's clients authenticate when the server has an authenticator."""

    OP = "op"
    """With the protocol's first op (rosbridge's ``auth``, D23); the URL is not read."""
    URL_TOKEN = "url"
    """With a token in the handshake's URL, checked before any session (D33)."""
    BEARER = "bearer"
    """With ``Authorization: Bearer <token>`` on each request (``http_endpoint.bearer``)."""


@dataclass(frozen=True, slots=True)
class SessionRequest:
    """What a front end gets to make the session of an admitted connection.

    Attributes:
        graph: the served graph's port.
        client_id: the connection's id in the graph (``ws:127.0.0.1:5000#3``).
        transport: ``ws``, ``tcp``, ``tls``, ``udp``, ``stdio`` or ``memory``.
        peer: the peer's address.
        config: the per-client settings for this transport: rosbridge's
            ``SessionConfig``, whose ``ClientRules`` part every front end reads.
        on_output: the pump's wake-up.
        on_closed: the server's bookkeeping when the session closes.
        fragment_budget: the server-wide budget of incomplete messages.
        auth_nonce: the connection's auth challenge when the transport sent it.
        authenticated: the transport admitted the client already (a URL token).
        memory: the server's memory budget every session is charged to (D44).
    """

    graph: GraphPort
    client_id: str
    transport: str
    peer: str
    config: SessionConfig
    on_output: Callable[[], None]
    on_closed: Callable[[str], None]
    fragment_budget: FragmentBudget | None = None
    auth_nonce: str | None = None
    authenticated: bool = False
    memory: MemoryBudget | None = None


@dataclass(frozen=True, slots=True)
class FrontEnd:
    """One protocol on the server's connections.

    Attributes:
        name: its name in logs and errors (``rosbridge``, ``foxglove``).
        subprotocols: WebSocket subprotocols that select it, in the server's
            preference; empty for the default front end (a client that offers
            none of the others).
        make_session: the session of an admitted connection.
        auth: how its clients authenticate (``AuthMode``).
        labels: WebRTC data-channel labels that select it (docs/webrtc.md).
    """

    name: str
    subprotocols: tuple[str, ...]
    make_session: Callable[[SessionRequest], ServerSession]
    auth: AuthMode = AuthMode.OP
    labels: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class HttpFrontEnd:
    """One front end of HTTP requests on the WebSocket port (docs/architecture.md).

    Attributes:
        name: its name in logs and in ``ServerConfig.http_options``.
        paths: the paths (or path prefixes ending in ``/``) its endpoint claims.
        make_endpoint: its endpoint for a server and its options: an
            ``HttpEndpoint`` that claims and answers the requests; it admits
            each through the server (``RosbridgeServer.open_session``).
        options: its options when ``ServerConfig.http_options`` names none.
        auth: how its clients authenticate.
    """

    name: str
    paths: tuple[str, ...]
    make_endpoint: Callable[[RosbridgeServer, object], HttpEndpoint]
    options: object = None
    auth: AuthMode = AuthMode.BEARER


class FrontEnds:
    """The front ends of one listener: a default and the ones chosen by subprotocol.

    Args:
        default: the front end of a client that offers none of the others'
            subprotocols (rosbridge); None: such a client is refused.
        others: the front ends chosen by subprotocol.
    """

    def __init__(self, default: FrontEnd | None, others: Sequence[FrontEnd] = ()) -> None:
        self.default = default
        self.others = tuple(others)
        self._by_subprotocol = {name: each for each in self.others for name in each.subprotocols}
        every = (*([] if default is None else [default]), *self.others)
        self._by_label = {label: each for each in every for label in each.labels}

    def select(self, offered: Iterable[str]) -> tuple[FrontEnd | None, str | None]:
        """The front end a handshake offering ``offered`` gets, and the subprotocol to answer.

        The first subprotocol the client offers (in its order) that a front end
        claims wins; none: the default front end, no subprotocol.
        """
        for name in offered:
            frontend = self._by_subprotocol.get(name)
            if frontend is not None:
                return frontend, name
        return self.default, None

    def by_label(self, label: str) -> FrontEnd | None:
        """The front end a WebRTC data channel labelled ``label`` speaks, or None."""
        return self._by_label.get(label)

    def refusal(self) -> str:
        """What a client that offers none of this listener's subprotocols is told (HTTP 400)."""
        names = ", ".join(name for each in self.others for name in each.subprotocols)
        return f"this port speaks {', '.join(e.name for e in self.others)} only: offer {names}"

    def without_default(self) -> FrontEnds:
        """These front ends, a client offering none of them refused (a protocol's own port)."""
        return FrontEnds(None, self.others)
