"""A client's QoS (protocol 2.1.0's ``qos``) in the rmw_zenoh tokens the Zenoh link declares.

A token says what the link delivers (docs/zenoh.md, "QoS"), which ROS 2 nodes on
rmw_zenoh read as the endpoint's QoS:

- a publisher of a topic whose first registration fixed an offer (D62) carries that
  offer's reliability, durability, history and depth, and deadline: the link puts
  every message of the topic on Zenoh as it is published, through a publication
  cache of that depth when the offer is transient local (``ZenohLink._tap``). Its
  lifespan is written infinite: the cache serves late joiners what it keeps,
  however old, as rmw_zenoh's own does (rmw_zenoh implements no lifespan), while
  the graph's clients get the lifespan they were offered;
- a subscription a client made with a ``qos`` carries that request, resolved
  against the offer (``best_available``); subscriptions have no lifespan;
- any other keeps the link's profiles (``wire.VOLATILE_QOS``, ``wire.LATCHED_QOS``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from rwt_protocol.qos import History as QosHistory
from rwt_protocol.qos import Reliability as QosReliability

from .wire import INFINITE, Durability, History, QoS, Reliability

if TYPE_CHECKING:
    from rwt_protocol.qos import QosProfile

__all__ = ["token_qos"]


def _duration(seconds: float) -> tuple[int, int]:
    """Seconds as rmw's (s, ns); infinite as ``RMW_DURATION_INFINITE``."""
    if math.isinf(seconds):
        return INFINITE
    ns = round(seconds * 1e9)
    return ns // 1_000_000_000, ns % 1_000_000_000


def token_qos(profile: QosProfile) -> QoS:
    """The token QoS of a graph endpoint of ``profile`` (resolved: no ``best_available``).

    ``profile``: a topic's offer (a publisher's token), or a subscription's request
    resolved against it. The lifespan is infinite either way (module text).
    """
    reliability = (
        Reliability.BEST_EFFORT
        if profile.reliability is QosReliability.BEST_EFFORT
        else Reliability.RELIABLE
    )
    keep_all = profile.history is QosHistory.KEEP_ALL
    return QoS(
        reliability=reliability,
        durability=Durability.TRANSIENT_LOCAL if profile.transient_local else Durability.VOLATILE,
        history=History.KEEP_ALL if keep_all else History.KEEP_LAST,
        depth=0 if keep_all else profile.keep,
        deadline=_duration(profile.deadline_s),
        lifespan=INFINITE,
    )
