"""The protocols a server speaks, each a front end on the one connection runtime.

A front end names how a connection chooses it (a WebSocket subprotocol in the
handshake, a WebRTC data channel's label), how its session is made from the
runtime's ``SessionRequest``, how its clients prove who they are (``AuthMode``,
``rwt_protocol.credentials``), and what a transport, which speaks no protocol,
needs to know of its frames (``first_topic``, ``split_text``). The registry
(``frontends_registry``) lists them all, with the HTTP front ends that answer
paths on the WebSocket port; the listeners and the WebRTC peers consult it
(``FrontEnds``, and the server's HTTP endpoints made from
``frontends_registry.HTTP_FRONTENDS``) and nothing else: admission
(``--max-connections``, the host shares, ``/connected_clients``), the per-client
limits, flow control, the idle timeout and the slow-consumer rule are the
server's and the pump's, the same for every front end (docs/architecture.md,
"How to add a protocol").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_protocol.credentials import AuthMode

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Sequence

    from rwt_protocol.runtime.contract import ServerSession
    from rwt_protocol.runtime.inframes import FramerEvent
    from rwt_protocol.runtime.request import SessionRequest

__all__ = ["AuthMode", "ChannelLabel", "FrontEnd", "FrontEnds"]


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
        first_topic: the topic a connection's first message names, by which
            ``--placement topic`` moves it to the worker owning that topic (D57);
            None: its connections stay where they land.
        split_text: a text frame too large for a channel's message (a WebRTC data
            channel's 64 KiB) cut into parts its peer reassembles (rosbridge's
            ``fragment`` ops, D19): ``split_text(frame, max_bytes)``; None: such a
            frame goes whole where the peer takes it, else it is dropped and logged.
    """

    name: str
    subprotocols: tuple[str, ...]
    make_session: Callable[[SessionRequest], ServerSession]
    auth: AuthMode = AuthMode.OP
    labels: tuple[str, ...] = ()
    lossy_labels: tuple[str, ...] = ()
    first_topic: Callable[[FramerEvent], str | None] | None = None
    split_text: Callable[[bytes, int], Sequence[bytes]] | None = None


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
