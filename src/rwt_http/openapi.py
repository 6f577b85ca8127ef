"""The OpenAPI 3.1 document of the live graph (``GET /openapi.json``, docs/http.md): its parts.

Each topic a client may see (``rwt_graph.visibility``, the access rules) gets its
paths: ``GET`` its latest message and ``GET .../events`` its stream where the rules
let the client subscribe to it, ``POST`` a message where they let it publish
(``--topics-sub-glob`` and ``--topics-pub-glob``, D50), so the document offers no
operation the server would refuse with 403. Each service gets its ``POST``, each
action its ``POST`` (a stream of feedback and the result). Every message type is
one schema under ``components/schemas`` (JSON Schema 2020-12, the dialect of
OpenAPI 3.1), named ``pkg.Type`` and made by the same rule as the MCP tools'
(``rwt_graph.types.jsonschema`` over rosapi's type definitions,
``rwt_graph.rosapi.typedefs``): a ``uint8[]`` is base64 text or a list of 0-255,
as rosbridge's JSON has it.

The document is made in slices and cached (``document``); this module makes one
entity's paths (``paths_of``) and the text around them (``document_prefix``,
``document_suffix``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rwt_graph.rosapi.typedefs import typedef_name, typedefs
from rwt_graph.types.jsonschema import json_schema
from rwt_protocol.codecs.json import encode_json
from rwt_protocol.runtime.access import Family

from .routes import EVENTS_SUFFIX

if TYPE_CHECKING:
    from rwt_graph.port import GraphFront
    from rwt_graph.types import MessageType

__all__ = ["Entry", "document_prefix", "document_suffix", "listing_path", "paths_of"]

_UNSAFE = re.compile(r"[^A-Za-z0-9_]")
_ERROR = {
    "description": "refused (400 bad input, 401 no or a wrong bearer token, 403 the access "
    "rules, 404 unknown, 502 the provider failed, 503 the server or this host's share of it "
    "is full, 504 no answer in time)",
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


@dataclass(frozen=True, slots=True)
class Entry:
    """One topic, service or action of the document, as a client under its rules sees it.

    Attributes:
        family: ``Family.TOPICS``, ``SERVICES`` or ``ACTIONS``.
        name: the resolved name (``/robot/odom``).
        type_name: its type (``nav_msgs/msg/Odometry``).
        read: a topic the rules let the client subscribe to: its ``GET`` and stream.
        write: a topic the rules let the client publish on: its ``POST``.
    """

    family: Family
    name: str
    type_name: str
    read: bool = True
    write: bool = True


def document_prefix(version: str) -> bytes:
    """The document's text before its paths: ``{"openapi":...,"info":...,"paths":{``.

    Args:
        version: the server's version, for ``info.version``.
    """
    info = {
        "title": "rwt HTTP API",
        "version": version,
        "description": "The ROS graph over HTTP and Server-Sent Events (docs/http.md).",
    }
    return b'{"openapi":"3.1.0","info":' + encode_json(info) + b',"paths":{'


def document_suffix(schemas: dict[str, object]) -> bytes:
    """The document's text after its paths: the components with ``schemas``, and the end."""
    components = {
        "schemas": schemas,
        "securitySchemes": {"bearer": {"type": "http", "scheme": "bearer"}},
    }
    return b'},"components":' + encode_json(components) + b"}"


def listing_path() -> dict[str, object]:
    """The path of ``GET /api/topics``, first in every document."""
    return {"/api/topics": {"get": _listing()}}


def paths_of(graph: GraphFront, entry: Entry, schemas: dict[str, object]) -> dict[str, object]:
    """The path items of ``entry``, its message types added to ``schemas``.

    A topic whose name ends in ``/events`` has no path of its own: that path is
    the stream of the topic before it (``routes``), so only its stream is listed.

    Raises:
        GraphError: a type the graph's registry cannot resolve.
    """
    if entry.family is Family.TOPICS:
        ref = _message_schema(graph, graph.registry.message(entry.type_name), schemas)
        return _topic_paths(entry, ref)
    if entry.family is Family.SERVICES:
        service = graph.registry.service(entry.type_name)
        request = _message_schema(graph, service.request, schemas)
        answer = _message_schema(graph, service.response, schemas)
        return {
            f"/api/services{entry.name}": {
                "post": _service(entry.name, service.name, request, answer)
            }
        }
    action = graph.registry.action(entry.type_name)
    goal = _message_schema(graph, action.goal, schemas)
    _message_schema(graph, action.feedback, schemas)
    _message_schema(graph, action.result, schemas)
    return {f"/api/actions{entry.name}": {"post": _action(entry.name, action.name, goal)}}


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

_DURATION: dict[str, object] = {"oneOf": [{"type": "number", "minimum": 0}, {"type": "string"}]}
_QOS_PARAMETERS: list[dict[str, object]] = [
    {
        "name": name,
        "in": "query",
        "required": False,
        "description": f"protocol 2.1.0's qos.{name} (docs/http.md, D62)",
        "schema": schema,
    }
    for name, schema in (
        ("history", {"type": "string", "enum": ["keep_last", "keep_all"]}),
        ("depth", {"type": "integer", "minimum": 0}),
        ("reliability", {"type": "string", "enum": ["reliable", "best_effort", "best_available"]}),
        (
            "durability",
            {"type": "string", "enum": ["transient_local", "volatile", "best_available"]},
        ),
        ("deadline", _DURATION),
        ("lifespan", _DURATION),
    )
]
"""Protocol 2.1.0's ``qos``, one query parameter a policy (``routes._qos``)."""

_STREAM_PARAMETERS += _QOS_PARAMETERS


def _topic_paths(entry: Entry, ref: object) -> dict[str, object]:
    """The paths of a topic: its own (GET, POST) and its stream's, as the rules allow."""
    name, type_name = entry.name, entry.type_name
    own: dict[str, object] = {}
    paths: dict[str, object] = {}
    if entry.read:
        own["get"] = {
            "operationId": _op_id("get", name),
            "summary": f"The latest message of {name} ({type_name})",
            "responses": {
                "200": {"description": "the message", "content": _json(ref)},
                "default": _ERROR,
            },
        }
    if entry.write:
        type_parameter = {
            "name": "type",
            "in": "query",
            "required": False,
            "schema": {"type": "string", "default": type_name},
        }
        own["post"] = {
            "operationId": _op_id("publish", name),
            "summary": f"Publish a message on {name} ({type_name})",
            "parameters": [type_parameter, *_QOS_PARAMETERS],
            "requestBody": {"required": True, "content": _json(ref)},
            "responses": {
                "200": {"description": "published", "content": _json({"type": "object"})},
                "default": _ERROR,
            },
        }
    if own and not (name.endswith(EVENTS_SUFFIX) and name != EVENTS_SUFFIX):
        paths[f"/api/topics{name}"] = own
    if entry.read:
        stream = {"text/event-stream": {"schema": {"type": "string"}, "x-rwt-data": ref}}
        paths[f"/api/topics{name}{EVENTS_SUFFIX}"] = {
            "get": {
                "operationId": _op_id("stream", name),
                "summary": f"The messages of {name} as Server-Sent Events (one JSON each)",
                "parameters": _STREAM_PARAMETERS,
                "responses": {
                    "200": {"description": "the stream", "content": stream},
                    "default": _ERROR,
                },
            }
        }
    return paths


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
