"""rosapi as in-process services of node ``/rosapi`` (REF §7.1, §7.2).

``install_rosapi(graph)`` offers every ``/rosapi/*`` service of the graph's
dialect: ROS 2 types ``rosapi_msgs/srv/<Name>`` (with ``get_ros_version`` and the
newer ``interfaces``, ``action_type`` and action detail services), or ROS 1
types ``rosapi/<Name>`` (with ``search_param`` and ``service_host``). Clients
reach them by any spelling (``rosapi/topics`` resolves to ``/rosapi/topics``).
The names of the other dialect's services are reserved too, so no client can
offer, say, a forged ``/rosapi/get_ros_version`` on a ROS 1 server
(docs/limits.md, reserved names).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from ..types import Dialect
from ..types.convert import time_keys, time_value
from . import listing
from .nodeparams import NodeParamServices
from .paramsrv import ROS1_HANDLERS, ROS2_HANDLERS
from .typedefs import typedefs
from .visibility import EVERYTHING, Visibility, VisibilityFor

if TYPE_CHECKING:
    from rwt_protocol.ports import ClientId

    from ..graph import Graph
    from ..local import LocalService
    from ..types import MessageType

__all__ = ["ROSAPI_NODE", "Rosapi", "install_rosapi", "rosapi_service_names"]

ROSAPI_NODE = "/rosapi"

Message = dict[str, object]
Handler = Callable[["Graph", Visibility, Message], "Message | Awaitable[Message]"]
"""A rosapi service: its answer, or an awaitable of it (``set_param`` on another node)."""


def _topics(graph: Graph, vis: Visibility, request: Message) -> Message:
    names, types = listing.topics(graph, vis)
    return {"topics": names, "types": types}


def _topics_and_raw_types(graph: Graph, vis: Visibility, request: Message) -> Message:
    names, types = listing.topics(graph, vis)
    texts = [graph.registry.message(type_name).full_text() for type_name in types]
    return {"topics": names, "types": types, "typedefs_full_text": texts}


def _node_details(graph: Graph, vis: Visibility, request: Message) -> Message:
    subscribing, publishing, services = listing.node_details(graph, vis, str(request["node"]))
    return {"subscribing": subscribing, "publishing": publishing, "services": services}


def _details(pick: Callable[[Graph, str], MessageType]) -> Handler:
    def handler(graph: Graph, vis: Visibility, request: Message) -> Message:
        return {"typedefs": typedefs(pick(graph, str(request["type"])), graph.registry.message)}

    return handler


def _interfaces(graph: Graph, vis: Visibility, request: Message) -> Message:
    registry = graph.registry
    names = registry.message_names() + registry.service_names() + registry.action_names()
    return {"interfaces": sorted(names)}


def _get_time(graph: Graph, vis: Visibility, request: Message) -> Message:
    return {"time": time_value(graph.clock.wall(), graph.registry.dialect)}


def _both_time_spellings(response: Message) -> Message:
    """Add ``secs``/``nsecs`` to a ROS 2 time: roslibpy reads only those (REF §7.2)."""
    stamp = response["time"]
    if isinstance(stamp, dict):
        sec_key, nsec_key = time_keys(Dialect.ROS2)
        response["time"] = {**stamp, "secs": stamp[sec_key], "nsecs": stamp[nsec_key]}
    return response


def _common() -> dict[str, Handler]:
    """The services both dialects have, by short name."""
    return {
        "topics": _topics,
        "topics_for_type": lambda g, v, r: {
            "topics": listing.topics_for_type(g, v, str(r["type"]))
        },
        "topics_and_raw_types": _topics_and_raw_types,
        "services": lambda g, v, r: {"services": listing.services(g, v)},
        "services_for_type": lambda g, v, r: {
            "services": listing.services_for_type(g, v, str(r["type"]))
        },
        "nodes": lambda g, v, r: {"nodes": listing.node_names(g)},
        "node_details": _node_details,
        "action_servers": lambda g, v, r: {"action_servers": listing.action_servers(g, v)},
        "topic_type": lambda g, v, r: {"type": listing.topic_type(g, v, str(r["topic"]))},
        "service_type": lambda g, v, r: {"type": listing.service_type(g, v, str(r["service"]))},
        "publishers": lambda g, v, r: {"publishers": listing.publishers(g, v, str(r["topic"]))},
        "subscribers": lambda g, v, r: {"subscribers": listing.subscribers(g, v, str(r["topic"]))},
        "service_providers": lambda g, v, r: {
            "providers": listing.service_providers(g, v, str(r["service"]))
        },
        "service_node": lambda g, v, r: {"node": listing.service_node(g, v, str(r["service"]))},
        "message_details": _details(lambda g, t: g.registry.message(t)),
        "service_request_details": _details(lambda g, t: g.registry.service(t).request),
        "service_response_details": _details(lambda g, t: g.registry.service(t).response),
        "get_time": _get_time,
    }


def _ros2(distro: str | None) -> dict[str, Handler]:
    return {
        **_common(),
        **ROS2_HANDLERS,
        "get_ros_version": lambda g, v, r: {"version": 2, "distro": distro or g.ros_distro},
        "interfaces": _interfaces,
        "action_type": lambda g, v, r: {"type": listing.action_type(g, v, str(r["action"]))},
        "action_goal_details": _details(lambda g, t: g.registry.action(t).goal),
        "action_result_details": _details(lambda g, t: g.registry.action(t).result),
        "action_feedback_details": _details(lambda g, t: g.registry.action(t).feedback),
    }


def _ros1() -> dict[str, Handler]:
    return {
        **_common(),
        **ROS1_HANDLERS,
        "service_host": lambda g, v, r: {"host": listing.service_host(g, v, str(r["service"]))},
    }


#: The type of each service, by short name, where it is not the short name in CamelCase.
_TYPES = {
    "action_servers": "GetActionServers",
    "get_ros_version": "GetROSVersion",
}


def _type_short(service: str) -> str:
    return _TYPES.get(service) or "".join(part.capitalize() for part in service.split("_"))


def rosapi_service_names() -> frozenset[str]:
    """Every ``/rosapi/*`` service name of either dialect (resolved names)."""
    return frozenset(f"/rosapi/{short}" for short in {**_ros1(), **_ros2("")})


@dataclass
class Rosapi:
    """The installed rosapi services; ``close()`` withdraws them all.

    ``reserved`` holds the names of the other dialect's rosapi services, kept
    from clients while rosapi is installed.
    """

    services: list[LocalService] = field(default_factory=list)
    reserved: set[str] = field(default_factory=set)
    graph: Graph | None = None
    node_params: NodeParamServices | None = None

    def close(self) -> None:
        """Withdraw every rosapi service (pending calls have already been answered)."""
        if self.node_params is not None:
            self.node_params.close()
            self.node_params = None
        for service in self.services:
            service.close()
        self.services.clear()
        if self.graph is not None:
            self.graph.services.reserved -= self.reserved
        self.reserved.clear()


def install_rosapi(
    graph: Graph, *, visibility: VisibilityFor | None = None, distro: str | None = None
) -> Rosapi:
    """Offer the rosapi services of ``graph``'s dialect, provided by node ``/rosapi``.

    In ROS 2, each node with parameters in the store also answers its own
    parameter services (``nodeparams``), as ROS 2 tools expect.

    Args:
        graph: the graph to describe and whose parameters to serve.
        visibility: gives each calling client the names it may see (access rules);
            None shows everything to everyone.
        distro: the ROS 2 distribution ``get_ros_version`` reports; None reports
            the graph's at the time of each call (``Graph.ros_distro``: the running
            ROS's once a link to it is open, ``jazzy`` before).

    Returns:
        A handle whose ``close()`` withdraws the services.
    """
    ros1 = graph.registry.dialect is Dialect.ROS1
    table = _ros1() if ros1 else _ros2(distro)
    package = "rosapi" if ros1 else "rosapi_msgs/srv"
    rosapi = Rosapi(graph=graph)
    rosapi.reserved = set(rosapi_service_names().difference(f"/rosapi/{s}" for s in table))
    graph.services.reserved |= rosapi.reserved
    for short, handler in table.items():
        rosapi.services.append(
            graph.create_caller_service(
                f"/rosapi/{short}",
                f"{package}/{_type_short(short)}",
                _bound(graph, handler, visibility),
                node=ROSAPI_NODE,
                amend=_both_time_spellings if short == "get_time" and not ros1 else None,
            )
        )
    if not ros1:  # each node's own parameter services, as ROS 2 tools call them
        rosapi.node_params = NodeParamServices(graph, visibility)
    return rosapi


def _bound(
    graph: Graph, handler: Handler, visibility: VisibilityFor | None
) -> Callable[[ClientId, Message], Message | Awaitable[Message]]:
    def serve(caller: ClientId, request: Message) -> Message | Awaitable[Message]:
        vis = EVERYTHING if visibility is None else visibility(caller)
        return handler(graph, replace(vis, caller=caller), request)

    return serve
