"""The parameter services of rosapi (REF §7.1 set/get/has/delete_param, get_param_names).

Values travel as JSON text both ways (roslibjs and roslibpy send
``JSON.stringify(value)`` and parse the reply's ``value``). A client's text is
decoded by ``rwt_protocol.codecs.json.decode_json_text``, under the rules of frames
(no lone surrogate, at most 100 levels, 64-bit integers; docs/limits.md), so a
value every other client reads back, and the Zenoh link shares, can always be
encoded again.

ROS 2 (``rosapi_msgs``): names are ``"<node>:<param>"``; a refusal is an answer
with ``successful: false`` and a ``reason`` (roslibjs then calls the failure
callback), never a failed call. ``set_param`` may create a parameter on a node
that exists (as a node that allows undeclared parameters), not invent a node.
A missing parameter without a ``default_value`` answers ``value: "null"`` with
``successful: false``, so clients that ignore ``successful`` (roslibpy) read None.

ROS 1 (``rosapi``): global names; the responses have no such fields, so a
refusal fails the call (``result: false``, D4). A missing parameter reads as
its ``default`` (``null`` when none), as rospy's ``get_param`` does; deleting
one that does not exist does nothing.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import RemoteProtocolError

from ..parameters.store import ParameterError, ParamValue, to_json_safe
from .listing import encodable, node_names

if TYPE_CHECKING:
    from collections.abc import Awaitable

    from ..graph import Graph
    from .visibility import Visibility

__all__ = ["ROS1_HANDLERS", "ROS2_HANDLERS"]

Message = dict[str, object]


def _dumps(value: object) -> str:
    return json.dumps(to_json_safe(value), ensure_ascii=False)  # type: ignore[arg-type]


def _loads(text: object, what: str) -> ParamValue:
    """The value of a client's JSON text.

    Raises:
        ParameterError: the text breaks the rules of ``decode_json_text``.
    """
    try:
        return decode_json_text(str(text), what)  # type: ignore[return-value]
    except RemoteProtocolError as exc:
        raise ParameterError(exc.message) from None


def _default(text: object) -> object:
    """A ``default_value``/``default``: JSON if it decodes, else the text itself (as rosapi).

    Text that does not decode under the rules (a lone surrogate, deep nesting) is
    also taken as the string it is: a valid string, answered as it came.
    """
    if text == "":
        return None
    try:
        return decode_json_text(str(text), "default")
    except RemoteProtocolError:
        return text


def _visible(vis: Visibility, name: str) -> str:
    if not vis.param(name):
        raise ParameterError(f"parameter {name} is not accessible")
    return name


def _refused(exc: ParameterError) -> Message:
    return {"successful": False, "reason": exc.message}


_OK: Message = {"successful": True, "reason": ""}

# ---- ROS 2 ------------------------------------------------------------------------


def ros2_set_param(graph: Graph, vis: Visibility, request: Message) -> Message | Awaitable[Message]:
    """``SetParam``: set ``name`` to the JSON ``value``.

    A parameter of a node that owns its parameters (another ROS 2 node, whose
    values here are copies: ``Parameters.own``) is set by that node: the answer
    waits for it and says what it said (a type change, a read-only parameter or
    its own validation refused).
    """
    try:
        name = _visible(vis, graph.params.key(str(request["name"])))
        value = _loads(request["value"], "set_param value")
        node, _, param = name.partition(":")
        if node not in node_names(graph):
            raise ParameterError(f"node {node} does not exist")
        owner = graph.params.owned_by(node)
        if owner is not None:
            return _set_by_node(owner(param, value))
        graph.params.set(name, value)
    except ParameterError as exc:
        return _refused(exc)
    return dict(_OK)


async def _set_by_node(answer: Awaitable[tuple[bool, str]]) -> Message:
    successful, reason = await answer
    return {"successful": successful, "reason": reason}


def ros2_get_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``GetParam``: the value as JSON text, or ``default_value`` when it is not set."""
    try:
        name = _visible(vis, graph.params.key(str(request["name"])))
        return {"value": _dumps(graph.params.get(name)), **_OK}
    except ParameterError as exc:
        if request["default_value"] != "":
            return {"value": _dumps(_default(request["default_value"])), **_OK}
        return {"value": "null", **_refused(exc)}


def ros2_has_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``HasParam``: whether ``name`` is set (false for a malformed name)."""
    try:
        name = graph.params.key(str(request["name"]))
    except ParameterError:
        return {"exists": False}
    return {"exists": vis.param(name) and graph.params.has(name)}


def ros2_delete_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``DeleteParam``: remove ``name``."""
    try:
        graph.params.delete(_visible(vis, graph.params.key(str(request["name"]))))
    except ParameterError as exc:
        return _refused(exc)
    return dict(_OK)


def get_param_names(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``GetParamNames``: every visible parameter name."""
    return {"names": [name for name in graph.params.names() if vis.param(name) and encodable(name)]}


# ---- ROS 1 ------------------------------------------------------------------------


def ros1_set_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``SetParam``: set the global ``name`` to the JSON ``value``.

    Raises:
        ParameterError: bad JSON, a hidden name, or a value the store refuses.
    """
    name = _visible(vis, graph.params.key(str(request["name"])))
    graph.params.set(name, _loads(request["value"], "set_param value"))
    return {}


def ros1_get_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``GetParam``: the value (a namespace as an object) or ``default``, as JSON text."""
    name = graph.params.key(str(request["name"]))
    if vis.param(name) and graph.params.has(name):
        return {"value": _dumps(graph.params.get(name))}
    return {"value": _dumps(_default(request["default"]))}


def ros1_has_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``HasParam``: whether the parameter or namespace exists."""
    name = graph.params.key(str(request["name"]))
    return {"exists": vis.param(name) and graph.params.has(name)}


def ros1_delete_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``DeleteParam``: remove a parameter or namespace; nothing if it does not exist.

    Raises:
        ParameterError: a hidden name.
    """
    name = _visible(vis, graph.params.key(str(request["name"])))
    if graph.params.has(name):
        graph.params.delete(name)
    return {}


def ros1_search_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``SearchParam``: the global name of ``name`` from the root namespace, ``""`` if unset."""
    found = graph.params.search(str(request["name"]))
    return {"global_name": found if found and vis.param(found) else ""}


ROS2_HANDLERS = {
    "set_param": ros2_set_param,
    "get_param": ros2_get_param,
    "has_param": ros2_has_param,
    "delete_param": ros2_delete_param,
    "get_param_names": get_param_names,
}
ROS1_HANDLERS = {
    "set_param": ros1_set_param,
    "get_param": ros1_get_param,
    "has_param": ros1_has_param,
    "delete_param": ros1_delete_param,
    "get_param_names": get_param_names,
    "search_param": ros1_search_param,
}
