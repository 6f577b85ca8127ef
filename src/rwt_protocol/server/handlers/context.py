"""What a handler may use of its connection: the session's surface for handlers.

Handlers see a ``HandlerContext``, not the whole ``Session``: the graph, this
connection's holdings (``holdings.Holdings``: its subscriptions, advertisements,
offers, goals and counters), and the few actions a handler takes (send an op,
report a status, set a timer, check a cap, feed a reassembled frame back).
Every member is read-only: a handler changes its connection only through
methods (of the context, or of its holdings). The transport-facing
half of the session (``frames_to_send``, ``close``, ``request_close``, the
outbox) is out of a handler's reach. ``Session`` satisfies this protocol.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from ...ops.base import Compression

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from ...codecs.png import PendingPng
    from ...framing.fragments import Reassembler
    from ...levels import StatusLevel
    from ...ops import OpModel
    from ...ports import ClientId, GraphPort, MessageCodec, MessageEvent
    from ...runtime.callbook import CallBook
    from ...runtime.timers import Timer
    from ..holdings import Holdings
    from ..subscriptions import TopicSubscription
    from .providers import ProviderLink

__all__ = ["HandlerContext"]


class HandlerContext(Protocol):
    """One connection as its handlers see it (implemented by ``Session``)."""

    @property
    def graph(self) -> GraphPort:
        """The graph the connection operates on."""

    @property
    def client_id(self) -> ClientId:
        """The connection's identity in the graph."""

    @property
    def peer(self) -> str:
        """The peer's address, ``host:port``."""

    @property
    def holdings(self) -> Holdings:
        """What the connection holds: subscriptions, advertisements, offers, goals, counts."""

    @property
    def calls(self) -> CallBook:
        """The connection's calls in flight (a cap, a deadline each, answered once)."""

    @property
    def provider_link(self) -> ProviderLink:
        """The graph's way to the peer's services and actions."""

    @property
    def input_lossy(self) -> bool:
        """Whether the op being handled came on the transport's lossy channel (D36)."""

    @property
    def fragments(self) -> Reassembler:
        """The connection's incomplete ``fragment`` and ``png`` messages (D19)."""

    def set_status_level(self, level: StatusLevel) -> None:
        """Change which status frames the connection receives (D2)."""

    @property
    def config(self) -> SessionSettings:
        """The connection's settings (limits, access rules, authenticator)."""

    def send(
        self,
        op: OpModel,
        *,
        compression: Compression = Compression.NONE,
        fragment_size: int | None = None,
        codec: MessageCodec | None = None,
    ) -> None:
        """Queue an op that must not be dropped (``Session.send``)."""

    def send_request(self, op: OpModel, what: str) -> None:
        """Queue a request to this peer as a provider if it has room (``Session.send_request``).

        Raises:
            GraphError: ``<what>: provider busy ...`` (docs/limits.md).
        """

    def report(self, level: StatusLevel, text: str, op_id: str | int | None = None) -> None:
        """Send a ``status`` frame if the connection's level admits it (D1-D3)."""

    def check_cap(self, count: int, cap: int, what: str) -> None:
        """Raise ``LimitError`` when ``count`` already reached ``cap`` (docs/limits.md)."""

    def call_at(self, deadline: float, callback: Callable[[float], None]) -> Timer:
        """Run ``callback(now)`` once ``now >= deadline``."""

    def watch_fragments(self) -> None:
        """Make sure the earliest fragment deadline has a timer (D19)."""

    def receive_frame(self, frame: str | bytes, now: float, *, binary: bool = False) -> None:
        """Handle a frame reassembled from parts as if it had just arrived."""

    def inflate_png(self, png: PendingPng, op_id: str | int | None, now: float) -> None:
        """Inflate a ``png`` op's image at the connection's pace, then handle its text."""

    def deliver(self, subscription: TopicSubscription, event: MessageEvent) -> None:
        """Queue one topic message for the peer (the subscription's sink)."""

    def deliver_many(self, subscription: TopicSubscription, events: Sequence[MessageEvent]) -> None:
        """Queue a run of one topic's messages for the peer, in order (a batch sink's)."""

    def deliver_ruled(self, subscription: TopicSubscription, event: MessageEvent) -> None:
        """Queue one topic message of a subscription with QoS (its rule and lifespan)."""

    def warn_subscription(self, subscription: TopicSubscription, text: str) -> None:
        """Warn the peer of a QoS event of ``subscription`` (D64, D65), with its latest id."""


if TYPE_CHECKING:
    from ..session import SessionConfig as SessionSettings
