"""TF: the transform buffer and the tf2_web_republisher (docs/tf.md).

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_graph.tf import (
        DisconnectedFramesError,
        ExtrapolationError,
        StampedTransform,
        TFBuffer,
        TFError,
        TFRepublisher,
        UnknownFrameError,
    )
    from rwt_graph.tf.loop import install_tf_republisher

__all__ = [
    "DisconnectedFramesError",
    "ExtrapolationError",
    "StampedTransform",
    "TFBuffer",
    "TFError",
    "TFRepublisher",
    "UnknownFrameError",
    "install_tf_republisher",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
