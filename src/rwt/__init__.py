"""rwt: a ROS-free rosbridge v2 server, client and conformance suite.

What embedding code and client code need, in one import::

    import rwt

    graph = rwt.Graph()                                  # the in-memory robot graph
    server = rwt.RosbridgeServer(graph, rwt.ServerConfig(port=9090))
    # await server.serve()  -- inside an anyio event loop

    # await rwt.call_service(graph, "/add_two_ints", {"a": 1, "b": 2})
    # async with rwt.Recorder(graph, "run1"): ...        # record topics into a bag
    # async with rwt.Ros("ws://127.0.0.1:9090") as ros: ...

Names load when first used (PEP 562), so the client (``Ros``, ``SyncRos``,
``Topic``, ``Service``, ``Action``) works on an install without the server
extra, and ``import rwt`` stays cheap. docs/embedding.md and docs/client.md
show each in use.
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rwt_bag import Player, Recorder
    from rwt_client import Action, Ros, Service, SyncRos, Topic
    from rwt_graph.async_calls import GoalOutcome, call_service, send_action_goal
    from rwt_graph.graph import Graph
    from rwt_protocol.errors import CallTimeoutError, RwtError, ServiceCallError
    from rwt_transports.server import RosbridgeServer, ServerConfig

__all__ = [
    "Action",
    "CallTimeoutError",
    "GoalOutcome",
    "Graph",
    "Player",
    "Recorder",
    "Ros",
    "RosbridgeServer",
    "RwtError",
    "ServerConfig",
    "Service",
    "ServiceCallError",
    "SyncRos",
    "Topic",
    "__version__",
    "call_service",
    "send_action_goal",
]

_HOMES = {
    "Action": "rwt_client",
    "CallTimeoutError": "rwt_protocol.errors",
    "Graph": "rwt_graph.graph",
    "GoalOutcome": "rwt_graph.async_calls",
    "Player": "rwt_bag",
    "Recorder": "rwt_bag",
    "Ros": "rwt_client",
    "RosbridgeServer": "rwt_transports.server",
    "RwtError": "rwt_protocol.errors",
    "ServerConfig": "rwt_transports.server",
    "Service": "rwt_client",
    "ServiceCallError": "rwt_protocol.errors",
    "SyncRos": "rwt_client",
    "Topic": "rwt_client",
    "call_service": "rwt_graph.async_calls",
    "send_action_goal": "rwt_graph.async_calls",
}

try:
    __version__ = version("rwt")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0+unknown"


def __getattr__(name: str) -> object:
    """Load a public name from its home module on first use.

    Raises:
        AttributeError: ``name`` is not part of the public API.
        ModuleNotFoundError: the name needs the server extra (``pip install
            "rwt[server]"``) and it is not installed.
    """
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'rwt' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
