"""What a client's advertisement with a ``qos`` hears of its topic's offer (protocol 2.1.0).

ROS 2 tells a publisher two things of its offer that rosbridge_suite never passes
on, and that a rosbridge client can act on (resend, slow down, change its QoS):

- **offered incompatible QoS** (D64): a subscription asks what the topic's offer
  cannot meet, so it receives nothing from the topic while the offer stands. The
  client is warned once per episode (``rwt_graph.topic_qos``): from the first
  such subscription until none is left, or the offer changes;
- **offered deadline missed** (D65): the client's advertisement asked a
  ``deadline``, the topic's offer has one, and nothing was published on the
  topic for that long: one warning per episode (``deadline.DeadlineWatch``), the
  next message ending it. The topic's deadline is the offer's, fixed by its
  first registration (D62), as the messages of all its publishers are the one
  ROS 2 publisher's of the reference.

Each warning is a ``warning`` status with the advertisement's id: a client at the
default level ``error`` hears none of it (D2).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..qos import format_seconds
from .deadline import DeadlineWatch, Schedule

if TYPE_CHECKING:
    from collections.abc import Callable

    from ..qos import QosProfile

__all__ = ["PublisherQos"]


class PublisherQos:
    """One client's advertisement of a topic with a ``qos``: its ``OfferWatch`` (module text).

    Args:
        spelling: the topic as the client wrote it.
        asked: the ``qos`` profile it advertised with.
        schedule: the session's timers.
        warn: sends the client a warning status (with the advertisement's id).
        since: when it advertised, monotonic seconds: the deadline counts from there.
    """

    __slots__ = ("_asked", "_deadline", "_deadline_s", "_spelling", "_warn", "since")

    def __init__(
        self,
        spelling: str,
        asked: QosProfile,
        schedule: Schedule,
        warn: Callable[[str], None],
        since: float,
    ) -> None:
        self._spelling = spelling
        self._asked = asked
        self._warn = warn
        self.since = since
        self._deadline_s = math.inf
        self._deadline = DeadlineWatch(schedule, self._missed)

    def on_offer(self, offered: QosProfile | None, latest: Callable[[], float]) -> None:
        """The topic's offer (``OfferWatch``): watch its deadline if the client asked one."""
        asked_one = not math.isinf(self._asked.deadline_s) or self._asked.deadline_best_available
        if offered is None or not asked_one:
            self._deadline.cancel()
            return
        self._deadline_s = offered.deadline_s
        self._deadline.arm(offered.deadline_s, latest, self.since)

    def on_incompatible(self, offered: QosProfile, reasons: list[str]) -> None:
        """A subscription the offer cannot meet (``OfferWatch``): warn once (D64)."""
        self._warn(
            f"{self._spelling} offers {offered.describe()}, which a subscription cannot use"
            f" ({'; '.join(reasons)}): it receives nothing from this topic while that offer"
            " stands, as in ROS 2 (offered incompatible QoS)"
        )

    def close(self) -> None:
        """The client no longer advertises the topic: stop watching."""
        self._deadline.cancel()

    def _missed(self) -> None:
        self._warn(
            f"{self._spelling} missed its offered deadline: nothing published for"
            f" {format_seconds(self._deadline_s)}"
        )
