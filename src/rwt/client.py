"""What the rosbridge client takes and returns besides ``rwt.Ros`` and its handles (docs/client.md).

``ActionResult`` is an action goal's outcome (``GoalHandle.result()``);
``message_class`` builds the ``MessageClass`` of a message type, for typed
topics (``rwt.Topic``); ``Connection`` is what a ``Ros``'s ``connector`` opens
(a connection of your own making, such as an in-process one).

Each name loads from its home on first use, as ``rwt``'s do.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rwt._names import load

if TYPE_CHECKING:
    from rwt_client.connectors import Connection
    from rwt_client.typed import MessageClass, message_class
    from rwt_protocol.ops import ActionResult

__all__ = [
    "ActionResult",
    "Connection",
    "MessageClass",
    "message_class",
]


def __getattr__(name: str) -> object:
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
