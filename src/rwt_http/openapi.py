"""The OpenAPI 3.1 document of the live graph (``GET /openapi.json``, docs/http.md).

Made at each request from the graph's change feed, so it lists what is there now:
each topic a client may see (``rwt_graph.visibility``, the access rules) gets its
paths (``GET`` its latest message, ``POST`` a message, ``GET .../events`` its
stream), each service its ``POST``, each action its ``POST`` (a stream of
feedback and the result). Every message type is one schema under
``components/schemas`` (JSON Schema 2020-12, the dialect of OpenAPI 3.1), named
``pkg.Type`` and made by the same rule as the MCP tools' (``rwt_graph.types.jsonschema``
over rosapi's type definitions, ``rwt_graph.rosapi.typedefs``): a ``uint8[]`` is
base64 text or a list of 0-255, as rosbridge's JSON has it.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

from rwt_graph.feed import EntityKind
from rwt_graph.rosapi.typedefs import typedef_name, typedefs
from rwt_graph.types.jsonschema import json_schema

if TYPE_CHECKING:
    from rwt_graph.port import GraphFront
    from rwt_graph.types import MessageType
    from rwt_graph.visibility import Visibility

__all__ = ["openapi_document"]

_UNSAFE = re.compile(r"[^A-Za-z0-9_]")
_ERROR = {
    "description": "refused (400 bad input, 401 no or a wrong bearer token, 403 the access "
    "rules, 404 unknown, 502 the provider failed, 504 no answer in time)",
    "content": {
        "application/json": {
            "schema": {
                "type": "object",
                "properties": {"error": {"type": "string"}},
                "required": ["error"],
            }
        }
    },
}


def openapi_document(graph: GraphFront, visibility: Visibility, version: str) -> dict[str, object]:
    """The document for a client who sees ``visibility`` of ``graph``.

    Args:
        graph: the served graph (its feed for the entities, its registry for the types).
        visibility: what the client may see (``Visibility.of`` the access rules).
        version: the server's version, for ``info.version``.
    """
    schemas: dict[str, object] = {}
    paths: dict[str, object] = {"/api/topics": {"get": _listing()}}
    _, entities = graph.feed.snapshot()
    seen: set[tuple[EntityKind, str]] = set()
    for change in sorted(entities, key=lambda c: (c.kind, c.name)):
        key = (change.kind, change.name)
        if key in seen or not visibility.sees(change):
            continue
        seen.add(key)
        if change.kind in (EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION):
            ref = _message_schema(graph, graph.registry.message(change.type_name), schemas)
            paths.update(_topic_paths(change.name, change.type_name, ref))
        elif change.kind is EntityKind.SERVICE:
            service = graph.registry.service(change.type_name)
            request = _message_schema(graph, service.request, schemas)
            answer = _message_schema(graph, service.response, schemas)
            paths[f"/api/services{change.name}"] = {
                "post": _service(change.name, service.name, request, answer)
            }
        elif change.kind is EntityKind.ACTION:
            action = graph.registry.action(change.type_name)
            goal = _message_schema(graph, action.goal, schemas)
            _message_schema(graph, action.feedback, schemas)
            _message_schema(graph, action.result, schemas)
            paths[f"/api/actions{change.name}"] = {"post": _action(change.name, action.name, goal)}
    return {
        "openapi": "3.1.0",
        "info": {
            "title": "rwt HTTP API",
            "version": version,
            "description": "The ROS graph over HTTP and Server-Sent Events (docs/http.md).",
        },
        "components": {
            "schemas": schemas,
            "securitySchemes": {"bearer": {"type": "http", "scheme": "bearer"}},
        },
        "paths": paths,
    }


def _key(type_name: str) -> str:
    """A type's schema name: ``std_msgs/msg/String`` -> ``std_msgs.String``."""
    return typedef_name(type_name).replace("/", ".")


def _message_schema(graph: GraphFront, mtype: MessageType, schemas: dict[str, object]) -> object:
    """A ``$ref`` to ``mtype``'s schema, adding it and its nested types to ``schemas``."""
    key = _key(mtype.name)
    if key not in schemas:
        schema = json_schema([dict(d) for d in typedefs(mtype, graph.registry.message)])
        for name, nested in dict(schema.get("$defs", {})).items():  # type: ignore[call-overload]
            schemas.setdefault(name.replace("/", "."), _components_refs(nested))
    return {"$ref": f"#/components/schemas/{key}"}


def _components_refs(value: object) -> object:
    """``value`` with its ``#/$defs/pkg~1Type`` references as ``#/components/schemas/pkg.Type``."""
    if isinstance(value, dict):
        out: dict[str, object] = {}
        for k, v in value.items():
            if k == "$ref" and isinstance(v, str) and v.startswith("#/$defs/"):
                name = v.removeprefix("#/$defs/").replace("~1", "/").replace("~0", "~")
                out[k] = f"#/components/schemas/{name.replace('/', '.')}"
            else:
                out[k] = _components_refs(v)
        return out
    if isinstance(value, list):
        return [_components_refs(v) for v in value]
    return value


def _op_id(verb: str, name: str) -> str:
    return verb + _UNSAFE.sub("_", name)


def _json(schema: object) -> dict[str, object]:
    return {"application/json": {"schema": schema}}


def _listing() -> dict[str, object]:
    item = {"type": "array", "items": {"type": "string"}}
    listing = {"type": "object", "properties": {"topics": item, "types": item}}
    return {
        "operationId": "list_topics",
        "summary": "The topics a client may see and their types (as rosapi's /rosapi/topics)",
        "responses": {"200": {"description": "the topics", "content": _json(listing)}},
    }


_STREAM_PARAMETERS = [
    {
        "name": name,
        "in": "query",
        "required": False,
        "description": text,
        "schema": {"type": "integer", "minimum": 0},
    }
    for name, text in (
        ("throttle_rate", "at least this many ms between two messages (rosbridge's)"),
        ("queue_length", "at most this many messages wait for a slow reader (rosbridge's)"),
    )
]


def _topic_paths(name: str, type_name: str, ref: object) -> dict[str, object]:
    type_parameter = {
        "name": "type",
        "in": "query",
        "required": False,
        "schema": {"type": "string", "default": type_name},
    }
    stream = {"text/event-stream": {"schema": {"type": "string"}, "x-rwt-data": ref}}
    return {
        f"/api/topics{name}": {
            "get": {
                "operationId": _op_id("get", name),
                "summary": f"The latest message of {name} ({type_name})",
                "responses": {
                    "200": {"description": "the message", "content": _json(ref)},
                    "default": _ERROR,
                },
            },
            "post": {
                "operationId": _op_id("publish", name),
                "summary": f"Publish a message on {name} ({type_name})",
                "parameters": [type_parameter],
                "requestBody": {"required": True, "content": _json(ref)},
                "responses": {
                    "200": {"description": "published", "content": _json({"type": "object"})},
                    "default": _ERROR,
                },
            },
        },
        f"/api/topics{name}/events": {
            "get": {
                "operationId": _op_id("stream", name),
                "summary": f"The messages of {name} as Server-Sent Events (one JSON each)",
                "parameters": _STREAM_PARAMETERS,
                "responses": {
                    "200": {"description": "the stream", "content": stream},
                    "default": _ERROR,
                },
            }
        },
    }


def _service(name: str, type_name: str, request: object, answer: object) -> dict[str, object]:
    return {
        "operationId": _op_id("call", name),
        "summary": f"Call {name} ({type_name})",
        "requestBody": {"required": False, "content": _json(request)},
        "responses": {
            "200": {"description": "the response", "content": _json(answer)},
            "default": _ERROR,
        },
    }


def _action(name: str, type_name: str, goal: object) -> dict[str, object]:
    stream = {"text/event-stream": {"schema": {"type": "string"}}}
    return {
        "operationId": _op_id("goal", name),
        "summary": f"Send a goal to {name} ({type_name}): its feedback and result as events",
        "requestBody": {"required": True, "content": _json(goal)},
        "responses": {
            "200": {"description": "feedback events, then one result event", "content": stream},
            "default": _ERROR,
        },
    }
