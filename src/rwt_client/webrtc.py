"""A client connection over a WebRTC data channel: ``webrtc+http://HOST:PORT/webrtc``.

The server's side is ``rwt serve --webrtc`` (docs/webrtc.md): the offer, with its
ICE candidates gathered (no trickle), is posted to the URL without its
``webrtc+`` prefix (``http://HOST:PORT/webrtc``; ``webrtc+https://`` posts over
TLS), the answer comes back with ``201 Created`` and the session's
``Location``, and the ``rosbridge`` data channel then carries whole frames as a
WebSocket does: JSON as text messages, CBOR as binary ones. A JSON message
larger than the server takes in one (its answer's ``a=max-message-size``, 64 KiB
without one, RFC 8841) goes as ``fragment`` ops (spec 3.1.1, D19), which the
server reassembles; a CBOR one that large cannot be cut and is refused
(``ConnectionClosedError``). The other way, the server cuts a JSON message over
64 KiB into ``fragment`` ops whose id starts ``webrtc:`` (docs/webrtc.md): this
connection joins those, so its reader gets the message whole, as over a WebSocket
(fragments a subscription asked for with ``fragment_size`` are left to the
reader). ``send`` waits while the channel buffers more than
``SEND_HIGH_WATER_BYTES``. Closing the connection deletes the session (``DELETE``
its ``Location``) and closes the peer connection.

WebRTC comes from aiortc, the ``webrtc`` extra; without it, opening such a URL
raises ``ConfigError`` with the command that installs it. The request is one
HTTP/1.1 exchange made with h11 (the ``server`` extra, which ``webrtc`` brings).
"""

from __future__ import annotations

import contextlib
import itertools
import json
import re
import ssl
from collections import deque
from typing import TYPE_CHECKING, Any
from urllib.parse import urljoin, urlsplit

import anyio

from rwt_protocol.distribution import install_hint
from rwt_protocol.errors import ConfigError, RwtError
from rwt_protocol.framing.datagrams import fragment_datagrams
from rwt_protocol.framing.fragments import PartKind, Reassembler

from .connectors import WEBRTC_SCHEMES, ConnectionClosedError

if TYPE_CHECKING:
    from anyio.abc import ByteStream

__all__ = ["WebRtcConnection", "signalling_url"]

DEFAULT_PATH = "/webrtc"
"""The signalling path when the URL names none (the server's ``WEBRTC_PATH``)."""

MAX_ANSWER_BYTES = 256 * 1024
"""The largest answer (status line, headers and SDP) read from the server."""

SEND_HIGH_WATER_BYTES = 1024 * 1024
"""``send`` waits while the data channel buffers more than this for the server."""

DEFAULT_MAX_MESSAGE_BYTES = 64 * 1024
"""The largest message a peer whose SDP states no ``a=max-message-size`` takes (RFC 8841 6.1)."""

MAX_PENDING_MESSAGES = 4
"""Messages the server cut into ``fragment`` ops that may be incomplete at once."""

_READ_SIZE = 65536
_TRANSPORT_FRAGMENT = '{"op":"fragment","id":"webrtc:'  # the server's own cut (webrtc.py)
_MAX_MESSAGE_SIZE = re.compile(r"^a=max-message-size:(\d+)\s*$", re.MULTILINE)
_ids = itertools.count(1)


class WebRtcConnection:
    """A rosbridge session over the ``rosbridge`` data channel of one peer connection."""

    def __init__(
        self, url: str, pc: Any, channel: Any, session: str, limit: int, answer: str
    ) -> None:
        self.url = url
        self._pc = pc
        self._channel = channel
        self._session = session  # the http(s) URL that DELETE ends
        self._limit = limit
        found = _MAX_MESSAGE_SIZE.search(answer)
        self.remote_max_message_size = int(found.group(1)) if found else DEFAULT_MAX_MESSAGE_BYTES
        """The largest message the server takes, bytes (0: any size)."""
        self._messages: deque[str | bytes] = deque()
        self._parts = Reassembler(
            max_bytes=limit, max_pending=MAX_PENDING_MESSAGES, timeout_s=float("inf")
        )
        self._arrived = anyio.Event()
        self._drained = anyio.Event()
        self._closed_reason: str | None = None
        channel.bufferedAmountLowThreshold = SEND_HIGH_WATER_BYTES // 4
        channel.on("message", self._on_message)
        channel.on("close", lambda: self._end("closed by the server"))
        channel.on("bufferedamountlow", self._on_low)

    @classmethod
    async def open(
        cls, url: str, max_message_size: int, ssl_context: ssl.SSLContext | None = None
    ) -> WebRtcConnection:
        """Offer, post the offer, take the answer and wait for the data channel to open.

        Raises:
            ConfigError: aiortc is missing (its install command in the text), or the
                URL is not ``webrtc+http(s)://HOST[:PORT][/PATH]``.
            ConnectionClosedError: the server refused the offer (its status and reason).
            OSError: the server cannot be reached.
        """
        try:
            from aiortc import (  # noqa: PLC0415 (optional: the webrtc extra)
                RTCConfiguration,
                RTCPeerConnection,
                RTCSessionDescription,
            )
        except ImportError:
            raise ConfigError(f"{url}: WebRTC needs aiortc: {install_hint('webrtc')}") from None
        endpoint = signalling_url(url)
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        try:
            channel = pc.createDataChannel("rosbridge")
            opened = anyio.Event()
            channel.on("open", opened.set)
            channel.on("close", opened.set)
            await pc.setLocalDescription(await pc.createOffer())
            status, location, text = await _post(endpoint, pc.localDescription.sdp, ssl_context)
            if status != 201 or location is None:
                raise ConnectionClosedError(f"{url} refused the offer: {status} {text.strip()}")
            await pc.setRemoteDescription(RTCSessionDescription(text, "answer"))
            session = urljoin(endpoint, location)
            conn = cls(url, pc, channel, session, max_message_size, text)
            await opened.wait()
            if channel.readyState != "open":
                raise ConnectionClosedError(f"{url}: the data channel closed before it opened")
        except BaseException:  # refused, failed or cancelled: the peer connection must go
            with anyio.CancelScope(shield=True):
                await pc.close()
            raise
        return conn

    def _on_message(self, message: str | bytes) -> None:
        size = len(message) if isinstance(message, bytes) else len(message.encode())
        if size > self._limit:  # as a WebSocket fails for it (close 1009)
            self._end(f"closed by the client (message of {size} bytes over {self._limit})")
            self._channel.close()
            return
        if isinstance(message, str) and message.startswith(_TRANSPORT_FRAGMENT):
            try:
                part = json.loads(message)
                whole = self._parts.add(
                    PartKind.FRAGMENT,
                    part["id"],
                    part["num"],
                    part["total"],
                    data=part["data"],
                    now=0.0,
                )
            except (RwtError, ValueError, KeyError, TypeError) as exc:
                self._end(f"closed by the client (a fragment of the server's is wrong: {exc})")
                self._channel.close()
                return
            if whole is None:
                return
            message = whole
        self._messages.append(message)
        self._arrived.set()

    def _on_low(self) -> None:
        self._drained.set()  # the current event: ``send`` makes a new one each wait

    def _end(self, reason: str) -> None:
        if self._closed_reason is None:
            self._closed_reason = reason
        self._arrived.set()
        self._drained.set()

    async def send(self, frame: str | bytes) -> None:
        """Send one text (``str``, JSON) or binary (``bytes``, CBOR) message.

        Raises:
            ConnectionClosedError: the connection is gone, or a CBOR message is larger
                than the server takes (``remote_max_message_size``).
        """
        limit = self.remote_max_message_size
        if isinstance(frame, bytes):
            if limit and len(frame) > limit:
                raise ConnectionClosedError(
                    f"{self.url}: a CBOR message of {len(frame)} bytes is over the server's "
                    f"max-message-size ({limit}): it cannot be cut into fragment ops"
                )
            parts: list[str | bytes] = [frame]
        else:
            data = frame.encode()
            parts = (
                [frame]
                if not limit or len(data) <= limit
                else [
                    part.decode() for part in fragment_datagrams(data, limit, f"rwt:{next(_ids)}")
                ]
            )
        for part in parts:
            if self._closed_reason is not None or self._channel.readyState != "open":
                reason = self._closed_reason or "connection closed"
                raise ConnectionClosedError(f"{self.url}: {reason}")
            self._channel.send(part)
            while self._channel.bufferedAmount > SEND_HIGH_WATER_BYTES:
                self._drained = anyio.Event()
                await self._drained.wait()

    async def receive(self) -> str | bytes:
        """Wait for the next whole message."""
        while not self._messages:
            if self._closed_reason is not None:
                raise ConnectionClosedError(f"{self.url}: {self._closed_reason}")
            self._arrived = anyio.Event()
            await self._arrived.wait()
        return self._messages.popleft()

    async def aclose(self) -> None:
        """End the session (``DELETE``, best effort) and close the peer connection."""
        self._end("connection closed")
        with anyio.CancelScope(shield=True):
            with anyio.move_on_after(2), contextlib.suppress(OSError, ConnectionClosedError):
                await _request("DELETE", self._session, b"", {}, None)
            await self._pc.close()


def signalling_url(url: str) -> str:
    """The http(s) URL offers are posted to: ``url`` without ``webrtc+``, ``/webrtc`` by default.

    Raises:
        ConfigError: not ``webrtc+http(s)://HOST[:PORT][/PATH]``.
    """
    parts = urlsplit(url)
    if parts.scheme not in WEBRTC_SCHEMES or not parts.hostname:
        raise ConfigError(f"expected webrtc+http://HOST:PORT/webrtc, got {url!r}")
    path = parts.path if parts.path not in ("", "/") else DEFAULT_PATH
    return f"{parts.scheme.removeprefix('webrtc+')}://{parts.netloc}{path}"


async def _post(
    url: str, sdp: str, ssl_context: ssl.SSLContext | None
) -> tuple[int, str | None, str]:
    """Post the offer: the status, the ``Location`` and the body (the answer on 201)."""
    headers = {"Content-Type": "application/sdp"}
    return await _request("POST", url, sdp.encode(), headers, ssl_context)


async def _request(
    method: str,
    url: str,
    body: bytes,
    headers: dict[str, str],
    ssl_context: ssl.SSLContext | None,
) -> tuple[int, str | None, str]:
    """One HTTP/1.1 request (``Connection: close``); the status, ``Location`` and body text.

    Raises:
        OSError: the server cannot be reached.
        ConnectionClosedError: the answer is not HTTP h11 reads, or over ``MAX_ANSWER_BYTES``.
    """
    import h11  # noqa: PLC0415 (the server extra's, which webrtc brings)

    parts = urlsplit(url)
    host = parts.hostname or ""
    tls = parts.scheme == "https"
    port = parts.port or (443 if tls else 80)
    stream: ByteStream
    if tls:
        context = ssl_context or ssl.create_default_context()
        stream = await anyio.connect_tcp(host, port, ssl_context=context, tls=True)
    else:
        stream = await anyio.connect_tcp(host, port)
    conn = h11.Connection(h11.CLIENT)
    fields = [
        ("Host", parts.netloc),
        ("Content-Length", str(len(body))),
        ("Connection", "close"),
        *headers.items(),
    ]
    target = parts.path + (f"?{parts.query}" if parts.query else "")
    try:
        data = conn.send(h11.Request(method=method, target=target, headers=fields)) or b""
        data += (conn.send(h11.Data(data=body)) or b"") if body else b""
        data += conn.send(h11.EndOfMessage()) or b""
        await stream.send(data)
        return await _answer(conn, stream, url)
    except (h11.ProtocolError, anyio.EndOfStream, anyio.BrokenResourceError) as exc:
        raise ConnectionClosedError(f"{url}: not an HTTP answer: {exc}") from None
    finally:
        await anyio.aclose_forcefully(stream)


async def _answer(conn: Any, stream: ByteStream, url: str) -> tuple[int, str | None, str]:
    """Read the response of ``conn`` (h11) from ``stream``, bounded by ``MAX_ANSWER_BYTES``."""
    import h11  # noqa: PLC0415 (the server extra's, which webrtc brings)

    status, location, body, read = 0, None, bytearray(), 0
    while True:
        event = conn.next_event()
        if event is h11.NEED_DATA:
            data = await stream.receive(_READ_SIZE)
            read += len(data)
            if read > MAX_ANSWER_BYTES:
                raise ConnectionClosedError(f"{url}: the answer is over {MAX_ANSWER_BYTES} bytes")
            conn.receive_data(data)
        elif isinstance(event, h11.Response):
            status = event.status_code
            for name, value in event.headers:
                if name == b"location":
                    location = value.decode("latin-1")
        elif isinstance(event, h11.Data):
            body += event.data
        elif isinstance(event, h11.EndOfMessage | h11.ConnectionClosed):
            return status, location, body.decode("utf-8", "replace")
