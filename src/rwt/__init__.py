"""rwt: a ROS-free rosbridge v2 server, client and conformance suite.

What most programs need, in one import::

    import rwt

    graph = rwt.Graph()                                  # the in-memory robot graph
    server = rwt.GraphServer(graph, rwt.ServerConfig(port=9090))
    # await server.serve()  -- inside an anyio event loop

    # await rwt.call_service(graph, "/add_two_ints", {"a": 1, "b": 2})
    # async with rwt.Ros("ws://127.0.0.1:9090") as ros: ...

The rest is in namespaces that follow the docs pages: ``rwt.types`` (message
types), ``rwt.tf``, ``rwt.media`` (depth clouds), ``rwt.video``, ``rwt.bag``
(record and replay), ``rwt.zenoh``, ``rwt.ros2``, ``rwt.server`` (the parts of
``ServerConfig``, access rules, authentication), ``rwt.client`` and
``rwt.errors``. docs/api.md lists them, and where each name that left ``rwt``
went.

The API is closed: every type its functions and methods take, return or raise
is in ``rwt`` or one of its namespaces (tests/api/test_public_api.py walks them),
and the packages behind it (``rwt_graph``, ``rwt_client``, ...) are its
implementation, free to change. Each name's ``__module__`` is its public place
(as in anyio and httpx), so tracebacks, ``repr`` and the API reference show
``rwt.Graph`` and ``rwt.tf.TFBuffer``, not where they are defined. Every error is
an ``rwt.RwtError``.

Names and namespaces load when first used (PEP 562), so the client (``Ros``,
``SyncRos``, ``Topic``, ``Service``, ``Action``) works on an install without the
server extra, and ``import rwt`` stays cheap. docs/embedding.md and
docs/client.md show each in use.
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING

from rwt_protocol.distribution import DISTRIBUTION

from ._names import NAMESPACES, load

if TYPE_CHECKING:
    from rwt_client import Action, GoalHandle, Param, Ros, ServerGoal, Service, SyncRos, Topic
    from rwt_client.connectors import ConnectionClosedError
    from rwt_graph.actions import GoalCanceledError, GoalContext
    from rwt_graph.async_calls import GoalOutcome, call_service, send_action_goal
    from rwt_graph.clock import Clock
    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalActionServer, LocalPublisher, LocalService, LocalSubscription
    from rwt_protocol.errors import (
        CallTimeoutError,
        ConfigError,
        FieldError,
        GraphError,
        OpRefusedError,
        ProtocolError,
        RwtError,
        ServiceCallError,
        TransportError,
    )
    from rwt_protocol.levels import StatusLevel
    from rwt_protocol.ports import GoalStatus
    from rwt_protocol.qos import QosProfile
    from rwt_protocol.server.session import SessionConfig
    from rwt_transports.listen import ListenError
    from rwt_transports.server import GraphServer, RosbridgeServer, ServerConfig

    # the namespaces, for type checkers (they load on first use)
    from . import bag as bag
    from . import client as client
    from . import errors as errors
    from . import media as media
    from . import ros2 as ros2
    from . import server as server
    from . import tf as tf
    from . import types as types
    from . import video as video
    from . import zenoh as zenoh

__all__ = [
    "Action",
    "CallTimeoutError",
    "Clock",
    "ConfigError",
    "ConnectionClosedError",
    "FieldError",
    "GoalCanceledError",
    "GoalContext",
    "GoalHandle",
    "GoalOutcome",
    "GoalStatus",
    "Graph",
    "GraphError",
    "GraphServer",
    "ListenError",
    "LocalActionServer",
    "LocalPublisher",
    "LocalService",
    "LocalSubscription",
    "OpRefusedError",
    "Param",
    "ProtocolError",
    "QosProfile",
    "Ros",
    "RosbridgeServer",
    "RwtError",
    "ServerConfig",
    "ServerGoal",
    "Service",
    "ServiceCallError",
    "SessionConfig",
    "StatusLevel",
    "SyncRos",
    "Topic",
    "TransportError",
    "__version__",
    "call_service",
    "send_action_goal",
]

try:
    __version__ = version(DISTRIBUTION)
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0+unknown"


def __getattr__(name: str) -> object:
    """Load a public name, or a namespace (``rwt.tf``), on first use.

    Raises:
        AttributeError: ``name`` is not part of the public API.
        ModuleNotFoundError: the name needs an extra (``pip install "rwt-rosbridge[server]"``,
            ``rwt-rosbridge[zenoh]``, ``rwt-rosbridge[ros2]``) that is not installed.
    """
    if name in NAMESPACES:
        return importlib.import_module(f"{__name__}.{name}")
    value = globals()[name] = load(__name__, name)
    return value


def __dir__() -> list[str]:
    return sorted([*__all__, *NAMESPACES])
