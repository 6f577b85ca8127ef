"""Client-side connections to a rosbridge server: WebSocket, TCP and a stdio subprocess.

A ``Connection`` moves whole frames: ``send`` one JSON text (``str``) or one
CBOR item (``bytes``: a binary frame on WebSocket, an item in the stream on
TCP), ``receive`` the next frame. The Python client and
the conformance runner both use these, so neither cares which transport is
underneath (D22).

- WebSocket (``ws://``, ``wss://``): websockets' sans-IO ``ClientProtocol``
  driven from an anyio stream, as the server side does. Text frames carry JSON,
  binary frames CBOR (D27). Incoming messages are limited to
  ``max_message_size`` bytes (D24/D30): a bigger one fails the connection
  (close 1009, decided from the frame's header), which then ends at once
  (``closed by the client (1009 ...)``) however much more the server sends.
- TCP (``tcp://HOST:PORT``): JSON objects written one per line, CBOR items
  (``bytes``) as they are; the incoming stream is split into JSON objects
  whether or not the server separates them (rwt writes one per line,
  rosbridge_tcp writes them back to back, D22), and into CBOR items, which
  ``receive`` returns as ``bytes``.
- stdio: a subprocess speaking one JSON object per line on stdin/stdout.
- WebRTC (``webrtc+http://HOST:PORT/webrtc``, ``webrtc+https://...``): the
  ``rosbridge`` data channel of ``rwt serve --webrtc`` (``webrtc.WebRtcConnection``;
  aiortc, the ``webrtc`` extra).

Every failure of the underlying stream is raised as ``ConnectionClosedError`` (a
``TransportError``), so callers catch only rwt's errors.
"""

from __future__ import annotations

import ssl
from collections import deque
from typing import TYPE_CHECKING, Protocol
from urllib.parse import urlsplit

import anyio
from websockets.client import ClientProtocol
from websockets.exceptions import InvalidURI
from websockets.frames import Frame
from websockets.http11 import Response
from websockets.protocol import State
from websockets.uri import parse_uri

from rwt_protocol.errors import ConfigError, TransportError
from rwt_protocol.framing.messages import FrameKind, MessageAssembler, MessageTooBigError
from rwt_protocol.framing.streams import JsonStreamFramer
from rwt_protocol.runtime.inframes import FramerEvent, InFrame

if TYPE_CHECKING:
    from collections.abc import Sequence

    from anyio.abc import ByteStream, Process

__all__ = [
    "WEBRTC_SCHEMES",
    "Connection",
    "ConnectionClosedError",
    "StdioConnection",
    "TcpConnection",
    "WebSocketConnection",
    "connect",
    "server_url",
]

MiB = 1024 * 1024
_READ_SIZE = 65536
Frame_ = str | bytes
"""A whole frame: JSON text as ``str``, CBOR as ``bytes``."""


class ConnectionClosedError(TransportError):
    """The connection is closed, or could not be opened; ``message`` says why."""


class Connection(Protocol):
    """A connection that carries whole rosbridge frames."""

    url: str

    async def send(self, frame: str | bytes) -> None:
        """Send one frame: ``str`` is JSON text, ``bytes`` a binary (CBOR) frame.

        Raises:
            ConnectionClosedError: the connection is gone.
        """

    async def receive(self) -> str | bytes:
        """Wait for the next frame.

        Raises:
            ConnectionClosedError: the connection ended.
        """

    async def aclose(self) -> None:
        """Close the connection; idempotent, never raises."""


async def connect(
    url: str,
    *,
    timeout_s: float = 10.0,
    max_message_size: int = 64 * MiB,
    ssl_context: ssl.SSLContext | None = None,
) -> Connection:
    """Open a connection to a rosbridge server.

    Args:
        url: ``ws://HOST:PORT[/path]``, ``wss://...``, ``tcp://HOST:PORT``,
            ``tcp+tls://HOST:PORT``, ``webrtc+http://HOST:PORT/webrtc`` (a WebRTC
            data channel, docs/webrtc.md) or ``HOST:PORT`` (WebSocket; ``server_url``).
        timeout_s: seconds allowed for connecting and the handshake.
        max_message_size: largest incoming message, bytes.
        ssl_context: TLS settings for ``wss://`` and ``tcp+tls://``; the system
            defaults otherwise.

    Returns:
        The open connection.

    Raises:
        ConnectionClosedError: the server cannot be reached or refused the handshake.
        ConfigError: not one of the above (``server_url``), or a WebRTC URL without
            aiortc installed.
    """
    url = server_url(url)
    scheme = urlsplit(url).scheme
    with anyio.fail_after(timeout_s):
        try:
            if scheme in ("ws", "wss"):
                return await WebSocketConnection.open(url, max_message_size, ssl_context)
            if scheme in WEBRTC_SCHEMES:
                from .webrtc import WebRtcConnection  # noqa: PLC0415 (aiortc: optional)

                return await WebRtcConnection.open(url, max_message_size, ssl_context)
            return await TcpConnection.open(url, max_message_size, ssl_context)
        except TimeoutError:
            raise
        except (OSError, anyio.BrokenResourceError, anyio.EndOfStream) as exc:
            # anyio's EndOfStream and BrokenResourceError carry no text: the server
            # closed, or reset, the connection during the handshake
            reason = str(exc) or str(exc.__cause__ or "") or "the server closed the connection"
            raise ConnectionClosedError(f"cannot connect to {url}: {reason}") from None


URL_FORMS = (
    "ws://, wss://, tcp:// or tcp+tls://HOST:PORT, webrtc+http://HOST:PORT/webrtc, or HOST:PORT"
)
"""The forms of a server's address that ``server_url`` takes, as its errors list them."""


def server_url(text: str, transport: str | None = None) -> str:
    """A rosbridge server's address, in every form rwt takes it, as a URL to connect to.

    The one parser of a server's address: the client (``connect``, ``Ros``),
    ``rwt conformance`` and ``rwt record`` all take ``ws://HOST:PORT[/PATH]``,
    ``wss://...``, ``tcp://HOST:PORT``, ``tcp+tls://HOST:PORT``,
    ``webrtc+http(s)://HOST:PORT[/PATH]`` (the ``rosbridge`` data channel of
    ``rwt serve --webrtc``, its signalling at ``/webrtc`` unless the path says
    otherwise) and ``HOST:PORT`` (WebSocket, the transport rosbridge clients use
    by default).

    Args:
        text: the address as the user wrote it.
        transport: ``ws`` or ``tcp`` to replace the scheme (``rwt conformance
            --transport``); TLS stays: ``wss://`` becomes ``tcp+tls://`` and back.

    Returns:
        The URL, with its scheme: ``127.0.0.1:9090`` gives ``ws://127.0.0.1:9090``.

    Raises:
        ConfigError: another scheme (``http://``), no host, or no port where one is
            needed (TCP, ``HOST:PORT``), or a port outside 0-65535.
    """
    url = text if "://" in text else f"{transport or 'ws'}://{text}"
    parts = urlsplit(url)
    if parts.scheme not in _SCHEMES:
        raise ConfigError(f"unsupported URL scheme {parts.scheme!r} in {text!r}: use {URL_FORMS}")
    tls = parts.scheme in ("wss", "tcp+tls")
    if transport == "tcp" and parts.scheme not in ("tcp", "tcp+tls"):
        url = ("tcp+tls://" if tls else "tcp://") + parts.netloc
    elif transport == "ws" and parts.scheme in ("tcp", "tcp+tls"):
        url = ("wss://" if tls else "ws://") + parts.netloc
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:  # urllib's own words: "Port out of range 0-65535"
        raise ConfigError(f"{text!r}: the port is not a number in 0-65535") from None
    if not parts.hostname:
        raise ConfigError(f"{text!r} names no host: use {URL_FORMS}")
    if port is None and ("://" not in text or parts.scheme in ("tcp", "tcp+tls")):
        raise ConfigError(f"{text!r} names no port: use {URL_FORMS}")
    return url


WEBRTC_SCHEMES = ("webrtc+http", "webrtc+https")
"""The schemes of a WebRTC signalling endpoint (``webrtc.WebRtcConnection``)."""

_SCHEMES = ("ws", "wss", "tcp", "tcp+tls", *WEBRTC_SCHEMES)


async def close_quietly(stream: ByteStream) -> None:
    """Close ``stream``, cutting it when a clean close fails.

    A TLS peer that already closed, or sent data after its close_notify
    (``APPLICATION_DATA_AFTER_CLOSE_NOTIFY``), must not turn closing into an error.
    """
    try:
        await stream.aclose()
    except (
        OSError,
        anyio.BrokenResourceError,
        anyio.ClosedResourceError,
        anyio.BusyResourceError,  # TLS: its close_notify exchange reads, as the reader task does
    ):
        await anyio.aclose_forcefully(stream)


class WebSocketConnection:
    """A WebSocket client connection (RFC 6455) over an anyio byte stream."""

    def __init__(self, url: str, stream: ByteStream, protocol: ClientProtocol, limit: int) -> None:
        self.url = url
        self._stream = stream
        self._protocol = protocol
        self._messages: deque[Frame_] = deque()
        self._assembler = MessageAssembler(limit)
        self._write_lock = anyio.Lock()

    @classmethod
    async def open(
        cls, url: str, max_message_size: int, ssl_context: ssl.SSLContext | None = None
    ) -> WebSocketConnection:
        """Connect and complete the opening handshake.

        Raises:
            ConnectionClosedError: refused or broken handshake.
            OSError: the TCP connection failed.
        """
        try:
            uri = parse_uri(url)
        except InvalidURI as exc:
            raise ConfigError(str(exc)) from None
        stream: ByteStream
        if uri.secure:
            context = ssl_context or ssl.create_default_context()
            stream = await anyio.connect_tcp(uri.host, uri.port, ssl_context=context, tls=True)
        else:
            stream = await anyio.connect_tcp(uri.host, uri.port)
        protocol = ClientProtocol(uri, max_size=max_message_size)
        conn = cls(url, stream, protocol, max_message_size)
        try:
            await conn._handshake()
        except BaseException:  # refused, broken or cancelled: the socket must not leak
            await anyio.aclose_forcefully(stream)
            raise
        return conn

    async def _handshake(self) -> None:
        """Send the opening request and read until the answer (RFC 6455 4.1)."""
        protocol = self._protocol
        protocol.send_request(protocol.connect())
        await self._flush()
        while protocol.state is State.CONNECTING:
            protocol.receive_data(await self._stream.receive(_READ_SIZE))
            for event in protocol.events_received():
                if not isinstance(event, Response):
                    self._collect(event)  # frames that came with the answer are the server's first
                elif protocol.handshake_exc is not None:
                    raise ConnectionClosedError(
                        f"{self.url} refused the WebSocket handshake: {event.status_code}"
                    )

    async def send(self, frame: str | bytes) -> None:
        """Send one text (``str``) or binary (``bytes``) message."""
        if self._protocol.state is not State.OPEN:
            raise ConnectionClosedError(f"{self.url}: {self._close_reason()}")
        if isinstance(frame, str):
            self._protocol.send_text(frame.encode())
        else:
            self._protocol.send_binary(frame)
        await self._flush()

    async def receive(self) -> str | bytes:
        """Wait for the next whole message; answers pings on the way."""
        while not self._messages:
            if self._protocol.state is State.CLOSED:
                raise ConnectionClosedError(f"{self.url}: {self._close_reason()}")
            if self._failed():
                # RFC 6455 7.1.7: after failing the connection (a message over
                # the limit, invalid UTF-8, a protocol error) nothing more is
                # read; a server that goes on sending must not keep it open.
                await close_quietly(self._stream)  # no close frame: the server may not read
                raise ConnectionClosedError(f"{self.url}: {self._close_reason()}")
            try:
                data = await self._stream.receive(_READ_SIZE)
            except (
                anyio.EndOfStream,
                anyio.BrokenResourceError,
                anyio.ClosedResourceError,
                anyio.BusyResourceError,  # TLS: aclose's close_notify exchange is reading
                OSError,
            ):
                self._protocol.receive_eof()
                raise ConnectionClosedError(f"{self.url}: {self._close_reason()}") from None
            self._protocol.receive_data(data)
            for event in self._protocol.events_received():
                self._collect(event)
            await self._flush()
        return self._messages.popleft()

    async def aclose(self) -> None:
        """Send a close frame (1000) and close the stream."""
        try:
            if self._protocol.state is State.OPEN:
                self._protocol.send_close(1000)
                await self._flush()
        except (ConnectionClosedError, anyio.BrokenResourceError, anyio.ClosedResourceError):
            pass  # the peer is gone already: only the socket is left to close
        except OSError:
            pass
        finally:
            await close_quietly(self._stream)

    def _collect(self, event: object) -> None:
        kind = FrameKind.of(event.opcode) if isinstance(event, Frame) else None
        if kind is None:
            return
        assert isinstance(event, Frame)
        try:
            message = self._assembler.add(kind, event.data, fin=event.fin)
        except MessageTooBigError:
            self._protocol.fail(1009, "message too big")
            return
        if message is not None:
            data = message.data
            self._messages.append(data if message.binary else data.decode("utf-8", "replace"))

    async def _flush(self) -> None:
        async with self._write_lock:
            for data in self._protocol.data_to_send():
                try:
                    if data:
                        await self._stream.send(data)
                    else:
                        await self._stream.send_eof()
                except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
                    raise ConnectionClosedError(f"{self.url}: connection lost") from None
                except NotImplementedError:
                    pass  # TLS streams cannot half-close; closing follows

    def _failed(self) -> bool:
        """Whether this side failed the connection (sent a close other than 1000 first)."""
        sent = self._protocol.close_sent
        return sent is not None and sent.code != 1000 and self._protocol.close_rcvd is None

    def _close_reason(self) -> str:
        close = self._protocol.close_rcvd
        if close is None:
            sent = self._protocol.close_sent
            if self._failed() and sent is not None:
                return f"closed by the client ({sent.code} {sent.reason})".rstrip()
            return "connection closed"
        return f"closed by the server ({close.code} {close.reason})".rstrip()


class _LineStreamConnection:
    """Shared part of the TCP and stdio connections: JSON text out, JSON values in."""

    url: str

    def __init__(self, url: str, limit: int) -> None:
        self.url = url
        self._framer = JsonStreamFramer(limit)
        self._frames: deque[str | bytes] = deque()

    carries_cbor = False
    """Whether the stream takes CBOR items (TCP does, D22; stdio is JSON lines only)."""

    async def send(self, frame: str | bytes) -> None:
        """Send one JSON text followed by a newline, or one CBOR item as it is.

        A CBOR item (``bytes``, a map or an array, D21) needs no delimiter: it is
        self-delimiting, and its first byte tells it apart from JSON (D22).

        Raises:
            ConnectionClosedError: the connection is gone, or ``bytes`` on a stream
                that carries JSON only (stdio).
        """
        if isinstance(frame, bytes):
            if not self.carries_cbor:
                raise ConnectionClosedError(f"{self.url}: this transport carries JSON text only")
            data = frame
        else:
            data = (frame.replace("\n", " ") + "\n").encode()
        try:
            await self._write(data)
        except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            raise ConnectionClosedError(f"{self.url}: connection lost") from None

    async def receive(self) -> str | bytes:
        """Wait for the next JSON value from the stream."""
        while not self._frames:
            try:
                data = await self._read()
            except (
                anyio.EndOfStream,
                anyio.BrokenResourceError,
                anyio.ClosedResourceError,
                anyio.BusyResourceError,  # TLS: aclose's close_notify exchange is reading
                OSError,
            ):
                raise ConnectionClosedError(f"{self.url}: connection closed") from None
            self._take(self._framer.receive_data(data))
        return self._frames.popleft()

    def _take(self, events: list[FramerEvent]) -> None:
        # The server's own framer (rwt_protocol.framing.streams) also reads CBOR items,
        # which a TCP server sends for CBOR subscriptions (D22).
        for event in events:
            if isinstance(event, InFrame):
                self._frames.append(event.data if event.binary else event.data.decode())
            elif event.fatal:
                raise ConnectionClosedError(f"{self.url}: {event.message}")

    async def _write(self, data: bytes) -> None:
        raise NotImplementedError

    async def _read(self) -> bytes:
        raise NotImplementedError


class TcpConnection(_LineStreamConnection):
    """A rosbridge TCP connection (D22): JSON texts and CBOR items."""

    carries_cbor = True

    def __init__(self, url: str, stream: ByteStream, limit: int) -> None:
        super().__init__(url, limit)
        self._stream = stream

    @classmethod
    async def open(
        cls, url: str, max_message_size: int, ssl_context: ssl.SSLContext | None = None
    ) -> TcpConnection:
        """Connect to ``tcp://HOST:PORT``, or ``tcp+tls://HOST:PORT`` (TLS, as ``rwt serve``).

        Raises:
            ConfigError: no port in the URL.
            OSError: the connection failed (``ssl.SSLError``: the TLS handshake).
        """
        parts = urlsplit(url)
        if parts.hostname is None or parts.port is None:
            raise ConfigError(f"expected tcp://HOST:PORT, got {url!r}")
        stream: ByteStream
        if parts.scheme == "tcp+tls":
            context = ssl_context or ssl.create_default_context()
            stream = await anyio.connect_tcp(
                parts.hostname, parts.port, ssl_context=context, tls=True
            )
        else:
            stream = await anyio.connect_tcp(parts.hostname, parts.port)
        return cls(url, stream, max_message_size)

    async def aclose(self) -> None:
        """Close the socket."""
        await close_quietly(self._stream)

    async def _write(self, data: bytes) -> None:
        await self._stream.send(data)

    async def _read(self) -> bytes:
        return await self._stream.receive(_READ_SIZE)


class StdioConnection(_LineStreamConnection):
    """A rosbridge server run as a subprocess, one JSON object per line on stdin/stdout."""

    def __init__(self, command: Sequence[str], process: Process, limit: int) -> None:
        super().__init__("stdio:" + " ".join(command), limit)
        self.process = process

    @classmethod
    async def open(
        cls, command: Sequence[str], max_message_size: int = 64 * MiB
    ) -> StdioConnection:
        """Start ``command`` with pipes for stdin and stdout (stderr is inherited).

        Raises:
            ConnectionClosedError: the command cannot be started.
        """
        try:
            process = await anyio.open_process(list(command), stderr=None)
        except OSError as exc:
            raise ConnectionClosedError(f"cannot start {command[0]!r}: {exc}") from None
        return cls(command, process, max_message_size)

    async def aclose(self) -> None:
        """Close stdin, then wait (at most 5 s) for the process before terminating it."""
        if self.process.stdin is not None:
            await self.process.stdin.aclose()
        with anyio.move_on_after(5.0):
            await self.process.wait()
            return
        self.process.terminate()
        await self.process.wait()

    async def _write(self, data: bytes) -> None:
        assert self.process.stdin is not None  # opened with a pipe
        await self.process.stdin.send(data)

    async def _read(self) -> bytes:
        assert self.process.stdout is not None  # opened with a pipe
        return await self.process.stdout.receive(_READ_SIZE)
