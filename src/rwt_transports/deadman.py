"""The safety envelope's timer: dead-man stops on time, and its status for the console.

The envelope (``rwt_graph.safety.envelope.Envelope``) keeps no event loop: it says
when its next dead-man falls due (``next_deadline``) and publishes the stops that
did when asked (``expire``). ``run_deadman`` is that asking, one task of the server
while it serves the graph: it sleeps until the next deadline, woken early when a
topic becomes commanded (``Envelope.on_commanded``), so a stop goes out when it
falls due, not at the next tick of a poll (docs/safety.md gives the latency
measured). It also publishes the envelope's status (the rules and the last
events, ``STATUS_TOPIC``) when it changed, at most every ``STATUS_INTERVAL_S``.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import anyio

if TYPE_CHECKING:
    from rwt_graph.safety.envelope import Envelope

__all__ = ["STATUS_INTERVAL_S", "run_deadman"]

logger = logging.getLogger("rwt.safety")

STATUS_INTERVAL_S = 0.5
"""The envelope's status topic is published at most this often, seconds."""


async def run_deadman(envelope: Envelope) -> None:
    """Publish the envelope's dead-man stops when they fall due, until cancelled.

    A bug in a round is logged and the next round goes on: the server's other
    tasks are not ended by it.
    """
    wake = [anyio.Event()]

    def commanded() -> None:
        wake[0].set()

    envelope.on_commanded = commanded
    published = -math.inf
    try:
        while True:
            now = envelope.clock()
            deadline = envelope.next_deadline()
            wait = math.inf if deadline is None else max(deadline - now, 0.0)
            if envelope.changed:
                wait = min(wait, max(published + STATUS_INTERVAL_S - now, 0.0))
            with anyio.move_on_after(wait):
                await wake[0].wait()
            if wake[0].is_set():
                wake[0] = anyio.Event()
            try:
                envelope.expire()
                now = envelope.clock()
                if envelope.changed and now - published >= STATUS_INTERVAL_S:
                    envelope.publish_status()
                    published = now
            except Exception:  # a bug here must not end the server's task group
                logger.exception("event=bug task=deadman")
                await anyio.sleep(STATUS_INTERVAL_S)
    finally:
        envelope.on_commanded = None
