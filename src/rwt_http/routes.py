"""A request's method and target read as a ``Route`` of the HTTP API (docs/http.md).

``<name>`` in a path is the ROS name without its leading slash
(``/api/topics/robot/odom`` is ``/robot/odom``). A topic's event stream is its
path with ``/events`` added, so ``GET /api/topics/a/events`` is always the stream of
``/a``: the latest message of a topic named ``/a/events`` is not reachable by GET
(its stream is, at ``/api/topics/a/events/events``). The query's ``type``,
``throttle_rate`` and ``queue_length`` keep rosbridge's names (spec 3.4.2-3.4.3);
``history``, ``depth``, ``reliability``, ``durability``, ``deadline`` and ``lifespan``
are protocol 2.1.0's ``qos`` of a publish or an event stream, spelled as in the op
(D62): ``?durability=transient_local&depth=5``, ``?lifespan=0.2``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING
from urllib.parse import parse_qs, unquote, urlsplit

from pydantic import ValidationError

from rwt_protocol.errors import RemoteProtocolError
from rwt_protocol.names import name_problem
from rwt_protocol.ops.qos import Qos

if TYPE_CHECKING:
    from rwt_protocol.qos import QosProfile

__all__ = [
    "API_PREFIX",
    "EVENTS_SUFFIX",
    "OPENAPI_PATH",
    "Route",
    "RouteError",
    "RouteKind",
    "parse_route",
]

API_PREFIX = "/api/"
"""Where the API's paths start."""

OPENAPI_PATH = "/openapi.json"
"""Where the OpenAPI document is answered."""

EVENTS_SUFFIX = "/events"
"""What a topic's path ends with for its event stream (``/api/topics/a/events``)."""

MAX_QUEUE_LENGTH = 10_000
"""Largest ``queue_length`` an event stream may ask for (messages held for it)."""


class RouteKind(Enum):
    """What a request asks for."""

    OPENAPI = "openapi"
    TOPICS = "topics"
    LATEST = "latest"
    PUBLISH = "publish"
    EVENTS = "events"
    SERVICE = "service"
    ACTION = "action"


@dataclass(frozen=True, slots=True)
class Route:
    """One request of the API.

    Attributes:
        kind: what it asks for.
        name: the resolved ROS name (``/robot/odom``); empty for the listing and
            the document.
        type_name: the ``type`` query parameter, or None.
        throttle_rate_ms: ``throttle_rate``: at least this many milliseconds
            between two messages of an event stream (0: none).
        queue_length: ``queue_length``: at most this many messages wait for an
            event stream's client (0: the send buffer's bytes only).
        qos: the QoS its query gives (protocol 2.1.0, D62), or None.
    """

    kind: RouteKind
    name: str = ""
    type_name: str | None = None
    throttle_rate_ms: int = 0
    queue_length: int = 0
    qos: QosProfile | None = None


class RouteError(RemoteProtocolError):
    """A request the API cannot take: ``status`` (404, 405, 400) and the text."""

    def __init__(self, status: int, text: str) -> None:
        super().__init__(text)
        self.status = status
        self.text = text


_BY_FAMILY = {
    ("topics", "GET"): RouteKind.LATEST,
    ("topics", "HEAD"): RouteKind.LATEST,
    ("topics", "POST"): RouteKind.PUBLISH,
    ("services", "POST"): RouteKind.SERVICE,
    ("actions", "POST"): RouteKind.ACTION,
}


def parse_route(method: str, target: str) -> Route:
    """The route of ``method`` on ``target`` (a request target: path and query).

    Raises:
        RouteError: 404 for a path the API does not have, 405 for a method its
            path does not take, 400 for a bad query value or a name that is not a
            ROS name (``rwt_protocol.names``, as a rosbridge op's name is checked).
    """
    parts = urlsplit(target)
    path, query = unquote(parts.path), parse_qs(parts.query)
    if path == OPENAPI_PATH:
        return _checked(method, ("GET", "HEAD"), Route(RouteKind.OPENAPI))
    if not path.startswith(API_PREFIX):
        raise RouteError(404, f"no such path: {_shown(path)}")
    family, _, rest = path[len(API_PREFIX) :].partition("/")
    if family == "topics" and not rest.strip("/"):
        return _checked(method, ("GET", "HEAD"), Route(RouteKind.TOPICS))
    name = "/" + rest.strip("/")
    if family not in ("topics", "services", "actions") or name == "/" or "//" in name:
        raise RouteError(404, f"no such path: {_shown(path)}")
    if family == "topics" and name.endswith(EVENTS_SUFFIX) and name != EVENTS_SUFFIX:
        stream = _stream(query)
        route = Route(
            RouteKind.EVENTS, _named(name.removesuffix(EVENTS_SUFFIX)), *stream, _qos(query)
        )
        return _checked(method, ("GET",), route)
    _named(name)
    kind = _BY_FAMILY.get((family, method))
    if kind is None:
        allowed = sorted(m for f, m in _BY_FAMILY if f == family)
        raise RouteError(405, f"{API_PREFIX}{family}/<name> takes {', '.join(allowed)}")
    qos = _qos(query) if kind is RouteKind.PUBLISH else None
    return Route(kind, name, _one(query, "type"), qos=qos)


def _shown(text: str) -> str:
    """``text`` as an error may quote it: escaped (no control or bidi characters), cut."""
    return ascii(text if len(text) <= 80 else text[:77] + "...")


def _named(name: str) -> str:
    """``name`` when it is a ROS name; else a 400 naming the problem (cut and escaped)."""
    problem = name_problem(name)
    if problem is not None:
        raise RouteError(400, ascii(problem)[1:-1])
    return name


def _checked(method: str, allowed: tuple[str, ...], route: Route) -> Route:
    if method not in allowed:
        raise RouteError(405, f"this path takes {', '.join(allowed)}")
    return route


def _one(query: dict[str, list[str]], key: str) -> str | None:
    values = query.get(key)
    return values[-1] if values else None


_QOS_FIELDS = ("history", "depth", "reliability", "durability", "deadline", "lifespan")


def _qos(query: dict[str, list[str]]) -> QosProfile | None:
    """The QoS a query gives (``ops.qos.Qos``'s rules, D62), None when it names no policy.

    Raises:
        RouteError: 400 naming the parameter of a bad value.
    """
    given: dict[str, object] = {}
    for key in _QOS_FIELDS:
        text = _one(query, key)
        if text is None:
            continue
        value: object = text
        if key == "depth":
            digits = text.removeprefix("-")
            value = int(text) if digits.isdigit() and len(digits) < 20 else text
        elif key in ("deadline", "lifespan"):
            try:
                value = float(text)
            except ValueError:
                value = text  # "infinite", "best_available": the model reads those
        given[key] = value
    if not given:
        return None
    try:
        return Qos.model_validate(given).profile()
    except ValidationError as exc:
        error = exc.errors()[0]
        field = ".".join(str(part) for part in error["loc"]) or "qos"
        text = error["msg"][:1].lower() + error["msg"][1:]
        raise RouteError(400, f"{field}: {text}"[:200]) from None


def _stream(query: dict[str, list[str]]) -> tuple[str | None, int, int]:
    """``type``, ``throttle_rate`` and ``queue_length`` of an event stream's query."""
    numbers = []
    for key, top in (("throttle_rate", 3_600_000), ("queue_length", MAX_QUEUE_LENGTH)):
        text = _one(query, key) or "0"
        if not text.isdigit() or int(text) > top:
            raise RouteError(400, f"{key} must be an integer from 0 to {top}")
        numbers.append(int(text))
    return _one(query, "type"), numbers[0], numbers[1]
