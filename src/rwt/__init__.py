"""rwt: a ROS-free rosbridge v2 server, client and conformance suite.

What embedding code and client code need, in one import::

    import rwt

    graph = rwt.Graph()                                  # the in-memory robot graph
    server = rwt.RosbridgeServer(graph, rwt.ServerConfig(port=9090))
    # await server.serve()  -- inside an anyio event loop

    # await rwt.call_service(graph, "/add_two_ints", {"a": 1, "b": 2})
    # async with rwt.Recorder(graph, "run1"): ...        # record topics into a bag
    # async with rwt.Ros("ws://127.0.0.1:9090") as ros: ...

``rwt`` is closed: every type its functions and methods take, return or raise
is here too (tests/api/test_public_api.py walks them), and the packages behind
it (``rwt_graph``, ``rwt_client``, ...) are its implementation, free to change.
Each name's ``__module__`` reads ``rwt`` (as in anyio and httpx), so tracebacks,
``repr`` and the API reference show ``rwt.Graph``, not where it is defined.
Every error is an ``rwt.RwtError``; the tree is drawn in ``rwt.RwtError``'s
module docstring (rwt_protocol/errors.py).

Names load when first used (PEP 562), so the client (``Ros``, ``SyncRos``,
``Topic``, ``Service``, ``Action``) works on an install without the server
extra, and ``import rwt`` stays cheap. docs/embedding.md and docs/client.md
show each in use.
"""

from __future__ import annotations

import importlib
import sys
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rwt_bag import (
        BagError,
        BagFormat,
        BagInfo,
        Player,
        PlayStats,
        Recorder,
        RecordStats,
        SplitPolicy,
        bag_info,
        serve_controls,
    )
    from rwt_bag.formats import ChunkCompression, Compression
    from rwt_bag.info import TopicSummary
    from rwt_bag.selection import TopicSelection
    from rwt_cli.checks import ListenError
    from rwt_client import Action, GoalHandle, Param, Ros, ServerGoal, Service, SyncRos, Topic
    from rwt_client.connectors import ConnectionClosedError
    from rwt_client.typed import MessageClass, message_class
    from rwt_console.site import ConsoleSite
    from rwt_graph.actions import GoalCanceledError, GoalContext
    from rwt_graph.async_calls import GoalOutcome, call_service, send_action_goal
    from rwt_graph.clock import Clock
    from rwt_graph.graph import Graph
    from rwt_graph.local import LocalActionServer, LocalPublisher, LocalService, LocalSubscription
    from rwt_graph.media import (
        CameraIntrinsics,
        DecodedDepthCloud,
        ImageError,
        decode_depthcloud,
        encode_depthcloud,
        points_from_depth,
    )
    from rwt_graph.media.depthcloud_node import DepthCloudEncoder
    from rwt_graph.parameters.store import (
        ParameterError,
        ParameterNotSetError,
        ParameterStoreFullError,
    )
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
    from rwt_graph.types import (
        ActionType,
        ArrayKind,
        Constant,
        Converted,
        DefinitionError,
        Dialect,
        FieldSpec,
        FieldType,
        InvalidTypeNameError,
        MessageType,
        ServiceType,
        TypeRegistry,
        UnknownTypeError,
        WireCodec,
    )
    from rwt_graph.types.wire import CdrError
    from rwt_protocol.errors import (
        CallTimeoutError,
        ConfigError,
        FieldError,
        GraphError,
        LimitError,
        LocalProtocolError,
        OpRefusedError,
        ProtocolError,
        RemoteProtocolError,
        RwtError,
        ServiceCallError,
        TransportError,
    )
    from rwt_protocol.framing.messages import MessageTooBigError
    from rwt_protocol.levels import StatusLevel
    from rwt_protocol.ops import ActionResult, Auth
    from rwt_protocol.ports import GoalStatus
    from rwt_protocol.server.access import AccessDeniedError, AccessPolicy, Family
    from rwt_protocol.server.outbox import OutFrame
    from rwt_protocol.server.session import SessionConfig
    from rwt_ros2 import Ros2Link, Ros2Options, Ros2Unavailable, open_ros2_link
    from rwt_ros2.runtime import ament_interface_dirs
    from rwt_transports.allocator import tune_allocator
    from rwt_transports.memory import MemoryConnection
    from rwt_transports.server import RosbridgeServer, ServerConfig, rosauth_authenticator
    from rwt_transports.udp import UdpOptions
    from rwt_transports.websocket import WebSocketOptions
    from rwt_video import StreamType, VideoConfig, VideoTokens, install_token_service, serve_video
    from rwt_zenoh.config import ZenohOptions
    from rwt_zenoh.link import ZenohLink, open_zenoh_link
    from rwt_zenoh.wire import RmwCompat, WireError

__all__ = [
    "AccessDeniedError",
    "AccessPolicy",
    "Action",
    "ActionResult",
    "ActionType",
    "ArrayKind",
    "Auth",
    "BagError",
    "BagFormat",
    "BagInfo",
    "CallTimeoutError",
    "CameraIntrinsics",
    "CdrError",
    "ChunkCompression",
    "Clock",
    "Compression",
    "ConfigError",
    "ConnectionClosedError",
    "ConsoleSite",
    "Constant",
    "Converted",
    "DecodedDepthCloud",
    "DefinitionError",
    "DepthCloudEncoder",
    "Dialect",
    "DisconnectedFramesError",
    "ExtrapolationError",
    "Family",
    "FieldError",
    "FieldSpec",
    "FieldType",
    "GoalCanceledError",
    "GoalContext",
    "GoalHandle",
    "GoalOutcome",
    "GoalStatus",
    "Graph",
    "GraphError",
    "ImageError",
    "InvalidTypeNameError",
    "LimitError",
    "ListenError",
    "LocalActionServer",
    "LocalProtocolError",
    "LocalPublisher",
    "LocalService",
    "LocalSubscription",
    "MemoryConnection",
    "MessageClass",
    "MessageTooBigError",
    "MessageType",
    "OpRefusedError",
    "OutFrame",
    "Param",
    "ParameterError",
    "ParameterNotSetError",
    "ParameterStoreFullError",
    "PlayStats",
    "Player",
    "ProtocolError",
    "RecordStats",
    "Recorder",
    "RemoteProtocolError",
    "RmwCompat",
    "Ros",
    "Ros2Link",
    "Ros2Options",
    "Ros2Unavailable",
    "RosbridgeServer",
    "RwtError",
    "ServerConfig",
    "ServerGoal",
    "Service",
    "ServiceCallError",
    "ServiceType",
    "SessionConfig",
    "SplitPolicy",
    "StampedTransform",
    "StatusLevel",
    "StreamType",
    "SyncRos",
    "TFBuffer",
    "TFError",
    "TFRepublisher",
    "Topic",
    "TopicSelection",
    "TopicSummary",
    "TransportError",
    "TypeRegistry",
    "UdpOptions",
    "UnknownFrameError",
    "UnknownTypeError",
    "VideoConfig",
    "VideoTokens",
    "WebSocketOptions",
    "WireCodec",
    "WireError",
    "ZenohLink",
    "ZenohOptions",
    "__version__",
    "ament_interface_dirs",
    "bag_info",
    "call_service",
    "decode_depthcloud",
    "encode_depthcloud",
    "install_tf_republisher",
    "install_token_service",
    "message_class",
    "open_ros2_link",
    "open_zenoh_link",
    "points_from_depth",
    "rosauth_authenticator",
    "send_action_goal",
    "serve_controls",
    "serve_video",
    "tune_allocator",
]

# home module -> the public names it defines; the one table __getattr__ reads
_HOMES: dict[str, tuple[str, ...]] = {
    "rwt_ros2.runtime": ("ament_interface_dirs",),
    "rwt_transports.allocator": ("tune_allocator",),
    "rwt_video": (
        "StreamType",
        "VideoConfig",
        "VideoTokens",
        "install_token_service",
        "serve_video",
    ),
    "rwt_bag": (
        "BagError",
        "BagFormat",
        "BagInfo",
        "PlayStats",
        "Player",
        "RecordStats",
        "Recorder",
        "SplitPolicy",
        "bag_info",
        "serve_controls",
    ),
    "rwt_client": (
        "Action",
        "GoalHandle",
        "Param",
        "Ros",
        "ServerGoal",
        "Service",
        "SyncRos",
        "Topic",
    ),
    "rwt_client.connectors": ("ConnectionClosedError",),
    "rwt_client.typed": (
        "MessageClass",
        "message_class",
    ),
    "rwt_console.site": ("ConsoleSite",),
    "rwt_graph.actions": ("GoalCanceledError", "GoalContext"),
    "rwt_bag.info": ("TopicSummary",),
    "rwt_bag.formats": ("ChunkCompression", "Compression"),
    "rwt_bag.selection": ("TopicSelection",),
    "rwt_protocol.server.outbox": ("OutFrame",),
    "rwt_graph.clock": ("Clock",),
    "rwt_graph.graph": ("Graph",),
    "rwt_graph.local": (
        "LocalActionServer",
        "LocalPublisher",
        "LocalService",
        "LocalSubscription",
    ),
    "rwt_graph.media": (
        "CameraIntrinsics",
        "DecodedDepthCloud",
        "ImageError",
        "decode_depthcloud",
        "encode_depthcloud",
        "points_from_depth",
    ),
    "rwt_graph.media.depthcloud_node": ("DepthCloudEncoder",),
    "rwt_graph.parameters.store": (
        "ParameterError",
        "ParameterNotSetError",
        "ParameterStoreFullError",
    ),
    "rwt_graph.tf": (
        "DisconnectedFramesError",
        "ExtrapolationError",
        "StampedTransform",
        "TFBuffer",
        "TFError",
        "TFRepublisher",
        "UnknownFrameError",
    ),
    "rwt_graph.types": (
        "ActionType",
        "ArrayKind",
        "Constant",
        "Converted",
        "DefinitionError",
        "Dialect",
        "FieldSpec",
        "FieldType",
        "InvalidTypeNameError",
        "MessageType",
        "ServiceType",
        "TypeRegistry",
        "UnknownTypeError",
        "WireCodec",
    ),
    "rwt_graph.types.wire": ("CdrError",),
    "rwt_protocol.server.access": (
        "AccessDeniedError",
        "AccessPolicy",
        "Family",
    ),
    "rwt_protocol.errors": (
        "CallTimeoutError",
        "ConfigError",
        "FieldError",
        "GraphError",
        "LimitError",
        "LocalProtocolError",
        "OpRefusedError",
        "ProtocolError",
        "RemoteProtocolError",
        "RwtError",
        "ServiceCallError",
        "TransportError",
    ),
    "rwt_protocol.levels": ("StatusLevel",),
    "rwt_protocol.framing.messages": ("MessageTooBigError",),
    "rwt_protocol.ops": ("ActionResult", "Auth"),
    "rwt_protocol.ports": ("GoalStatus",),
    "rwt_protocol.server.session": ("SessionConfig",),
    "rwt_ros2": (
        "Ros2Link",
        "Ros2Options",
        "Ros2Unavailable",
        "open_ros2_link",
    ),
    "rwt_graph.async_calls": (
        "GoalOutcome",
        "call_service",
        "send_action_goal",
    ),
    "rwt_cli.checks": ("ListenError",),
    "rwt_transports.memory": ("MemoryConnection",),
    "rwt_transports.server": (
        "RosbridgeServer",
        "ServerConfig",
        "rosauth_authenticator",
    ),
    "rwt_graph.tf.loop": ("install_tf_republisher",),
    "rwt_transports.udp": ("UdpOptions",),
    "rwt_transports.websocket": ("WebSocketOptions",),
    "rwt_zenoh.config": ("ZenohOptions",),
    "rwt_zenoh.link": (
        "ZenohLink",
        "open_zenoh_link",
    ),
    "rwt_zenoh.wire": ("RmwCompat", "WireError"),
}
_HOME_OF = {name: home for home, names in _HOMES.items() for name in names}

try:
    __version__ = version("rwt")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0+unknown"


def __getattr__(name: str) -> object:
    """Load a public name from its home module on first use, as ``rwt.<name>``.

    Raises:
        AttributeError: ``name`` is not part of the public API.
        ModuleNotFoundError: the name needs an extra (``pip install "rwt[server]"``,
            ``rwt[zenoh]``, ``rwt[ros2]``) that is not installed.
    """
    home = _HOME_OF.get(name)
    if home is None:
        raise AttributeError(f"module 'rwt' has no attribute {name!r}")
    importlib.import_module(home)
    _claim_loaded()
    return globals()[name]


def _claim_loaded() -> None:
    """Name ``rwt.<name>`` every public name whose home is loaded, used through rwt or not.

    An error raised before its name was ever looked up in ``rwt`` (a ``FieldError``
    from ``rwt.Graph``) then reads ``rwt.FieldError`` in its traceback too.
    """
    for home, names in _HOMES.items():
        module = sys.modules.get(home)
        if module is None:
            continue
        for name in names:
            if name in globals():
                continue
            value = getattr(module, name)
            if getattr(value, "__module__", "").startswith("rwt_"):
                value.__module__ = __name__
            globals()[name] = value


def __dir__() -> list[str]:
    return sorted(__all__)
