"""TF, built in: a transform buffer and tf2_web_republisher's interfaces (paper IV.A).

``TFBuffer`` keeps the frame tree from ``/tf`` and ``/tf_static`` and answers
lookups; ``TFSubscription`` decides which transforms a republisher client gets at
each tick; ``install_tf_republisher(graph, sleep)`` wires both into a graph as the
``/tf2_web_republisher`` action, the ``/republish_tfs`` service and the
actionlib topics of ``/tf2_web_republisher`` (REF §7.3).
"""

from __future__ import annotations

from .buffer import (
    DisconnectedFramesError,
    ExtrapolationError,
    StampedTransform,
    TFBuffer,
    TFError,
    UnknownFrameError,
    normalize_frame,
)
from .install import TF_NODE, Sleep, TFRepublisher, install_tf_republisher
from .republisher import TFRequest, TFSubscription

__all__ = [
    "TF_NODE",
    "DisconnectedFramesError",
    "ExtrapolationError",
    "Sleep",
    "StampedTransform",
    "TFBuffer",
    "TFError",
    "TFRepublisher",
    "TFRequest",
    "TFSubscription",
    "UnknownFrameError",
    "install_tf_republisher",
    "normalize_frame",
]
