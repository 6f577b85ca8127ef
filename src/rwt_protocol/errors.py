"""The error tree of rwt.

``RwtError`` is the root of every error rwt raises on purpose; catching it
catches them all. Any other exception escaping rwt is a bug. Every class of the
tree is public, in ``rwt`` (``rwt.FieldError``) or in the namespace of its feature
(``rwt.tf.TFError``; docs/api.md says where each is), and
tests/api/test_error_tree.py checks that every exception class of every rwt
package is drawn here::

    RwtError
    ├── ProtocolError                     the rosbridge protocol was not followed
    │   ├── RemoteProtocolError           the peer's fault: becomes a status frame (D1)
    │   │   ├── LimitError                a per-connection cap (docs/limits.md)
    │   │   ├── MessageTooBigError        rwt_protocol.framing.messages: over --max-message-size
    │   │   ├── AccessDeniedError         rwt_protocol.runtime.access: a --*-glob rule
    │   │   ├── WireError                 rwt_zenoh.wire: not rmw_zenoh's wire form
    │   │   ├── FoxgloveInputError        rwt_foxglove.protocol: what a Foxglove client sent
    │   │   │                             cannot be used (an error status)
    │   │   ├── AssetError                rwt_foxglove.assets: a package:// URI not served
    │   │   ├── OfferError                rwt_transports.webrtc.offer: a WebRTC offer refused
    │   │   │                             before anything is built for it (HTTP 400, D38)
    │   │   ├── RouteError                rwt_http.routes: a request the HTTP API has no path or
    │   │   │                             method for, or a bad query (HTTP 404, 405, 400)
    │   │   └── CdrError                  rwt_graph.types.wire: bytes that are not the type's CDR
    │   └── LocalProtocolError            embedding code misused the API
    ├── GraphError                        the graph refused an operation
    │   ├── FieldError                    a value does not fit its type (D9)
    │   ├── UnknownNameError              no such service or action
    │   ├── DefinitionError               rwt_graph.types: a bad .msg/.srv/.action text
    │   ├── InvalidTypeNameError          rwt_graph.types: not a ROS type name
    │   ├── UnknownTypeError              rwt_graph.types: no such type
    │   ├── ParameterError                rwt_graph.parameters.store
    │   │   ├── ParameterNotSetError
    │   │   └── ParameterStoreFullError   no room: the store is full, or the node holds its share
    │   ├── ImageError                    rwt_graph.media: an image or depth cloud that cannot
    │   │                                 be read or encoded (also a ValueError)
    │   ├── EnvelopeError                 rwt_graph.safety.envelope: a command the safety
    │   │                                 envelope refused (out of bounds, not finite; D67)
    │   └── TFError                       rwt_graph.tf
    │       ├── UnknownFrameError         no such frame in the buffer
    │       ├── DisconnectedFramesError   the two frames are in different trees
    │       └── ExtrapolationError        the time is outside the buffered range
    ├── ConfigError                       an argument, option or setting that cannot be used
    │   │                                 (also a ValueError): a bad URL, a bad --zenoh-*
    │   │                                 option, a malformed secret file, RWT_NO_SHORTCUTS
    │   └── RulesError                    rwt_graph.safety.rules: safety rules that cannot be
    │                                     used, naming the file's line (D66)
    ├── ServiceCallError                  a call or goal answered ``result: false``
    │   └── CallTimeoutError              ... or not answered in time (also a TimeoutError)
    ├── OpRefusedError                    rwt_client: the server answered an op with an error status
    ├── GoalCanceledError                 rwt_graph.actions: an action handler honours a cancel
    ├── TransportError                    a transport failed (mapped at the boundary)
    │   ├── ConnectionClosedError         rwt_client.connectors: the connection is gone
    │   ├── ListenError                   rwt_transports: a listener cannot bind (also an OSError)
    │   └── SendTimeoutError              rwt_conformance: a server that does not read
    ├── VideoError                        rwt_video
    │   ├── StreamParamError              a query parameter that cannot be used (HTTP 4xx)
    │   └── EncodeError                   a frame that cannot be encoded (skipped)
    ├── BagError                          rwt_bag: a bag that cannot be read, written or played
    │   └── InflateError                  past a decompression bound (docs/limits.md)
    ├── Ros2Unavailable                   rwt_ros2: rclpy cannot be imported (also a RuntimeError)
    ├── InterfaceBuildError               rwt_ros2.interfaces: a package rclpy lacks cannot be
    │                                     built (also a RuntimeError)
    ├── SuiteError                        rwt_conformance: malformed suite data
    └── StepFailedError                   rwt_conformance: a step's expectation failed

Errors a peer caused carry the status level they are reported at; the session
turns them into ``status`` frames in one place (docs/decisions.md, D1).
"""

from __future__ import annotations

from .levels import StatusLevel

__all__ = [
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
    "UnknownNameError",
]


class RwtError(Exception):
    """Root of every error rwt raises on purpose.

    Args:
        message: lowercase text without a trailing period, shaped
            ``<what> (expected X, got Y) at <path>`` where that applies.
        level: the status level the error is reported at when it reaches a client.
    """

    def __init__(self, message: str, *, level: StatusLevel = StatusLevel.ERROR) -> None:
        super().__init__(message)
        self.message = message
        self.level = level


class ProtocolError(RwtError):
    """A violation of the rosbridge protocol."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something invalid; it becomes a ``status`` frame (D1)."""


class LimitError(RemoteProtocolError):
    """The op would take this connection over one of its caps (docs/limits.md)."""


class LocalProtocolError(ProtocolError):
    """Embedding code misused the API (for example sent an op in the wrong role)."""


class GraphError(RwtError):
    """The graph refused an operation: unknown type, type conflict, unknown topic..."""


class FieldError(GraphError):
    """A message value does not fit its type (D9).

    Args:
        path: JSON path of the offending value, ``$.msg.pose.position.x``.
        problem: what is wrong, ``expected float64, got str``.
    """

    def __init__(self, path: str, problem: str) -> None:
        super().__init__(f"{problem} at {path}")
        self.path = path
        self.problem = problem


class UnknownNameError(GraphError):
    """No service or action of that name in the graph.

    Args:
        kind: what was looked up, ``service`` or ``action``.
        name: the name as the caller gave it.
    """

    def __init__(self, kind: str, name: str) -> None:
        super().__init__(f"{kind} {name} does not exist")
        self.kind = kind
        self.name = name


class ConfigError(RwtError, ValueError):
    """An argument, option or setting that cannot be used; the text names it.

    Also a ``ValueError``, as the plain ``ValueError`` it replaces was.
    """


class TransportError(RwtError):
    """A transport failed; mapped from anyio/websockets errors at the boundary."""


class ServiceCallError(RwtError):
    """A service call or action goal failed: answered ``result: false`` (D4, D28).

    Args:
        message: what failed, ``call to /add_two_ints failed: ...``.
        values: the server's ``values`` (its error text, D28), if any.
    """

    def __init__(self, message: str, values: object = None) -> None:
        super().__init__(message)
        self.values = values


class CallTimeoutError(ServiceCallError, TimeoutError):
    """No answer came within the time allowed; the call or goal is forgotten."""


class OpRefusedError(RwtError):
    """The server refused an op this client sent: an ``error`` status for its id (spec 3.2.2).

    Raised by the client (``rwt_client``) for ops the protocol does not answer
    otherwise, such as ``advertise`` of a topic the server holds with another type.

    Args:
        op: the op refused, ``advertise``.
        op_id: its id.
        reason: the status text, ``advertise: /t is established with type ...``.
    """

    def __init__(self, op: str, op_id: str | int, reason: str) -> None:
        text = reason.removeprefix(f"{op}: ")
        super().__init__(f"the server refused {op} {op_id!r}: {text}")
        self.op = op
        self.op_id = op_id
        self.reason = reason
