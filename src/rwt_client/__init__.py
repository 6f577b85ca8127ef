"""The Python rosbridge client: async first, with a thin sync facade.

Shaped like roslibpy (``Ros``, ``Topic``, ``Service``, ``Action``, ``Param``),
on anyio, over WebSocket or TCP::

    import anyio
    from rwt_client import Ros, Topic

    async def main() -> None:
        async with Ros("ws://127.0.0.1:9090") as ros:
            chatter = Topic(ros, "/chatter", "std_msgs/String")
            await chatter.subscribe(lambda msg: print(msg["data"]))
            await chatter.publish({"data": "hello"})

    anyio.run(main)

``SyncRos`` runs the same client in a background thread for blocking code.
"""

from __future__ import annotations

from rwt_protocol.levels import StatusLevel

from .api import Action, GoalHandle, Param, Service, Topic
from .connectors import ConnectionClosedError
from .ros import CallTimeoutError, Ros, ServerGoal, ServiceCallError
from .sync import SyncRos
from .typed import message_class

__all__ = [
    "Action",
    "CallTimeoutError",
    "ConnectionClosedError",
    "GoalHandle",
    "Param",
    "Ros",
    "ServerGoal",
    "Service",
    "ServiceCallError",
    "StatusLevel",
    "SyncRos",
    "Topic",
    "message_class",
]
