"""rosapi helpers (spec 4.1, REF §7.1-7.2), as roslibpy names them.

Each is one ``call_service`` to ``/rosapi/<name>``; the shapes are rosbridge
ROS 2's (``pkg/msg/Type``, ``sec``/``nanosec``). A server without rosapi makes
them fail with ``ServiceCallError`` or ``CallTimeoutError``.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Protocol

from rwt_protocol.codecs.json import decode_json_text
from rwt_protocol.errors import ServiceCallError

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["RosapiMixin"]


class _Caller(Protocol):
    async def call_service(
        self,
        service: str,
        args: object = None,
        *,
        type_name: str | None = None,
        timeout_s: float | None = None,
    ) -> object: ...


async def _rosapi(
    ros: _Caller, name: str, args: Mapping[str, object] | None = None
) -> dict[str, object]:
    values = await ros.call_service(f"/rosapi/{name}", args or {})
    return values if isinstance(values, dict) else {}


def _succeeded(values: dict[str, object], what: str) -> None:
    """Raise ``ServiceCallError`` for a ROS 2 rosapi answer saying ``successful: false``."""
    if values.get("successful") is False:
        reason = values.get("reason") or "no reason given"
        raise ServiceCallError(f"{what} refused by the server: {reason}", values)


def _strings(values: dict[str, object], key: str) -> list[str]:
    items = values.get(key)
    return [str(item) for item in items] if isinstance(items, list) else []


class RosapiMixin:
    """rosapi queries for ``Ros``."""

    async def get_topics(self: _Caller) -> list[str]:
        """Names of every topic (``/rosapi/topics``)."""
        return _strings(await _rosapi(self, "topics"), "topics")

    async def get_topics_and_types(self: _Caller) -> dict[str, str]:
        """Topic name -> type (``/rosapi/topics``)."""
        values = await _rosapi(self, "topics")
        return dict(zip(_strings(values, "topics"), _strings(values, "types"), strict=False))

    async def get_topic_type(self: _Caller, topic: str) -> str:
        """The type of ``topic``, "" when unknown (``/rosapi/topic_type``)."""
        return str((await _rosapi(self, "topic_type", {"topic": topic})).get("type", ""))

    async def get_topics_for_type(self: _Caller, type_name: str) -> list[str]:
        """Topics of one type (``/rosapi/topics_for_type``)."""
        return _strings(await _rosapi(self, "topics_for_type", {"type": type_name}), "topics")

    async def get_services(self: _Caller) -> list[str]:
        """Names of every service (``/rosapi/services``)."""
        return _strings(await _rosapi(self, "services"), "services")

    async def get_service_type(self: _Caller, service: str) -> str:
        """The type of ``service`` (``/rosapi/service_type``)."""
        return str((await _rosapi(self, "service_type", {"service": service})).get("type", ""))

    async def get_nodes(self: _Caller) -> list[str]:
        """Node names (``/rosapi/nodes``)."""
        return _strings(await _rosapi(self, "nodes"), "nodes")

    async def get_node_details(self: _Caller, node: str) -> dict[str, object]:
        """subscribing, publishing, services of a node (``/rosapi/node_details``)."""
        return await _rosapi(self, "node_details", {"node": node})

    async def get_action_servers(self: _Caller) -> list[str]:
        """Action server names (``/rosapi/action_servers``)."""
        return _strings(await _rosapi(self, "action_servers"), "action_servers")

    async def get_message_details(self: _Caller, type_name: str) -> list[dict[str, object]]:
        """Type definitions of a message type, root first (``/rosapi/message_details``)."""
        typedefs = (await _rosapi(self, "message_details", {"type": type_name})).get("typedefs")
        return [t for t in typedefs if isinstance(t, dict)] if isinstance(typedefs, list) else []

    async def get_params(self: _Caller) -> list[str]:
        """Parameter names (``/rosapi/get_param_names``)."""
        return _strings(await _rosapi(self, "get_param_names"), "names")

    async def get_param(self: _Caller, name: str, default: object = None) -> object:
        """A parameter's value, decoded from its JSON text (``/rosapi/get_param``).

        Raises:
            RemoteProtocolError: the server's text breaks the rules of JSON text
                in values (``rwt_protocol.codecs.json.decode_json_text``).
        """
        args = {"name": name, "default_value": "" if default is None else json.dumps(default)}
        text = (await _rosapi(self, "get_param", args)).get("value", "")
        if not isinstance(text, str) or not text:
            return default
        return decode_json_text(text, "get_param value")

    async def set_param(self: _Caller, name: str, value: object) -> None:
        """Set a parameter to ``value`` (sent as JSON text, ``/rosapi/set_param``).

        Raises:
            ServiceCallError: the server refused it: the call failed (ROS 1), or
                answered ``successful: false`` (ROS 2; roslibjs calls its failure
                callback then): the text carries the server's ``reason``.
        """
        args = {"name": name, "value": json.dumps(value)}
        _succeeded(await _rosapi(self, "set_param", args), f"set_param {name}")

    async def delete_param(self: _Caller, name: str) -> None:
        """Delete a parameter (``/rosapi/delete_param``).

        Raises:
            ServiceCallError: refused, as ``set_param``.
        """
        _succeeded(await _rosapi(self, "delete_param", {"name": name}), f"delete_param {name}")

    async def get_time(self: _Caller) -> float:
        """The server's time in seconds (``/rosapi/get_time``; ROS 1 or ROS 2 shape)."""
        time = (await _rosapi(self, "get_time")).get("time", {})
        if not isinstance(time, dict):
            return 0.0
        sec = time.get("sec", time.get("secs", 0))
        nanosec = time.get("nanosec", time.get("nsecs", 0))
        return float(sec) + float(nanosec) / 1e9  # type: ignore[arg-type]
