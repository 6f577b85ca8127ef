"""The HTTP front ends a server answers on its WebSocket port, unless told not to.

One entry a front end (``frontends.HttpFrontEnd``): its paths, its endpoint's
factory, its default options. The server makes each endpoint from here
(``RosbridgeServer``) and knows none by name; ``ServerConfig.http_options``
gives one its options, or None to turn it off. Adding an HTTP front end is its
own package, its transport module and a line here (docs/architecture.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .http_api import HTTP_API

if TYPE_CHECKING:
    from .frontends import HttpFrontEnd

__all__ = ["HTTP_FRONTENDS"]

HTTP_FRONTENDS: tuple[HttpFrontEnd, ...] = (HTTP_API,)
"""The HTTP API (``rwt_http``, docs/http.md)."""
