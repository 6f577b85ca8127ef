"""Requests for the console's files answered without I/O: GET/HEAD of known paths only.

Why a fixed table: the files are read from the package once, at first use, and a
request path is only ever looked up in that table, so no path a client sends
reaches the file system (no traversal), and the answer is bounded by the
package's own files. Every answer says ``no-cache`` (a new rwt version serves
new files at the same paths) and carries a Content-Security-Policy that lets
the page load only its own scripts and styles, talk only WebSocket, and show
images and video from any HTTP origin (the video server is on another port).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cache
from importlib import resources

__all__ = ["ConsoleSite", "Reply", "console_for", "http_response_bytes"]

PREFIX = "/console/"
"""Where the console's files live on a port; ``/`` is the page too on the WebSocket port."""

_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".json": "application/json",
    ".svg": "image/svg+xml",
    ".txt": "text/plain; charset=utf-8",
}
_MAX_FILE_BYTES = 512 * 1024
"""A file of the package larger than this is not served (they are all far smaller)."""

_POLICY = (
    "default-src 'self'; script-src 'self'; style-src 'self'; "
    "connect-src 'self' ws: wss:; img-src 'self' data: blob: http: https:; "
    "media-src 'self' blob: http: https:; frame-ancestors 'none'; base-uri 'none'"
)
_STATUS_TEXT = {200: "OK", 404: "Not Found", 405: "Method Not Allowed"}


@dataclass(frozen=True, slots=True)
class Reply:
    """One HTTP answer.

    Attributes:
        status: the HTTP status code (200, 404 or 405).
        headers: header fields, in order (Content-Type and Content-Length included).
        body: the body bytes; empty for HEAD (Content-Length still says the GET size).
    """

    status: int
    headers: tuple[tuple[str, str], ...]
    body: bytes


@cache
def _files() -> dict[str, tuple[bytes, str]]:
    """Every servable file of ``static/``: name -> (bytes, content type)."""
    files: dict[str, tuple[bytes, str]] = {}
    root = resources.files(__package__).joinpath("static")
    for entry in root.iterdir():
        suffix = "." + entry.name.rsplit(".", 1)[-1] if "." in entry.name else ""
        kind = _TYPES.get(suffix)
        if kind is None or not entry.is_file():
            continue
        data = entry.read_bytes()
        if len(data) <= _MAX_FILE_BYTES:
            files[entry.name] = (data, kind)
    return files


@dataclass
class ConsoleSite:
    """The console as one port serves it, with what the page must know to find the rest.

    Mutable on purpose: ``rwt serve`` fills in the ports as its listeners bind
    (``--port 0`` and ``--video-port 0`` are known only then).

    Attributes:
        websocket_path: the path of the rosbridge WebSocket (``--url-path``; ``/`` for any).
        websocket_port: the WebSocket port when the page is served from another
            port (the video server's); None: the page's own port.
        websocket_tls: the WebSocket is wss (``--certfile``).
        video_port: the video server's port (``--video``), or None.
        video_token: the video server wants a token from ``/rwt/video_token`` in
            each stream URL (``--auth-secret-file`` with ``--video``; docs/video.md).
        auth: the server asks for the rosauth ``auth`` op first (``--auth-secret-file``).
        foxglove: Foxglove clients are answered on the WebSocket port (``rwt serve``'s
            default; ``--no-foxglove``: off): the page shows the URL they open
            (docs/foxglove.md).
        root_is_console: ``/`` serves the page (the WebSocket port); the video
            server keeps ``/`` for web_video_server's topic list.
        limits: the server's limits the page lists, by command-line option name
            (``{"--max-message-size": 10485760, ...}``; docs/limits.md).
    """

    websocket_path: str = "/"
    websocket_port: int | None = None
    websocket_tls: bool = False
    video_port: int | None = None
    video_token: bool = False
    auth: bool = False
    foxglove: bool = False
    root_is_console: bool = True
    limits: dict[str, object] = field(default_factory=dict)

    def config(self) -> dict[str, object]:
        """What ``/console/config.json`` answers (its fields are described in docs/console.md)."""
        return {
            "websocket": {
                "port": self.websocket_port,
                "path": self.websocket_path,
                "tls": self.websocket_tls,
            },
            "video": (
                None
                if self.video_port is None
                else {"port": self.video_port, "token": self.video_token}
            ),
            "auth": self.auth,
            "foxglove": self.foxglove,
            "limits": self.limits,
        }

    def handles(self, target: str) -> bool:
        """Whether the request target is one of the console's paths (query ignored)."""
        path = target.split("?", 1)[0]
        return (
            path.startswith(PREFIX)
            or path == PREFIX.rstrip("/")
            or (self.root_is_console and path in ("/", ""))
        )

    def answer(self, method: str, target: str) -> Reply:
        """The reply to ``method target``: a file, the config, or 404/405.

        Args:
            method: the HTTP method; only GET and HEAD are answered with content.
            target: the request target (a path with an optional query).
        """
        if method not in ("GET", "HEAD"):
            return _text(405, "only GET and HEAD are served", allow="GET, HEAD")
        path = target.split("?", 1)[0]
        name: str | None = None
        if path in ("/", "", PREFIX, PREFIX.rstrip("/")) and self.handles(path):
            name = "index.html"
        elif path.startswith(PREFIX):
            name = path[len(PREFIX) :]
        if name == "config.json":
            body = json.dumps(self.config()).encode()
            return _reply(200, body, "application/json", head=method == "HEAD")
        found = _files().get(name) if name else None
        if found is None:
            return _text(404, f"no console file at {path}")
        data, kind = found
        return _reply(200, data, kind, head=method == "HEAD")


def console_for(
    wanted: bool | None,
    origins: tuple[str, ...],
    url_path: str | None,
    *,
    tls: bool,
    auth: bool,
    foxglove: bool,
) -> ConsoleSite | None:
    """The console of a WebSocket port, or None when it is off (docs/console.md).

    By default (``wanted`` None) it is on, except with allowed origins: the operator
    chose which web pages may reach the robot, and the robot's own page is not one of
    them unless ``wanted`` says so (its origin must then be allowed too). With an
    authenticator it stays on: the page asks for the ``auth`` op first. ``rwt serve``
    (``--console``/``--no-console``, ``--allowed-origins``) and an embedded
    ``GraphServer`` (``WebSocketOptions.console``) both decide by this rule.

    Args:
        wanted: True or False as asked for; None for the default.
        origins: the allowed ``Origin`` patterns (empty: any origin).
        url_path: the WebSocket's only path, or None for any.
        tls: the WebSocket is wss.
        auth: the server asks for the ``auth`` op first.
        foxglove: Foxglove clients are answered on the same port.
    """
    if wanted is None:
        wanted = not origins
    if not wanted:
        return None
    path = url_path or "/"
    return ConsoleSite(websocket_path=path, websocket_tls=tls, auth=auth, foxglove=foxglove)


def _reply(status: int, body: bytes, kind: str, *, head: bool = False, **extra: str) -> Reply:
    headers = (
        ("Content-Type", kind),
        ("Content-Length", str(len(body))),
        ("Cache-Control", "no-cache"),
        ("X-Content-Type-Options", "nosniff"),
        ("Content-Security-Policy", _POLICY),
        ("Referrer-Policy", "no-referrer"),
        *((name.replace("_", "-").title(), value) for name, value in extra.items()),
    )
    return Reply(status, headers, b"" if head else body)


def _text(status: int, text: str, allow: str | None = None) -> Reply:
    body = f"{status} {text}\n".encode()
    if allow is None:
        return _reply(status, body, "text/plain; charset=utf-8")
    return _reply(status, body, "text/plain; charset=utf-8", allow=allow)


def http_response_bytes(reply: Reply) -> bytes:
    """``reply`` as HTTP/1.1 bytes that close the connection (for a raw socket)."""
    lines = [f"HTTP/1.1 {reply.status} {_STATUS_TEXT.get(reply.status, 'Error')}"]
    lines += [f"{name}: {value}" for name, value in reply.headers]
    lines += ["Connection: close", "", ""]
    return "\r\n".join(lines).encode("latin-1") + reply.body
