"""The HTTP video server (Robot Web Tools paper IV.B; web_video_server compatible).

Paths as web_video_server serves them: ``/`` lists the image topics,
``/stream?topic=...&type=...`` streams one (``multipart/x-mixed-replace`` for
mjpeg, png and ros_compressed; WebM for vp8 and vp9; fragmented MP4 for h264),
``/stream_viewer?topic=...`` is a page showing that stream and
``/snapshot?topic=...`` answers one JPEG. Like web_video_server every response
closes its connection and allows any origin (ros3djs loads the stream into a
WebGL texture). HTTP/1.1 is parsed by h11 (sans-IO) over anyio streams, the
same shape as the WebSocket transport.

With ``VideoConfig.tokens`` (``rwt serve --auth-secret-file``) every path but the
console's needs a live video token (``tokens``): 401 without one, 403 with a bad one,
checked by the one entry check of every front end (``AuthMode.VIDEO_TOKEN``,
``rwt_protocol.credentials``: ``?token=`` or ``Authorization: Bearer``).

Differences, all answering with a status where web_video_server would hang or
stream nothing: a topic that does not exist is 404, a topic of another type
400, vp8/vp9/h264 without PyAV installed 501, and a snapshot without a frame
within ``snapshot_timeout_s`` 503.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING
from urllib.parse import parse_qsl, urlsplit

import anyio
import h11
from anyio.abc import SocketAttribute, SocketStream, TaskStatus

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.credentials import AuthMode, EntryAuth, video_token
from rwt_protocol.errors import RwtError

from .encoders import BOUNDARY, VIDEO_CONTENT_TYPES, EncodeError
from .hub import PartViewer, SharedStream, StreamHub, VideoViewer
from .pages import stream_viewer_page, topic_list_page
from .params import StreamParamError, StreamParams, StreamType, parse_stream_params

if TYPE_CHECKING:
    from rwt_console import ConsoleSite
    from rwt_graph.graph import Graph

    from .tokens import VideoTokens

__all__ = ["VideoConfig", "serve_video"]

logger = logging.getLogger("rwt.video")
_episodes = EpisodeLog(logger)  # a peer can trigger these at will

_REQUEST_LIMIT_S = 10.0
_READ_SIZE = 65536
_NO_CACHE = "no-cache, no-store, must-revalidate, pre-check=0, post-check=0, max-age=0"


@dataclass(frozen=True)
class VideoConfig:
    """Settings of the video server (web_video_server's parameters where one exists).

    Attributes:
        host: address to bind (web_video_server's ``address``).
        port: HTTP port (``port``, 8080); 0 picks a free one.
        default_stream_type: the ``type`` when a request gives none.
        snapshot_timeout_s: how long ``/snapshot`` waits for a frame, seconds.
        max_connections: the most HTTP connections at once (viewers included); the
            next one is answered 503 at once (docs/limits.md).
        max_streams: the most distinct streams (topic, type and parameters; one
            encoder each) at once; a request for another one is answered 503.
        encoder_threads: the most frames encoded at once over all streams, each in
            a worker thread; None: the image threads every front end shares
            (``hub.ENCODER_THREADS``: half the CPUs, at least one). A stream
            waiting for its turn skips to its newest frame.
        console: the web console under ``/console/`` (docs/console.md); None: not served.
        tokens: when set, every path but the console's needs a live token of these
            (``?token=`` or ``Authorization: Bearer``): 401 without one, 403 with a
            wrong or expired one (``rwt serve --auth-secret-file``; docs/video.md).
    """

    host: str = "127.0.0.1"
    port: int = 8080
    default_stream_type: StreamType = StreamType.MJPEG
    snapshot_timeout_s: float = 10.0
    max_connections: int = 64
    max_streams: int = 16
    encoder_threads: int | None = None
    console: ConsoleSite | None = None
    tokens: VideoTokens | None = None


async def serve_video(
    graph: Graph,
    config: VideoConfig | None = None,
    *,
    task_status: TaskStatus[str] = anyio.TASK_STATUS_IGNORED,
) -> None:
    """Serve the image topics of ``graph`` over HTTP until cancelled.

    Args:
        graph: the graph whose topics are streamed (the one ``rwt serve`` serves).
        config: server settings.
        task_status: receives the base URL (``http://HOST:PORT``) once listening.

    Raises:
        OSError: the address cannot be bound.
    """
    config = config or VideoConfig()
    listener = await anyio.create_tcp_listener(
        local_host=config.host, local_port=config.port, reuse_port=False
    )
    async with listener, anyio.create_task_group() as tg:
        hub = StreamHub(graph, tg, config.max_streams, config.encoder_threads)
        port = listener.extra(SocketAttribute.local_port)
        host = f"[{config.host}]" if ":" in config.host else config.host
        url = f"http://{host}:{port}"
        logger.info("video server on %s", url)
        task_status.started(url)
        gate = _Gate(config.max_connections)
        await listener.serve(functools.partial(_serve_connection, hub, config, gate), task_group=tg)


class _Gate:
    """Counts the open connections against ``VideoConfig.max_connections``."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.open = 0
        self.refusing = False  # log once per episode


_BUSY = (
    b"HTTP/1.1 503 Service Unavailable\r\nConnection: close\r\n"
    b"Content-Type: text/plain; charset=utf-8\r\nContent-Length: 26\r\n\r\n"
    b"503 too many connections\r\n"
)


async def _serve_connection(
    hub: StreamHub, config: VideoConfig, gate: _Gate, stream: SocketStream
) -> None:
    if gate.open >= gate.limit:
        if not gate.refusing:
            _episodes.log(
                logging.WARNING,
                "refused",
                "event=refused reason='too many video connections' limit=%d",
                gate.limit,
            )
            gate.refusing = True
        with anyio.move_on_after(1.0), contextlib.suppress(Exception):
            async with stream:
                await stream.send(_BUSY)
        return
    gate.refusing = False
    gate.open += 1
    try:
        await _serve_request(hub, config, stream)
    finally:
        gate.open -= 1


async def _serve_request(hub: StreamHub, config: VideoConfig, stream: SocketStream) -> None:
    try:
        async with stream:
            http = _Http(stream)
            with anyio.move_on_after(_REQUEST_LIMIT_S):
                request = await http.read_request()
            if request is None:
                return
            async with anyio.create_task_group() as tg:
                tg.start_soon(_cancel_on_close, stream, tg.cancel_scope)
                await _route(hub, config, http, request)
                tg.cancel_scope.cancel()
    except (anyio.BrokenResourceError, anyio.ClosedResourceError, anyio.EndOfStream):
        pass  # the viewer went away
    except h11.ProtocolError as exc:
        logger.debug("bad HTTP request: %s", exc)
    except Exception:  # one broken connection must never take the server down
        _episodes.log(logging.ERROR, "failed", "video connection failed", exc_info=True)


async def _cancel_on_close(stream: SocketStream, scope: anyio.CancelScope) -> None:
    """A viewer that closes its side ends its response (and may end the stream)."""
    try:
        while await stream.receive(_READ_SIZE):
            pass
    except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
        pass
    scope.cancel()


class _Http:
    """One connection's h11 state and its socket."""

    def __init__(self, stream: SocketStream) -> None:
        self.stream = stream
        self.conn = h11.Connection(h11.SERVER)

    async def read_request(self) -> h11.Request | None:
        """The request, or None if the peer closed first; h11 bounds its size (16 KiB)."""
        while True:
            event = self.conn.next_event()
            if isinstance(event, h11.Request):
                return event
            if event is h11.NEED_DATA:
                try:
                    data = await self.stream.receive(_READ_SIZE)
                except anyio.EndOfStream:
                    data = b""
                self.conn.receive_data(data)
            elif isinstance(event, h11.ConnectionClosed):
                return None

    async def start(self, status: int, content_type: str, **headers: str) -> None:
        """Send the status line and headers; the body follows with ``send``."""
        fields = [
            ("Connection", "close"),
            ("Server", "rwt"),
            ("Cache-Control", _NO_CACHE),
            ("Pragma", "no-cache"),
            ("Content-Type", content_type),
            ("Access-Control-Allow-Origin", "*"),
            *((name.replace("_", "-"), value) for name, value in headers.items()),
        ]
        await self.stream.send(self.conn.send(h11.Response(status_code=status, headers=fields)))

    async def send(self, data: bytes) -> None:
        """Send part of the body."""
        if data:
            await self.stream.send(self.conn.send(h11.Data(data=data)))

    async def reply(self, status: int, content_type: str, body: bytes, **headers: str) -> None:
        """A whole response with a Content-Length."""
        await self.start(status, content_type, Content_Length=str(len(body)), **headers)
        await self.send(body)
        await self.stream.send(self.conn.send(h11.EndOfMessage()))

    async def error(self, status: int, text: str) -> None:
        """A plain-text error response."""
        await self.reply(status, "text/plain; charset=utf-8", f"{status} {text}\n".encode())


async def _route(hub: StreamHub, config: VideoConfig, http: _Http, request: h11.Request) -> None:
    target = request.target.decode("latin-1")
    if config.console is not None and config.console.handles(target):
        reply = config.console.answer(request.method.decode("latin-1"), target)
        fields = dict(reply.headers)
        del fields["Cache-Control"]  # ``start`` sets its own
        # Content-Length as the reply says: for HEAD, the size a GET would get
        await http.start(reply.status, fields.pop("Content-Type"), **fields)
        await http.send(reply.body)
        await http.stream.send(http.conn.send(h11.EndOfMessage()))
        return
    if request.method != b"GET":
        await http.error(405, "only GET is served")
        return
    url = urlsplit(request.target.decode("latin-1"))
    query = dict(parse_qsl(url.query, keep_blank_values=True))
    query.pop("token", None)
    headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in request.headers}
    token = video_token(headers, url.query)
    if config.tokens is not None and not await _admitted(config.tokens, http, headers, url.query):
        return
    if url.path in ("/", ""):
        topics = hub.graph.topic_names_and_types()
        page = topic_list_page(topics, token if config.tokens else None)
        await http.reply(200, "text/html; charset=utf-8", page.encode())
        return
    handler = _HANDLERS.get(url.path)
    if handler is None:
        await http.error(404, f"no page {url.path}")
        return
    try:
        params = _checked(hub.graph, parse_stream_params(query, config.default_stream_type))
        await handler(hub, config, http, params, token if config.tokens else None)
    except StreamParamError as exc:
        await http.error(exc.status, str(exc))


async def _admitted(tokens: VideoTokens, http: _Http, headers: dict[str, str], query: str) -> bool:
    """Whether the request's video token opens the server; if not, the 401 or 403 is sent.

    Through the one entry check (``EntryAuth``, ``AuthMode.VIDEO_TOKEN``).
    """
    entry = EntryAuth(required=True, token=tokens.valid)
    refusal = entry.check(
        AuthMode.VIDEO_TOKEN, "", headers=headers, query=query, now=time.monotonic()
    )
    if refusal is None:
        return True
    if refusal.status == 401:
        body = f"401 {refusal.text}\n".encode()
        await http.reply(
            401, "text/plain; charset=utf-8", body, WWW_Authenticate='Bearer realm="rwt video"'
        )
        return False
    _episodes.log(logging.WARNING, "bad_token", "event=refused reason='bad video token'")
    await http.error(refusal.status, refusal.text)
    return False


def _checked(graph: Graph, params: StreamParams) -> StreamParams:
    """``params`` after checking the topic; ros_compressed falls back to mjpeg.

    Raises:
        StreamParamError: no such topic (404) or not an image topic (400).
    """
    types = {name: _short(type_name) for name, type_name in graph.topic_names_and_types()}
    if params.type is StreamType.ROS_COMPRESSED:
        if types.get(params.source_topic) == "sensor_msgs/CompressedImage":
            return params
        _episodes.log(
            logging.WARNING,
            f"no_source {params.topic}",
            "no %s: streaming %s as mjpeg",
            params.source_topic,
            params.topic,
        )
        params = params.with_type(StreamType.MJPEG)  # as web_video_server does
    found = types.get(params.topic)
    if found is None:
        raise StreamParamError(f"topic {params.topic} does not exist", status=404)
    if found != "sensor_msgs/Image":
        raise StreamParamError(f"topic {params.topic} is a {found}, not a sensor_msgs/Image")
    return params


def _short(type_name: str) -> str:
    return type_name.replace("/msg/", "/")


def _type_of(params: StreamParams) -> str:
    if params.type is StreamType.ROS_COMPRESSED:
        return "sensor_msgs/msg/CompressedImage"
    return "sensor_msgs/msg/Image"


async def _stream(
    hub: StreamHub, config: VideoConfig, http: _Http, params: StreamParams, token: str | None
) -> None:
    try:
        if params.type.is_video:
            with hub.watching(params, _type_of(params), VideoViewer) as video:
                await _send_video(http, params, video)
        else:
            with hub.watching(params, _type_of(params), _part_viewer) as viewer:
                await _send_parts(http, viewer)
    except EncodeError as exc:
        await http.error(501, str(exc))
    except RwtError as exc:
        await http.error(400, exc.message)


async def _send_parts(http: _Http, viewer: PartViewer) -> None:
    """web_video_server's multipart stream: one part per frame, the newest first."""
    await http.start(200, f"multipart/x-mixed-replace;boundary={BOUNDARY}")
    await http.send(f"--{BOUNDARY}\r\n".encode())
    while True:
        await http.send((await viewer.next_part()).multipart)  # the bytes all viewers share


async def _send_video(http: _Http, params: StreamParams, viewer: VideoViewer) -> None:
    await http.start(200, VIDEO_CONTENT_TYPES[params.type], Expires="0", Max_Age="0")
    while True:
        try:
            chunk = await viewer.next_chunk()
        except EncodeError as exc:
            _episodes.log(
                logging.WARNING,
                f"viewer_stopped {params.topic}",
                "video viewer of %s stopped: %s",
                params.topic,
                exc,
            )
            return
        await http.send(chunk)


async def _snapshot(
    hub: StreamHub, config: VideoConfig, http: _Http, params: StreamParams, token: str | None
) -> None:
    """One JPEG (quality from the query, 95 by default) from the shared mjpeg stream."""
    params = params.with_type(StreamType.MJPEG) if params.type is not StreamType.MJPEG else params
    part = None
    with hub.watching(params, _type_of(params), _part_viewer) as viewer:
        with anyio.move_on_after(config.snapshot_timeout_s):
            part = await viewer.next_part()
    if part is None:
        await http.error(503, f"no image on {params.topic} within {config.snapshot_timeout_s} s")
        return
    await http.reply(200, part.content_type, part.data, X_Timestamp=f"{part.stamp_s:.6f}")


async def _stream_viewer(
    hub: StreamHub, config: VideoConfig, http: _Http, params: StreamParams, token: str | None
) -> None:
    page = stream_viewer_page(params, token)
    await http.reply(200, "text/html; charset=utf-8", page.encode())


def _part_viewer(stream: SharedStream) -> PartViewer:
    return PartViewer(stream.last_parts)


# the last argument: the request's token, for the pages' own links (None without tokens)
_Handler = Callable[[StreamHub, VideoConfig, _Http, StreamParams, str | None], Awaitable[None]]

_HANDLERS: dict[str, _Handler] = {
    "/stream": _stream,
    "/snapshot": _snapshot,
    "/stream_viewer": _stream_viewer,
}
