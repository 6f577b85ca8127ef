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
that exists (as a node that allows undeclared parameters), not invent a node,
and a client may not create one on the server's nodes or another client's (D34).
A missing parameter without a ``default_value`` answers ``value: "null"`` with
``successful: false``, so clients that ignore ``successful`` (roslibpy) read None.

ROS 1 (``rosapi``): global names; the responses have no such fields, so a
refusal fails the call (``result: false``, D4). A missing parameter reads as
its ``default`` (``null`` when none), as rospy's ``get_param`` does; deleting
one that does not exist does nothing. ``get_param`` of a namespace answers at
most ``MAX_NAMESPACE_BYTES`` (``/`` is the whole tree).

What a client sets is charged to it (the caller rosapi is told of, not in-process
code: ``parameters.store.CLIENT_SHARE``). Values go out as the store holds them,
encoded once per answer (``values.json_text``), never copied.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import RemoteProtocolError

from ..calls import is_local
from ..parameters.values import ParameterError, ParamValue, json_text, value_size
from .listing import encodable

if TYPE_CHECKING:
    from collections.abc import Awaitable

    from rwt_protocol.ports import ClientId

    from ..graph import Graph
    from .visibility import Visibility

__all__ = ["MAX_NAMESPACE_BYTES", "ROS1_HANDLERS", "ROS2_HANDLERS"]

Message = dict[str, object]

MAX_NAMESPACE_BYTES = 4 * 1024 * 1024
"""Bytes of JSON text one ROS 1 ``get_param`` of a namespace answers at most.

A namespace holds many parameters (``/`` all of them: 10,000 of up to 64 MiB), and
a request of 60 bytes would otherwise be answered with all of them in one frame.
Past it the call fails with the reason (D4), which says to ask for what it holds by
name (docs/limits.md). A single parameter is answered whole: its size is bounded
where it is set (the client's and the store's shares, the message size)."""


def _client(vis: Visibility) -> ClientId | None:
    """The client to charge for what it sets: the caller, unless in-process code."""
    caller = vis.caller
    return None if caller is None or is_local(caller) else caller


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

    The store judges a client's new parameter (its node must exist, and be
    neither the server's nor another client's; the client's share: D34); an
    in-process caller is trusted as ``graph.params.set`` is. A parameter of a
    node that owns its parameters (another ROS 2 node, whose
    values here are copies: ``Parameters.own``) is set by that node: the answer
    waits for it and says what it said (a type change, a read-only parameter or
    its own validation refused).
    """
    try:
        name = _visible(vis, graph.params.key(str(request["name"])))
        value = _loads(request["value"], "set_param value")
        node, _, param = name.partition(":")
        owner = graph.params.owned_by(node)
        if owner is not None:
            return _set_by_node(owner(param, value))
        graph.params.set(name, value, client=_client(vis))
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
        return {"value": json_text(graph.params.get(name)), **_OK}
    except ParameterError as exc:
        if request["default_value"] != "":
            return {"value": json_text(_default(request["default_value"])), **_OK}
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
    graph.params.set(name, _loads(request["value"], "set_param value"), client=_client(vis))
    return {}


def ros1_get_param(graph: Graph, vis: Visibility, request: Message) -> Message:
    """``GetParam``: the value (a namespace as an object) or ``default``, as JSON text.

    Raises:
        ParameterError: a namespace whose text would be over ``MAX_NAMESPACE_BYTES``.
    """
    name = graph.params.key(str(request["name"]))
    if vis.param(name) and graph.params.has(name):
        value = graph.params.get(name)
        if not isinstance(value, Mapping):
            return {"value": json_text(value)}
        # the count of its values first: no text of gigabytes is made to be refused
        size = value_size(value)
        text = json_text(value) if size <= MAX_NAMESPACE_BYTES else None
        if (
            text is None
            or len(text) > MAX_NAMESPACE_BYTES
            or (not text.isascii() and len(text.encode()) > MAX_NAMESPACE_BYTES)
        ):
            raise ParameterError(
                f"the namespace {name} holds more than one answer carries "
                f"({MAX_NAMESPACE_BYTES} bytes of JSON): get the namespaces and "
                "parameters in it by name (get_param_names lists them)"
            )
        return {"value": text}
    return {"value": json_text(_default(request["default"]))}


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
