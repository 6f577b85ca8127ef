"""The HTTP + Server-Sent Events front end: the graph for browsers, curl and scripts.

Paths on the server's WebSocket port (docs/http.md), answered by one sans-IO
session per request on the connection runtime every protocol shares
(``rwt_protocol.runtime``, docs/architecture.md, "How to add a protocol"): the
same admission, access rules, limits and slow-consumer rule as a rosbridge or
Foxglove client. The modules, each over the next:

- ``session``: ``HttpSession``, one request's work on the graph (list, latest
  message, publish, event stream, service call, action goal) and its answer.
- ``document``: the OpenAPI document made in slices, once per change of the graph,
  and kept per set of access rules (D59).
- ``openapi``: the OpenAPI 3.1 document's parts (``GET /openapi.json``).
- ``standing``: the registrations that keep a publish's ``qos`` past its request.
- ``routes``: a request's method and target read as a ``Route``.
- ``wire``: the bytes of a response and of a Server-Sent Event.

The transport's side (reading the request, the bearer token, running the pump)
is ``rwt_transports.http.api``; the document's builds run in
``rwt_transports.http.documents``.
"""

from __future__ import annotations

from .routes import API_PREFIX, OPENAPI_PATH, Route, RouteError, RouteKind, parse_route
from .session import HttpApiOptions, HttpSession
from .standing import StandingOffers

__all__ = [
    "API_PREFIX",
    "OPENAPI_PATH",
    "HttpApiOptions",
    "HttpSession",
    "Route",
    "RouteError",
    "RouteKind",
    "StandingOffers",
    "parse_route",
]
