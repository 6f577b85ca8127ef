"""Where each public name of ``rwt`` and its namespaces is defined, and loading it.

``rwt`` holds what most programs need; the rest is in namespaces that follow
the docs pages (``rwt.tf`` for docs/tf.md, ``rwt.bag`` for
docs/record-replay.md, ...). Every namespace module lists its names in
``__all__`` and loads each from its home on first use (PEP 562), so optional
extras (numpy, rosbags, zenoh, rclpy) load only with the names that need them.

``PUBLIC`` is the one table of homes; tests/api/test_public_api.py checks each
namespace's ``__all__`` against it.
"""

from __future__ import annotations

import importlib
import sys

__all__ = ["NAMESPACES", "PUBLIC", "load"]

#: public namespace -> home module -> the names it gives that namespace
PUBLIC: dict[str, dict[str, tuple[str, ...]]] = {
    "rwt": {
        "rwt_graph.graph": ("Graph",),
        "rwt_graph.clock": ("Clock",),
        "rwt_graph.local": (
            "LocalActionServer",
            "LocalPublisher",
            "LocalService",
            "LocalSubscription",
        ),
        "rwt_graph.actions": ("GoalCanceledError", "GoalContext"),
        "rwt_graph.async_calls": ("GoalOutcome", "call_service", "send_action_goal"),
        "rwt_protocol.ports": ("GoalStatus",),
        "rwt_transports.server": ("GraphServer", "RosbridgeServer", "ServerConfig"),
        "rwt_protocol.server.session": ("SessionConfig",),
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
        "rwt_protocol.errors": (
            "CallTimeoutError",
            "ConfigError",
            "FieldError",
            "GraphError",
            "OpRefusedError",
            "ProtocolError",
            "RwtError",
            "ServiceCallError",
            "TransportError",
        ),
        "rwt_client.connectors": ("ConnectionClosedError",),
        "rwt_transports.listen": ("ListenError",),
        "rwt_protocol.levels": ("StatusLevel",),
        "rwt_protocol.qos": ("QosProfile",),
    },
    "rwt.errors": {
        "rwt_protocol.errors": (
            "LimitError",
            "LocalProtocolError",
            "RemoteProtocolError",
            "UnknownNameError",
        ),
        "rwt_protocol.framing.messages": ("MessageTooBigError",),
        "rwt_graph.parameters.store": (
            "ParameterError",
            "ParameterNotSetError",
            "ParameterStoreFullError",
        ),
    },
    "rwt.types": {
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
        ),
        "rwt_graph.types.wire": ("CdrError",),
        "rwt_protocol.qos": ("Durability", "History", "Reliability"),
    },
    "rwt.client": {
        "rwt_protocol.ops": ("ActionResult",),
        "rwt_client.typed": ("MessageClass", "message_class"),
        "rwt_client.connectors": ("Connection",),
    },
    "rwt.server": {
        "rwt_transports.server": ("rosauth_authenticator",),
        "rwt_transports.host": ("Admitted",),
        "rwt_http.session": ("HttpApiOptions",),
        "rwt_protocol.auth": ("auth_query", "rosauth_op"),
        "rwt_transports.websocket": ("WebSocketOptions",),
        "rwt_transports.udp.transport": ("UdpOptions",),
        "rwt_transports.webrtc.signalling": ("WebRtcOptions",),
        "rwt_transports.http.mcp_options": ("McpOptions",),
        "rwt_transports.http.mcp_siblings": ("McpSiblings",),
        "rwt_transports.workers.placement": ("Placement",),
        "rwt_transports.memory": ("MemoryConnection",),
        "rwt_transports.process.allocator": ("tune_allocator",),
        "rwt_protocol.shortcuts": ("shortcut_report",),
        "rwt_protocol.runtime.access": (
            "AccessDeniedError",
            "AccessPolicy",
            "Family",
            "TopicUse",
        ),
        "rwt_protocol.ops": ("Auth",),
        "rwt_protocol.server.compat": ("Compat",),
        "rwt_transports.foxglove": ("FoxgloveOptions",),
        "rwt_foxglove.session": ("FoxgloveLimits",),
        "rwt_console.site": ("ConsoleSite",),
    },
    "rwt.tf": {
        "rwt_graph.tf": (
            "DisconnectedFramesError",
            "ExtrapolationError",
            "StampedTransform",
            "TFBuffer",
            "TFError",
            "TFRepublisher",
            "UnknownFrameError",
        ),
        "rwt_graph.tf.loop": ("install_tf_republisher",),
    },
    "rwt.media": {
        "rwt_graph.media": (
            "CameraIntrinsics",
            "DecodedDepthCloud",
            "ImageError",
            "decode_depthcloud",
            "encode_depthcloud",
            "points_from_depth",
        ),
        "rwt_graph.media.depthcloud_node": ("DepthCloudEncoder",),
    },
    "rwt.video": {
        "rwt_video": (
            "StreamType",
            "VideoConfig",
            "VideoTokens",
            "install_token_service",
            "serve_video",
        ),
    },
    "rwt.bag": {
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
        "rwt_bag.formats": ("ChunkCompression", "Compression"),
        "rwt_bag.info": ("TopicSummary",),
        "rwt_bag.selection": ("TopicSelection",),
        "rwt_graph.playback": ("PlaybackStatus",),
    },
    "rwt.zenoh": {
        "rwt_zenoh.config": ("ZenohOptions",),
        "rwt_zenoh.link": ("ZenohLink", "open_zenoh_link"),
        "rwt_zenoh.wire": ("RmwCompat", "WireError"),
    },
    "rwt.ros2": {
        "rwt_ros2": ("Ros2Link", "Ros2Options", "Ros2Unavailable", "open_ros2_link"),
        "rwt_ros2.runtime": ("ament_interface_dirs",),
    },
    "rwt.safety": {
        "rwt_graph.safety.rules": (
            "CallRule",
            "RulesError",
            "SafetyRules",
            "TopicRule",
            "load_rules",
            "parse_rules",
        ),
        "rwt_graph.safety.envelope": ("Envelope", "EnvelopeError"),
        "rwt_graph.safety.audit": ("AuditTrail", "SafetyEvent"),
    },
}
#: the namespaces below ``rwt``, as ``rwt.<name>``
NAMESPACES = tuple(space.removeprefix("rwt.") for space in PUBLIC if space != "rwt")
_HOME_OF = {
    (space, name): home
    for space, homes in PUBLIC.items()
    for home, names in homes.items()
    for name in names
}


def load(space: str, name: str) -> object:
    """``name`` of the namespace ``space`` (``rwt.tf``), from its home module.

    Every public name whose home is loaded is then named after its namespace
    (``__module__``), looked up or not: an error raised before its name was ever
    looked up (a ``FieldError`` from ``rwt.Graph``) reads ``rwt.FieldError`` in
    its traceback too, as names do in anyio and httpx.

    Raises:
        AttributeError: ``name`` is not in ``space``.
        ModuleNotFoundError: the name needs an extra (``pip install "rwt-rosbridge[server]"``,
            ``rwt-rosbridge[zenoh]``, ``rwt-rosbridge[ros2]``) that is not installed.
    """
    home = _HOME_OF.get((space, name))
    if home is None:
        raise AttributeError(f"module {space!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    _claim_loaded()
    return value


def _claim_loaded() -> None:
    """Name every public name whose home is loaded after its namespace."""
    for space, homes in PUBLIC.items():
        for home, names in homes.items():
            module = sys.modules.get(home)
            if module is None:
                continue
            for name in names:
                value = getattr(module, name)
                if getattr(value, "__module__", "").startswith("rwt_"):
                    value.__module__ = space
