"""What a transport and a front end know of the server: an interface, not the server.

Every way in (a listener, an HTTP endpoint, a WebRTC peer) gets its sessions from
the server that serves it, and from nothing else of it: ``SessionHost`` is what a
listener of a transport needs (admission, one session per connection, flow
control); ``FrontEndHost`` what a front end of the registry needs besides
(``frontends_registry``: the graph, the one entry check, tickets and slots, the
front ends by subprotocol and label, the settings it reads). ``GraphServer``
(server.py) implements both; a front end is typed against them, so that nothing
below the server imports it (docs/architecture.md, "How to add").

Also here, as they are part of what a front end sees: ``Admitted``, the ticket of
a connection admitted without a session, and ``Features``, what the server offers
(``GET /version``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from collections.abc import Callable

    from rwt_graph.graph import Graph
    from rwt_protocol.credentials import EntryAuth
    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.flow import FlowControl
    from rwt_protocol.runtime.rules import ClientRules
    from rwt_protocol.server.compat import Compat

    from .admission.arrival import Admission
    from .admission.shares import HostPrefixes
    from .frontends import FrontEnd, FrontEnds
    from .holding import Held

__all__ = [
    "Admitted",
    "Features",
    "FrontEndHost",
    "HostSettings",
    "ServedFrontEnd",
    "SessionHost",
]


@dataclass(slots=True)
class Admitted:
    """An admitted connection without a session yet (``FrontEndHost.admit``): its ticket.

    Attributes:
        client_id: the id its session will have (``webrtc:127.0.0.1:5000#3``).
        transport: the transport it was admitted on.
        peer: the peer's address.
        host: the host whose share it counts against; None for a local transport.
        address: the peer's address without its port.
        redeemed: a session took it, or it was released.
    """

    client_id: str
    transport: str
    peer: str
    host: str | None
    address: str
    redeemed: bool = False


@dataclass(frozen=True, slots=True)
class ServedFrontEnd:
    """One front end a server serves, as ``GET /version`` lists it (the registry's entry).

    Attributes:
        name: its name (``rosbridge``, ``foxglove``, ``http``, ``webrtc``, ``mcp``...).
        subprotocols: the WebSocket subprotocols that select it.
        labels: the WebRTC data-channel labels that select it (its lossy ones too).
        paths: the HTTP paths (or prefixes ending in ``/``) it answers.
        auth: how its clients prove who they are (``AuthMode``'s value: ``op``,
            ``url``, ``bearer``...); ``none`` when the server asks for no proof.
    """

    name: str
    subprotocols: tuple[str, ...] = ()
    labels: tuple[str, ...] = ()
    paths: tuple[str, ...] = ()
    auth: str = "none"


@dataclass(frozen=True, slots=True)
class Features:
    """What a server offers beyond the protocol: the ``rwt`` object of ``GET /version``.

    Attributes:
        transports: the ways in, as the server's URLs name them: ``ws`` or ``wss``,
            ``tcp`` or ``tcp+tls``, ``udp``, ``stdio``, ``webrtc`` (docs/server.md).
        encodings: the ``compression`` values a ``subscribe`` may ask for (spec
            3.3.4: ``none``, ``png``, ``cbor``, ``cbor-raw``; D20, D21).
        subprotocols: the WebSocket subprotocols that select another protocol on
            this port (Foxglove's, docs/foxglove.md); rosbridge needs none.
        frontends: every front end served, from the registry
            (``frontends_registry``): the protocols on the WebSocket port and the
            HTTP front ends.
        auth: how a client authenticates: ``none``; ``op``, the rosauth ``auth`` op
            first (a Foxglove client: a token in its URL; D23, D33); ``op-bound``,
            the same signed over the connection's ``auth_challenge`` (D31).
        safety: whether a safety envelope holds what remote clients command
            (``--safety``, docs/safety.md); its rules are not told here (D49).
    """

    transports: tuple[str, ...]
    encodings: tuple[str, ...]
    subprotocols: tuple[str, ...]
    frontends: tuple[ServedFrontEnd, ...]
    auth: str
    safety: bool = False


@dataclass(frozen=True, slots=True)
class HostSettings:
    """What a front end reads of its server's settings (``ServerConfig``, made once).

    Attributes:
        host: the address the listeners bind (``--host``).
        port: the WebSocket port as configured (``--port``; 0: a free one; None: none).
        tls: the listeners speak TLS (``--certfile``).
        allowed_origins: fnmatch patterns of accepted ``Origin`` headers
            (``--allowed-origins``); empty: any origin.
        max_message_size: the largest incoming message, bytes (``--max-message-size``).
        idle_timeout_s: seconds after which a connection that says nothing and holds
            nothing is closed (``--idle-timeout``); None: never.
        compat: the rosbridge_suite release the server plays (``--compat``, D49).
    """

    host: str
    port: int | None
    tls: bool
    allowed_origins: tuple[str, ...]
    max_message_size: int
    idle_timeout_s: float | None
    compat: Compat


class SessionHost(Protocol):
    """What a transport's listener needs from the server: sessions on its one graph (D22)."""

    @property
    def flow(self) -> FlowControl[Held]:
        """The server's flow control, shared by its connections' pumps and its links' gates."""

    @property
    def admission(self) -> Admission:
        """The server's starting connections, whose first input goes first (``arrival``)."""

    def open_session(
        self,
        transport: str,
        peer: str,
        on_output: Callable[[], None],
        *,
        frontend: FrontEnd | None = None,
        auth_nonce: str | None = None,
        authenticated: bool = False,
        ticket: Admitted | None = None,
        share_from_first: bool = False,
    ) -> ServerSession | None:
        """Admit a new connection and make its session (``GraphServer.open_session``).

        ``frontend``: the protocol it speaks (``frontends.FrontEnd``; None: the
        default, rosbridge); ``auth_nonce``: its auth challenge, when the transport
        sent it; ``authenticated``: it proved who it is at its entry (a URL token);
        ``ticket``: it was admitted already (``FrontEndHost.admit``);
        ``share_from_first``: its host's share applies from the first (D40). None
        when the server is full (``--max-connections``, the host's share) or stopping.
        """


class FrontEndHost(SessionHost, Protocol):
    """What a front end of the registry knows of its server (the module's text)."""

    @property
    def graph(self) -> Graph:
        """The served graph (its port, parameters, safety envelope)."""

    @property
    def entry(self) -> EntryAuth:
        """The one check of every way in (``rwt_protocol.credentials``)."""

    @property
    def rules(self) -> ClientRules:
        """The per-client rules of every protocol (the access rules, the caps)."""

    @property
    def settings(self) -> HostSettings:
        """The server's settings a front end reads."""

    @property
    def host_prefixes(self) -> HostPrefixes:
        """What names a peer's host for the host shares (``--host-prefix-v4``, ``-v6``)."""

    @property
    def frontends(self) -> FrontEnds:
        """The protocols of the WebSocket port: by subprotocol, and by data-channel label."""

    def admit(self, transport: str, peer: str) -> Admitted | None:
        """Admission without a session yet: a ticket, or None (full, stopping, the host's share)."""

    def release(self, ticket: Admitted) -> None:
        """Give back the slot of a ticket no session took; idempotent."""

    def take_slot(self, transport: str, peer: str) -> str | None:
        """A slot for a socket a session's request holds: its host, or None (refused; D40)."""

    def give_slot(self, host: str) -> None:
        """Give back a slot ``take_slot`` gave for ``host``."""

    def join_socket(self) -> None:
        """The socket of this task carries a request of a connection admitted already."""

    def features(self) -> Features:
        """What the server offers now (``GET /version``'s ``rwt`` object, D49)."""
