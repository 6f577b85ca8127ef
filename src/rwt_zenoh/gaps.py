"""Gaps in remote publishers' sequence numbers: messages lost before they reached here.

rmw_zenoh's attachment numbers each publisher's samples from 1 (``wire.Attachment``),
and rwt's link numbers its own so, once a sample is made (a local message that no
Zenoh subscriber matches makes none). A sample whose number is past the next one
expected means that those between were lost on the way: a full queue of the
publishing process's link (its outbox), of Zenoh, or of this process's inbox. The
link tells the topic's subscribers (``rwt_graph.topics.Topic.report_lost``, D61).
A number that goes back (a latched sample replayed to a late subscriber, a
duplicate) is no gap and changes nothing.
"""

from __future__ import annotations

from collections import OrderedDict

__all__ = ["MAX_TRACKED_PUBLISHERS", "SequenceGaps"]

MAX_TRACKED_PUBLISHERS = 4096
"""Remote publishers whose next sequence number is kept; past it the least recently
heard one is forgotten (its next gap goes unnoticed): GIDs come from the network."""


class SequenceGaps:
    """The next sequence number expected of each remote publisher (by GID); one thread.

    Args:
        max_tracked: publishers kept at most (``MAX_TRACKED_PUBLISHERS``).
    """

    def __init__(self, max_tracked: int = MAX_TRACKED_PUBLISHERS) -> None:
        self._max = max_tracked
        self._next: OrderedDict[bytes, int] = OrderedDict()

    def seen(self, gid: bytes, sequence: int) -> int:
        """Sample ``sequence`` of publisher ``gid`` came: how many before it were lost (0: none).

        The first sample heard of a publisher shows no gap: what it published before
        may have been for subscribers that were not here.
        """
        expected = self._next.get(gid)
        if expected is None:
            self._next[gid] = sequence + 1
            if len(self._next) > self._max:
                self._next.popitem(last=False)
            return 0
        if sequence < expected:  # replayed or repeated
            return 0
        self._next[gid] = sequence + 1
        self._next.move_to_end(gid)
        return sequence - expected
