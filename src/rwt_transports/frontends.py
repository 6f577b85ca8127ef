"""The protocols a server speaks, each a front end on the one connection runtime.

A front end names how a connection chooses it (a WebSocket subprotocol in the
handshake, a WebRTC data channel's label), how its session is made, and how its
clients prove who they are (``AuthMode``, ``rwt_protocol.credentials``); an HTTP
front end (``HttpFrontEnd``) names the paths it answers on the WebSocket port and
makes the endpoint that answers them. The registry (``frontends_registry``) lists
them all; the listeners and the WebRTC peers consult it (``FrontEnds``, and the
server's HTTP endpoints made from ``frontends_registry.HTTP_FRONTENDS``) and
nothing else: admission (``--max-connections``, the host shares,
``/connected_clients``), the per-client limits, flow control, the idle timeout and
the slow-consumer rule are the server's and the pump's, the same for every front
end (docs/architecture.md, "How to add a protocol").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_protocol.credentials import AuthMode

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Sequence

    from rwt_protocol.framing.fragments import FragmentBudget
    from rwt_protocol.ports import GraphPort
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.memory import MemoryBudget
    from rwt_protocol.server.session import SessionConfig

    from .server import GraphServer, ServerConfig
    from .websocket import HttpEndpoint

__all__ = [
    "AuthMode",
    "ChannelLabel",
    "FrontEnd",
    "FrontEnds",
    "HttpFrontEnd",
    "SessionRequest",
    "SocketFrontEnd",
]


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
        auth: how its clients prove who they are (``AuthMode``).
        labels: WebRTC data-channel labels that select it (docs/webrtc.md): a
            reliable, ordered channel so labelled opens its session.
        lossy_labels: labels of its session's lossy channel (unordered, never
            retransmitted, D36), which opens the session's lossy lane.
    """

    name: str
    subprotocols: tuple[str, ...]
    make_session: Callable[[SessionRequest], ServerSession]
    auth: AuthMode = AuthMode.OP
    labels: tuple[str, ...] = ()
    lossy_labels: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class ChannelLabel:
    """What a WebRTC data channel's label selects (``FrontEnds.by_label``).

    Attributes:
        frontend: the protocol its session speaks.
        lossy: the session's lossy channel (``FrontEnd.lossy_labels``), not its
            reliable one.
    """

    frontend: FrontEnd
    lossy: bool


@dataclass(frozen=True, slots=True)
class HttpFrontEnd:
    """One front end of HTTP requests on the WebSocket port (docs/architecture.md).

    Attributes:
        name: its name in logs and in ``ServerConfig.http_options``.
        paths: the paths (or path prefixes ending in ``/``) its endpoint claims.
        make_endpoint: its endpoint for a server and its options: an
            ``HttpEndpoint`` that claims and answers the requests; it admits
            each through the server (``GraphServer.admit``, ``open_session``)
            and checks its clients' proofs with ``GraphServer.entry``.
        options: its options when the configuration names none; None: off.
        auth: how its clients prove who they are.
        transport: the transport its sessions run on, when it is one of its own
            (``webrtc``), for ``GET /version``'s list.
        configured: where ``ServerConfig`` holds its options when it has a field
            of its own (``ServerConfig.webrtc``); ``ServerConfig.http_options``
            by its name comes first.
    """

    name: str
    paths: tuple[str, ...]
    make_endpoint: Callable[[GraphServer, object], HttpEndpoint]
    options: object = None
    auth: AuthMode = AuthMode.BEARER
    transport: str | None = None
    configured: Callable[[ServerConfig], object] | None = None

    def options_in(self, config: ServerConfig) -> object:
        """Its options under ``config``: ``http_options[name]``, its field, or the default.

        None: it is off.
        """
        if self.name in config.http_options:
            return config.http_options[self.name]
        if self.configured is not None:
            return self.configured(config)
        return self.options


@dataclass(frozen=True, slots=True)
class SocketFrontEnd:
    """A registered protocol of the WebSocket listeners besides the default (rosbridge).

    Attributes:
        name: its name (``foxglove``), also its own listener's in ``GraphServer.urls``.
        make: its front end for one server (made once, when the server is).
        on_port: whether ``ServerConfig`` puts it on the WebSocket port.
        own_port: the port of a listener that speaks only it; None: none.
    """

    name: str
    make: Callable[[GraphServer], FrontEnd]
    on_port: Callable[[ServerConfig], bool]
    own_port: Callable[[ServerConfig], int | None]


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
        self._by_label = {
            label: ChannelLabel(each, lossy)
            for each in every
            for lossy, labels in ((False, each.labels), (True, each.lossy_labels))
            for label in labels
        }

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

    @property
    def every(self) -> tuple[FrontEnd, ...]:
        """The default front end (if any), then the others."""
        return (*([] if self.default is None else [self.default]), *self.others)

    def by_label(self, label: str) -> ChannelLabel | None:
        """What a WebRTC data channel labelled ``label`` selects, or None: none registered.

        Safe from any thread (libdatachannel's asks): the table is not changed
        once the server serves.
        """
        return self._by_label.get(label)

    def labels(self) -> tuple[str, ...]:
        """Every registered data-channel label, for a refusal that names them."""
        return tuple(self._by_label)

    def refusal(self) -> str:
        """What a client that offers none of this listener's subprotocols is told (HTTP 400)."""
        names = ", ".join(name for each in self.others for name in each.subprotocols)
        return f"this port speaks {', '.join(e.name for e in self.others)} only: offer {names}"

    def without_default(self) -> FrontEnds:
        """These front ends, a client offering none of them refused (a protocol's own port)."""
        return FrontEnds(None, self.others)
