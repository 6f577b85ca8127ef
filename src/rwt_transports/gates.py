"""The links' gates: a served graph's links take part in its flow control.

``rwt_graph.link`` defines two gates a link goes through (``InflowGate``,
``OutflowGate``); the server installs these on the graph it serves. Both carry
out the decisions of the server's ``rwt_protocol.runtime.flow.FlowControl``, as its connections'
pumps do (docs/limits.md, "Backpressure").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import anyio

from .holding import Held, LinkHold, wait_for
from .pump import flush_deferred

if TYPE_CHECKING:
    from rwt_graph.link import Backlog
    from rwt_protocol.runtime.flow import FlowControl, HoldAccount

__all__ = ["InboundBatch", "InboundHold", "OutboundHold"]


class InboundHold:
    """The subscribers some of a link's deliveries congested (``InboundBatch.take_hold``)."""

    def __init__(
        self, flow: FlowControl[Held], congested: list[Held], account: HoldAccount
    ) -> None:
        self._flow = flow
        self._congested = congested
        self._account = account

    async def wait(self) -> None:
        """Wait until each is under its low watermark, within the publisher's hold budget."""
        flow = self._flow
        for held in self._congested:
            if held.over_water(own=False, mark=held.high_water):
                await wait_for(flow, held, own=False, account=self._account)


class InboundBatch:
    """The transports' ``InflowGate`` (``rwt_graph.link``): a link's deliveries as a reader's.

    A link's samples come from no connection, yet fill subscribers' outboxes as
    a publisher's frames do. Between ``begin`` and ``end`` the subscribers they
    push over their high watermark are noted and their frames held for one
    write each (as in a reader's batch). ``take_hold`` hands the link what the
    deliveries since its last call congested, for the link to hold back the
    topic they were of (``rwt_graph.topic_holds``) until those outboxes drain
    to their low watermark, within the hold budget of the remote publisher
    whose sample congested them (``rwt_protocol.runtime.flow.FlowControl.link_account``, D61): a
    burst from another process reaches a subscriber that keeps up on average
    whole, a slow one is left to the drop and close rules (D24) once that
    publisher's budget is spent, as with a local publisher, and the link's
    other topics go on meanwhile.

    Args:
        flow: the server's flow control.
    """

    def __init__(self, flow: FlowControl[Held]) -> None:
        self.flow = flow

    def begin(self) -> None:
        """Deliveries start: note congestion, defer the writes (no await until ``end``)."""
        self.flow.begin()

    def end(self) -> None:
        """Deliveries ended: write out what they queued."""
        self.flow.end()
        flush_deferred(self.flow)

    def congested(self) -> bool:
        """Whether a delivery since the last ``take_hold`` pushed an outbox over its high mark."""
        return self.flow.has_congested()

    def take_hold(self, publisher: str | None = None) -> InboundHold | None:
        """What the deliveries since the last call congested, to wait for; None if nothing.

        The wait is charged to ``publisher``'s hold budget (None: the links' own).
        """
        congested = self.flow.take_congested()
        if not congested:
            return None
        return InboundHold(self.flow, congested, self.flow.link_account(publisher))


class OutboundHold:
    """The transports' ``OutflowGate`` (``rwt_graph.link``): a link's queue held as an outbox.

    A link whose queue for the other middleware passed its high watermark
    during a reader's batch is waited for after the batch, as a congested
    subscriber is, until it is under its low watermark, within the reader's
    hold budget; a congestion outside a batch (an in-process publisher) holds
    nobody. Found slow, a link is not waited for until its queue empties.

    Args:
        flow: the server's flow control.
    """

    def __init__(self, flow: FlowControl[Held]) -> None:
        self.flow = flow
        self._holds: dict[int, LinkHold] = {}  # by the backlog's id: one per link

    def congested(self, backlog: Backlog) -> None:
        """Note ``backlog`` for the current batch's reader to wait for (on the event loop)."""
        hold = self._holds.get(id(backlog))
        if hold is None or hold.backlog is not backlog:
            # links come and go (a restarted one is a new backlog): keep only live episodes
            self._holds = {k: h for k, h in self._holds.items() if h.watching}
            hold = self._holds[id(backlog)] = LinkHold(backlog)
        hold.watch()
        flow = self.flow
        if flow.in_batch:  # only a reader's batch is held (and reads the loop's clock)
            flow.note_congested(hold, anyio.current_time())
