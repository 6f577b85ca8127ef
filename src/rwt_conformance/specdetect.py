"""Which version of the spec a server follows, found as ``rwt conformance`` finds it.

In order (docs/conformance.md, "Spec versions"):

1. ``GET /version`` on the host and port of the server's URL (``http`` for
   ``ws://`` and ``webrtc+http://``, ``https`` for ``wss://``, with the run's TLS
   settings): rosbridge_server's answer ``{"protocol": {"major", "minor",
   "patch"}, ...}`` (docs/reference-behaviour.md §13.4, D49). The server is not
   trusted: the exchange is bounded in time (``timeout_s``) and size (a body
   over ``MAX_VERSION_BYTES``, headers over ``MAX_HEADER_BYTES``); whatever
   else it answers (another status, not JSON, numbers that are not small
   integers) is a reason to probe, kept for the report.
2. Else (and always for ``tcp://`` and ``tcp+tls://``, which have no HTTP) a
   probe of what 2.0.0 changed: a ``publish`` with ``type`` to a fresh topic
   nobody advertised, then ``/rosapi/topic_type`` of that topic, asked until it
   names the type or ``PROBE_SETTLE_S`` have passed (a ROS 2 graph learns a new
   publisher a moment later). A topic that has the type was advertised by the
   publish: 2.0.0 or later. One that stays unknown was refused: the unversioned
   spec. A server whose rosapi does not answer cannot tell; it is taken to be
   unversioned, "assumed". Then, for a server that advertised, a probe of what
   2.1.0 added: the same ``publish`` to a second fresh topic with a ``qos`` no
   server that reads it can take (``{"depth": -1}``, refused by rosbridge_suite
   2.7.0/3.3.0/4.2.0 and by rwt, D62): a topic that stays unknown was refused for
   its ``qos``: 2.1.0; one advertised ignored it: 2.0.0.

``--spec-version`` skips both (``SpecFinding.given``).
"""

from __future__ import annotations

import json
import secrets
import ssl
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

import anyio
import h11

from rwt_client.connectors import Connection, ConnectionClosedError, connect

from .bounds import MAX_FRAME_BYTES, SendTimeoutError, close_within, send_within
from .frames import auth_op, decode_frame
from .model import Dialect
from .versions import SpecVersion

if TYPE_CHECKING:
    from collections.abc import Mapping

    from anyio.abc import ByteStream

__all__ = [
    "MAX_HEADER_BYTES",
    "MAX_VERSION_BYTES",
    "PROBE_SETTLE_S",
    "SpecFinding",
    "SpecSource",
    "find_spec_version",
    "probe_spec_version",
    "read_version_endpoint",
]

MAX_VERSION_BYTES = 64 * 1024
"""Largest ``GET /version`` body read (rwt's is about 300 bytes); past it, the probe."""

MAX_HEADER_BYTES = 16 * 1024
"""Largest status line and headers of the ``GET /version`` answer."""

PROBE_SETTLE_S = 1.0
"""Seconds the probe asks ``/rosapi/topic_type`` for the type before taking it as refused."""

_READ_BYTES = 4096
_PROBE_ID = "rwt_conformance_spec_probe"
_NUMBER_LIMIT = 10_000  # a version number past it is not one


class SpecSource(StrEnum):
    """Where a run's spec version came from (the JSON report's ``source``)."""

    VERSION_ENDPOINT = "version-endpoint"
    PROBE = "probe"
    OPTION = "option"


@dataclass(frozen=True, slots=True)
class SpecFinding:
    """The spec version a run judges by, where it came from, and the evidence.

    Attributes:
        version: the spec version.
        source: ``GET /version``, the probe or ``--spec-version``.
        detail: one line of evidence: the URL asked, what the probe saw, and why
            ``GET /version`` did not tell when the probe ran.
    """

    version: SpecVersion
    source: SpecSource
    detail: str = ""

    @classmethod
    def given(cls, version: SpecVersion) -> SpecFinding:
        """A version given with ``--spec-version``."""
        return cls(version, SpecSource.OPTION, "given with --spec-version")

    def describe(self) -> str:
        """``spec version 2.1.0 (from GET /version)`` and the like, one line."""
        if self.source is SpecSource.VERSION_ENDPOINT:
            how = "from GET /version"
        elif self.source is SpecSource.PROBE:
            how = f"from a probe: {self.detail}"
        else:
            how = "given with --spec-version"
        return f"spec version {self.version} ({how})"

    def as_json(self) -> dict[str, str]:
        """``{"version", "source", "detail"}`` for the JSON report."""
        return {"version": str(self.version), "source": self.source.value, "detail": self.detail}


async def find_spec_version(
    url: str,
    dialect: Dialect,
    ssl_context: ssl.SSLContext | None = None,
    timeout_s: float = 3.0,
    auth_secret: str | None = None,
    max_frame_bytes: int = MAX_FRAME_BYTES,
) -> SpecFinding:
    """The spec version of the server at ``url``: ``GET /version``, else the probe.

    Args:
        url: the server, as the run's URL.
        dialect: the server's ROS edition (the probe's type name).
        ssl_context: TLS settings, as for the run.
        timeout_s: bound of the HTTP exchange, and of each of the probe's waits.
        auth_secret: the server's rosauth secret (D23), for the probe's connection.
        max_frame_bytes: largest frame taken from the server, bytes.

    Returns:
        What was found; never raises for what the server does.
    """
    http_url = version_url(url)
    why = "no HTTP on a TCP URL"
    if http_url is not None:
        version, why = await read_version_endpoint(http_url, ssl_context, timeout_s)
        if version is not None:
            return SpecFinding(version, SpecSource.VERSION_ENDPOINT, why)
    version, seen = await probe_spec_version(
        url, dialect, ssl_context, timeout_s, auth_secret, max_frame_bytes
    )
    return SpecFinding(version, SpecSource.PROBE, f"{seen}; GET /version: {why}")


def version_url(url: str) -> str | None:
    """``http(s)://HOST:PORT/version`` for a WebSocket or WebRTC URL; None for TCP."""
    parts = urlsplit(url)
    scheme = {"ws": "http", "wss": "https", "webrtc+http": "http", "webrtc+https": "https"}
    http = scheme.get(parts.scheme)
    if http is None or not parts.netloc:
        return None
    return f"{http}://{parts.netloc}/version"


async def read_version_endpoint(
    url: str, ssl_context: ssl.SSLContext | None = None, timeout_s: float = 3.0
) -> tuple[SpecVersion | None, str]:
    """``GET url``, read as rosbridge_server's version answer (module docstring).

    Returns:
        The protocol version and ``GET URL says protocol X.Y.Z``; or None and why
        not (a refused connection, a status, a body too large, bad JSON...).
    """
    try:
        with anyio.fail_after(timeout_s):
            status, body = await _get(url, ssl_context)
    except TimeoutError:
        return None, f"no answer within {timeout_s:g} s"
    except (OSError, anyio.BrokenResourceError, anyio.EndOfStream) as exc:
        return None, f"cannot connect: {_printable(str(exc) or type(exc).__name__)}"
    except (h11.ProtocolError, _TooLargeError) as exc:
        return None, _printable(str(exc) or type(exc).__name__)
    if status != 200:
        return None, f"answered status {status}"
    try:
        document = json.loads(body)
    except (ValueError, RecursionError):
        return None, "the answer is not JSON"
    version = _protocol(document)
    if version is None:
        return None, "the answer has no protocol.major, .minor and .patch as small integers"
    return version, f"GET {url} says protocol {version}"


class _TooLargeError(Exception):
    """The answer is larger than the runner reads."""


async def _get(url: str, ssl_context: ssl.SSLContext | None) -> tuple[int, bytes]:
    """One ``GET`` over a fresh connection: the status and the body (bounded)."""
    parts = urlsplit(url)
    tls = parts.scheme == "https"
    host = parts.hostname or ""
    port = parts.port or (443 if tls else 80)
    stream: ByteStream
    if not tls:  # anyio wraps a stream given a context in TLS
        stream = await anyio.connect_tcp(host, port)
    else:
        context = ssl_context or ssl.create_default_context()
        stream = await anyio.connect_tcp(
            host, port, tls=True, ssl_context=context, tls_standard_compatible=False
        )
    async with stream:
        conn = h11.Connection(h11.CLIENT, max_incomplete_event_size=MAX_HEADER_BYTES)
        request = h11.Request(
            method="GET",
            target="/version",
            headers=[
                ("Host", parts.netloc),
                ("Accept", "application/json"),
                ("Connection", "close"),
                ("User-Agent", "rwt-conformance"),
            ],
        )
        await stream.send(conn.send(request) + (conn.send(h11.EndOfMessage()) or b""))
        status, body = 0, bytearray()
        while True:
            event = conn.next_event()
            if event is h11.NEED_DATA:
                try:
                    conn.receive_data(await stream.receive(_READ_BYTES))
                except anyio.EndOfStream:
                    conn.receive_data(b"")
            elif isinstance(event, h11.Response):
                status = event.status_code
            elif isinstance(event, h11.Data):
                body += event.data
                if len(body) > MAX_VERSION_BYTES:
                    raise _TooLargeError(f"the answer is over {MAX_VERSION_BYTES} bytes")
            elif isinstance(event, h11.EndOfMessage | h11.ConnectionClosed):
                return status, bytes(body)


def _protocol(document: object) -> SpecVersion | None:
    """``protocol``'s three numbers, each an integer (not a bool) in 0-9999."""
    if not isinstance(document, dict):
        return None
    protocol = document.get("protocol")
    if not isinstance(protocol, dict):
        return None
    numbers = [protocol.get(key) for key in ("major", "minor", "patch")]
    ints = [n for n in numbers if isinstance(n, int) and not isinstance(n, bool)]
    if len(ints) != 3 or not all(0 <= n < _NUMBER_LIMIT for n in ints):
        return None
    return SpecVersion.of(*ints)


async def probe_spec_version(
    url: str,
    dialect: Dialect,
    ssl_context: ssl.SSLContext | None = None,
    timeout_s: float = 3.0,
    auth_secret: str | None = None,
    max_frame_bytes: int = MAX_FRAME_BYTES,
) -> tuple[SpecVersion, str]:
    """Which of unversioned, 2.0.0 and 2.1.0 a server follows, by the probe (module text).

    A ``publish`` with ``type`` that advertises: 2.0.0 or later; then one with a bad
    ``qos`` that is refused: 2.1.0.

    Returns:
        The version and what the probe saw, one line; never raises for what the
        server does (a server it cannot tell about: unversioned, "assumed").
    """
    unversioned = SpecVersion.UNVERSIONED
    try:
        conn = await connect(
            url, timeout_s=2 * timeout_s, max_message_size=max_frame_bytes, ssl_context=ssl_context
        )
    except (ConnectionClosedError, TimeoutError):
        return unversioned, "assumed (the probe could not connect)"
    type_name = "std_msgs/String" if dialect is Dialect.ROS1 else "std_msgs/msg/String"
    topic = f"/rwt_conformance_spec_{secrets.token_hex(4)}"
    try:
        if auth_secret is not None:
            host = urlsplit(url).hostname or ""
            await send_within(conn, json.dumps(auth_op(auth_secret, {}, host)), timeout_s)
        told = await _publish_and_ask(conn, topic, type_name, timeout_s)
        what = f"a publish with type to an unknown topic, then /rosapi/topic_type: {told}"
        if not told.startswith("names "):
            if told.startswith("no type"):
                return unversioned, f"it was refused ({what})"
            return unversioned, f"assumed ({what})"
        return await _probe_qos(conn, topic, type_name, timeout_s, what)
    except ConnectionClosedError as exc:
        return unversioned, f"assumed (the server closed the probe's connection: {exc.message})"
    except SendTimeoutError as exc:
        return unversioned, f"assumed ({exc})"
    finally:
        await close_within(conn)


async def _publish_and_ask(
    conn: Connection, topic: str, type_name: str, timeout_s: float, qos: object = None
) -> str:
    """A ``publish`` with ``type`` (and ``qos``, when given) to ``topic``; its type told after."""
    publish: dict[str, object] = {"op": "publish", "topic": topic, "type": type_name}
    if qos is not None:
        publish["qos"] = qos
    publish.update(id=_PROBE_ID, msg={"data": "probe"})
    await send_within(conn, json.dumps(publish), timeout_s)
    return await _topic_type(conn, topic, timeout_s)


async def _probe_qos(
    conn: Connection, topic: str, type_name: str, timeout_s: float, before: str
) -> tuple[SpecVersion, str]:
    """2.1.0 or 2.0.0, for a server whose ``publish`` with ``type`` advertised (module text)."""
    told = await _publish_and_ask(conn, f"{topic}_qos", type_name, timeout_s, {"depth": -1})
    what = f"{before}; the same with qos depth -1 to another: {told}"
    if told.startswith("no type"):
        return SpecVersion.of(2, 1), f"it was advertised, and refused for its qos ({what})"
    if told.startswith("names "):
        return SpecVersion.of(2), f"it was advertised, and its qos ignored ({what})"
    return SpecVersion.of(2), f"it was advertised; its qos could not be told ({what})"


async def _topic_type(conn: Connection, topic: str, timeout_s: float) -> str:
    """Ask ``/rosapi/topic_type`` of ``topic`` until it names a type, for ``PROBE_SETTLE_S``.

    Returns:
        ``names TYPE``, ``no type after N s``, ``no answer ...`` or ``failed ...``.
    """
    settled = anyio.current_time() + PROBE_SETTLE_S
    pause_s = 0.05
    for ask in range(100):
        call_id = f"{_PROBE_ID}:{ask}"
        call = {
            "op": "call_service",
            "service": "/rosapi/topic_type",
            "args": {"topic": topic},
            "id": call_id,
        }
        await send_within(conn, json.dumps(call), timeout_s)
        answer = await _response(conn, call_id, timeout_s)
        if answer is None:
            return f"no answer within {timeout_s:g} s"
        if answer.get("result") is not True or not isinstance(answer.get("values"), dict):
            return "failed (no rosapi to ask)"
        values = answer["values"]
        told = values.get("type") if isinstance(values, dict) else None
        if isinstance(told, str) and told:
            return f"names {_printable(told)}"
        if anyio.current_time() + pause_s > settled:
            break
        await anyio.sleep(pause_s)
        pause_s = min(2 * pause_s, 0.25)
    return f"no type after {PROBE_SETTLE_S:g} s"


async def _response(
    conn: Connection, call_id: str, timeout_s: float
) -> Mapping[str, object] | None:
    """The ``service_response`` with ``call_id``, or None after ``timeout_s``."""
    with anyio.move_on_after(timeout_s):
        while True:
            value = decode_frame(await conn.receive()).value
            if (
                isinstance(value, dict)
                and value.get("op") == "service_response"
                and value.get("id") == call_id
            ):
                return value
    return None


def _printable(text: str, limit: int = 120) -> str:
    """What a server wrote, shown safely: controls escaped, at most ``limit`` characters."""
    shown = text if text.isprintable() else repr(text)
    return shown if len(shown) <= limit else shown[: limit - 3] + "..."
