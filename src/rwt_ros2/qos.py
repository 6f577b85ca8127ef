"""A client's QoS (protocol 2.1.0's ``qos``) as the ROS 2 link's rclpy endpoints take it.

The link gives a topic's rclpy publisher the QoS its first publisher registration
fixed (``rwt_graph.topic_qos``, D62), and its rclpy subscription the QoS its first
local subscriber still there asked, as rosbridge_suite 3.3 creates its one
publisher and one subscription per topic with the first registration's profile
(docs/ros2.md, "QoS"). Every policy goes across as given: ``best_available`` too,
which rmw resolves against the ROS 2 endpoints it meets, and ``keep_all`` as rclpy's
(the history within the graph is capped, ``rwt_protocol.qos.MAX_DEPTH``; ROS 2's is
its middleware's). Without a client's QoS the link keeps its own rules
(``graphview``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from rwt_protocol.qos import Durability, History, Reliability

if TYPE_CHECKING:
    from rwt_protocol.qos import QosProfile

__all__ = ["rclpy_qos"]


def rclpy_qos(profile: QosProfile) -> Any:
    """The ``rclpy.qos.QoSProfile`` of ``profile``, every policy as the client gave it.

    Durations go as rclpy ``Duration`` values (infinite: rclpy's ``Infinite``); a
    ``best_available`` deadline as ``DeadlineBestAvailable``.
    """
    from rclpy.duration import Duration, Infinite  # noqa: PLC0415 (rclpy: the link's extra)
    from rclpy.qos import (  # noqa: PLC0415
        DeadlineBestAvailable,
        DurabilityPolicy,
        HistoryPolicy,
        QoSProfile,
        ReliabilityPolicy,
    )

    def duration(seconds: float) -> Any:
        return Infinite if math.isinf(seconds) else Duration(nanoseconds=round(seconds * 1e9))

    keep_all = profile.history is History.KEEP_ALL
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        depth=profile.keep,
        reliability={
            Reliability.RELIABLE: ReliabilityPolicy.RELIABLE,
            Reliability.BEST_EFFORT: ReliabilityPolicy.BEST_EFFORT,
            Reliability.BEST_AVAILABLE: ReliabilityPolicy.BEST_AVAILABLE,
        }[profile.reliability],
        durability={
            Durability.TRANSIENT_LOCAL: DurabilityPolicy.TRANSIENT_LOCAL,
            Durability.VOLATILE: DurabilityPolicy.VOLATILE,
            Durability.BEST_AVAILABLE: DurabilityPolicy.BEST_AVAILABLE,
        }[profile.durability],
        deadline=DeadlineBestAvailable
        if profile.deadline_best_available
        else duration(profile.deadline_s),
        lifespan=duration(profile.lifespan_s),
    )
