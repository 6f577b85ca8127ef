"""The built-in web console: a page served by ``rwt serve`` on its own ports (docs/console.md).

The page and its ES modules are package data under ``static/``; ``ConsoleSite``
answers the HTTP requests for them (and for ``/console/config.json``, which tells
the page where the WebSocket and the video server are). No I/O here: the
WebSocket transport and the video server send the ``Reply``.
"""

from __future__ import annotations

from .site import ConsoleSite, Reply, console_for

__all__ = ["ConsoleSite", "Reply", "console_for"]
