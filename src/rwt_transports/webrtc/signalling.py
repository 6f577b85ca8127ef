"""WebRTC signalling on the WebSocket port, WHEP style (``rwt serve --webrtc``, docs/webrtc.md).

``POST /webrtc`` with ``Content-Type: application/sdp`` (a complete offer, its
ICE candidates in it: no trickle) answers ``201 Created`` with the answer SDP
and ``Location: /webrtc/<id>``; ``DELETE /webrtc/<id>`` ends that session
(204, or 404 for an unknown id); ``OPTIONS`` answers a browser's CORS
preflight; ``GET /webrtc/roslib-transport.js`` serves roslib's transport
factory for WebRTC (``ROSLIB_TRANSPORT_PATH``, a file of this package, with the
same CORS headers, so a page elsewhere can import it). Everything else on the
port (the WebSocket upgrade, the console) is unchanged: the WebSocket listener
hands a request here only when its request line starts with one of these
methods and the path (``claims``; a ``GET`` only below ``/webrtc/``).

HTTP/1.1 is parsed by h11 (sans-IO); one request per connection. The offer is
at most ``MAX_OFFER_BYTES``. With an authenticator (``--auth-secret-file``) an
offer carrying ``Authorization: Bearer <token>`` must carry a live video token
(``/rwt/video_token``, docs/video.md), else 401; an offer without one opens
sessions whose front end's own proof is asked for (rosbridge's ``auth`` op
first, as a WebSocket client sends it, D23). Both go through the server's one
entry check (``FrontEndHost.entry``, ``rwt_protocol.credentials``).

Video tracks: ``POST /webrtc?video=/camera/image&video=/arm/image`` binds the
offer's receiving video transceivers, in order, to those image topics (at most
``MAX_VIDEO_TRACKS``; video.py); with an authenticator they need the
bearer token, since a video-only peer has no data channel to authenticate on.

WebRTC is an HTTP front end of the registry (``frontends_registry.WEBRTC``),
off unless ``ServerConfig.webrtc`` is set; the protocols its data channels carry
are the registry's too, chosen by label (peers.py).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import TYPE_CHECKING, Protocol
from urllib.parse import parse_qsl

from rwt_protocol.credentials import EntryAuth

from ..frontends import AuthMode
from ..http.endpoint import claims_path, open_request, reply
from .ice import parse_ice_servers
from .stacks import data_stack, stack_refusal, video_native

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    import h11
    from anyio.abc import ByteStream, TaskGroup

__all__ = [
    "CONNECT_TIMEOUT_S",
    "MAX_OFFER_BYTES",
    "MAX_VIDEO_TRACKS",
    "ROSLIB_TRANSPORT_PATH",
    "WEBRTC_PATH",
    "Answer",
    "OfferHandler",
    "VideoRequest",
    "WebRtcOptions",
    "WebRtcSignalling",
]

logger = logging.getLogger("rwt.webrtc")

WEBRTC_PATH = "/webrtc"
"""The signalling endpoint: offers are posted here, sessions live under it."""

ROSLIB_TRANSPORT_PATH = WEBRTC_PATH + "/roslib-transport.js"
"""Where roslib's transport factory for WebRTC is served (docs/webrtc.md, "A page with roslib")."""

MAX_OFFER_BYTES = 64 * 1024
"""Largest offer SDP accepted (a browser's offer with a data channel is about 1 KiB): 413."""

CONNECT_TIMEOUT_S = 15.0
"""Default seconds a peer has, from its answer, to complete ICE and DTLS and open the
``rosbridge`` data channel; then its session is freed (``WebRtcOptions``)."""

MAX_VIDEO_TRACKS = 4
"""The most ``video`` query parameters (video tracks) of one offer: past it, 400."""

_METHODS = (b"POST", b"DELETE", b"OPTIONS", b"GET")
_SDP = "application/sdp"
_JS = "text/javascript; charset=utf-8"
_CORS = [
    (b"Access-Control-Allow-Methods", b"POST, DELETE, OPTIONS"),
    (b"Access-Control-Allow-Headers", b"Authorization, Content-Type"),
    (b"Access-Control-Expose-Headers", b"Location"),
    (b"Access-Control-Max-Age", b"600"),
]


def _names_signalling(method: bytes, after: bytes) -> bool:
    """After ``/webrtc``: a GET is of a file below it; the others of it or a session."""
    return after == b"/" if method == b"GET" else after in (b" ", b"/", b"?")


@dataclass(frozen=True, slots=True)
class WebRtcOptions:
    """Settings of WebRTC signalling (``rwt serve --webrtc``).

    Attributes:
        connect_timeout_s: seconds from the answer for ICE, DTLS and a data
            channel of a registered label to open (or, video only, the peer to
            connect); a peer that does not is freed (``CONNECT_TIMEOUT_S``).
        bearer_token: with an authenticator, checks the token of an offer's
            ``Authorization: Bearer`` header (the video server's tokens,
            ``rwt_video.VideoTokens.valid``); None: the server's
            (``ServerConfig.bearer_token``), and without one such an offer gets 401.
        ice_servers: STUN and TURN server URLs (``--ice-server``, the forms of
            ``rwt_transports.webrtc.ice.parse_ice_server``), whose server-reflexive
            and relayed candidates each answer carries (docs/webrtc.md, "Through
            NAT"); empty: host candidates only, and no traffic to any other host.
        stack: which WebRTC stack answers an offer of data channels only
            (``--webrtc-stack``, D51, D70, D72; stacks.py): ``reactor``
            (libwebrtc's dcsctp, reactor.py), ``native`` (libdatachannel,
            native.py), ``aiortc``, or ``auto``: the first of
            ``webrtc.stacks.AUTO_ORDER`` that imports and reaches every ICE server.
            An offer asking for video tracks is answered by libdatachannel where it
            imports (native_video.py), unless ``aiortc`` is chosen; any other
            offer with video or audio m-sections (or one aiortc would refuse) by
            aiortc whatever the choice (docs/webrtc.md, "Which stack").

    Raises:
        ValueError: an ICE server URL aiortc cannot use, or more than one STUN or
            TURN server (``parse_ice_servers``); a ``stack`` not of
            ``webrtc.native.STACKS``, or one that cannot serve here
            (``webrtc.stacks.stack_refusal`` says why: not installed, or ``native``
            with a TURN server over TCP or TLS).
    """

    connect_timeout_s: float = CONNECT_TIMEOUT_S
    bearer_token: Callable[[str], bool] | None = None
    ice_servers: tuple[str, ...] = field(default=(), repr=False)  # TURN passwords: no repr
    stack: str = "auto"

    def __post_init__(self) -> None:
        servers = parse_ice_servers(self.ice_servers)  # a bad URL: here, not at an offer
        if (refused := stack_refusal(self.stack, servers)) is not None:
            raise ValueError(refused)

    @property
    def data_stack(self) -> str:
        """The stack that answers offers of data channels only: ``auto`` resolved.

        ``reactor``, ``native`` or ``aiortc`` (``webrtc.stacks.data_stack``).
        """
        return data_stack(self.stack, parse_ice_servers(self.ice_servers))

    @property
    def native(self) -> bool:
        """Whether offers asking for video tracks are answered by the native stack."""
        return video_native(self.stack, parse_ice_servers(self.ice_servers))


@dataclass(frozen=True, slots=True)
class Answer:
    """What an offer got: an HTTP status, its text (the answer SDP on 201), its session path."""

    status: int
    text: str
    location: str | None = None


@dataclass(frozen=True, slots=True)
class VideoRequest:
    """The video tracks an offer's query asks for (docs/webrtc.md, "Video tracks").

    Attributes:
        topics: the image topic of each ``video`` parameter, in the query's order.
        query: the other parameters, the last value of each (the video server's
            stream parameters: ``bitrate``, ``width``, ``height``, ``gop``...).
    """

    topics: tuple[str, ...] = ()
    query: Mapping[str, str] = field(default_factory=dict)


def video_request(target: str) -> VideoRequest | Answer:
    """The video tracks the request target's query asks for, or a 400 ``Answer``."""
    _, _, query = target.partition("?")
    pairs = parse_qsl(query, keep_blank_values=True)
    topics = tuple(value for name, value in pairs if name == "video")
    if len(topics) > MAX_VIDEO_TRACKS:
        return Answer(400, f"{len(topics)} video parameters: at most {MAX_VIDEO_TRACKS}")
    if not all(topics):
        return Answer(400, "an empty video parameter: give an image topic, video=/camera/image")
    return VideoRequest(topics, {name: value for name, value in pairs if name != "video"})


class OfferHandler(Protocol):
    """The peer connections behind signalling (``webrtc.peers.WebRtcPeers``)."""

    async def offer(
        self, sdp: str, peer: str, *, authenticated: bool, video: VideoRequest | None = None
    ) -> Answer:
        """Answer an offer (with the video tracks of ``video``): 201 with the answer SDP."""

    def delete(self, session_id: str) -> bool:
        """End the session ``session_id``; False if there is none."""

    def bind(self, tg: TaskGroup | None) -> None:
        """Run sessions in ``tg`` (the server's connections); None: take no offers."""

    def stop_connecting(self) -> None:
        """Free the peers that are not connected yet (the server is stopping)."""


class WebRtcSignalling:
    """Answers WebRTC signalling requests on the WebSocket port.

    Args:
        peers: makes and ends the peer connections.
        options: the WebRTC settings.
        allowed_origins: fnmatch patterns of accepted ``Origin`` headers
            (``--allowed-origins``); empty: any origin, as on the WebSocket.
        entry: the server's one entry check (``FrontEndHost.entry``), which an
            offer's bearer token passes; by default none is required.
    """

    def __init__(
        self,
        peers: OfferHandler,
        options: WebRtcOptions,
        allowed_origins: tuple[str, ...] = (),
        *,
        entry: EntryAuth | None = None,
    ) -> None:
        self.peers = peers
        self.options = options
        self.allowed_origins = allowed_origins
        self.entry = entry or EntryAuth()

    def bind(self, tg: TaskGroup | None) -> None:
        """Answer offers in ``tg`` (the server's connections); None: free the unconnected."""
        self.peers.bind(tg)
        if tg is None:  # stopping: nothing connecting to close gracefully
            self.peers.stop_connecting()

    @staticmethod
    def claims(head: bytes) -> bool | None:
        """Whether the request starting with ``head`` is signalling; None: too short to tell."""
        return claims_path(head, _METHODS, WEBRTC_PATH, _names_signalling)

    async def serve(self, stream: ByteStream, head: bytes, peer: str) -> None:
        """Answer the one request on ``stream`` whose first bytes are ``head``, then return.

        The caller bounds the time (the handshake timeout) and closes the stream.
        """
        opened = await open_request(
            stream,
            head,
            limit=MAX_OFFER_BYTES,
            too_large=f"the offer is over {MAX_OFFER_BYTES} bytes",
            allowed_origins=self.allowed_origins,
            cors=_CORS,
        )
        if opened is None:
            return
        conn, request, headers, cors = opened.conn, opened.request, opened.headers, opened.cors
        answer = await self._route(request, headers, opened.body, peer)
        extra = cors + ([(b"Location", answer.location.encode())] if answer.location else [])
        kind = _SDP if answer.status == 201 else "text/plain; charset=utf-8"
        if request.method == b"GET" and answer.status == 200:
            kind = _JS
            extra.append((b"Cache-Control", b"no-cache"))  # a new rwt serves a new file
        logger.info(
            "event=signalling peer=%s method=%s status=%d",
            peer,
            request.method.decode(),
            answer.status,
        )
        await reply(conn, stream, answer.status, answer.text, extra, kind)

    async def _route(
        self, request: h11.Request, headers: dict[str, str], body: bytes, peer: str
    ) -> Answer:
        method = request.method.decode()
        path = request.target.decode("latin-1").split("?", 1)[0].rstrip("/")
        if method in ("OPTIONS", "GET"):
            return _bodiless(method, path)
        if method == "DELETE":
            session_id = path.removeprefix(WEBRTC_PATH + "/")
            if path.startswith(WEBRTC_PATH + "/") and self.peers.delete(session_id):
                return Answer(204, "")
            return Answer(404, f"no WebRTC session at {path}")
        if path != WEBRTC_PATH:
            return Answer(404, f"post offers to {WEBRTC_PATH}, not {path}")
        return await self._offer(request, headers, body, peer)

    async def _offer(
        self, request: h11.Request, headers: dict[str, str], body: bytes, peer: str
    ) -> Answer:
        """``POST /webrtc``: check the offer and its proof, then hand it to the peers."""
        kind = headers.get("content-type", "").split(";", 1)[0].strip().lower()
        if kind != _SDP:
            return Answer(400, f"the offer must be sent as Content-Type: {_SDP}, not {kind!r}")
        try:
            sdp = body.decode("utf-8")
        except UnicodeDecodeError:
            return Answer(400, "the offer is not UTF-8 text")
        if not sdp.strip():
            return Answer(400, "the offer is empty: post a complete SDP offer")
        video = video_request(request.target.decode("latin-1"))
        if isinstance(video, Answer):
            return video
        authenticated = False
        # a bearer token sent must be live; video tracks need one (a video-only peer has
        # no channel to send its protocol's proof on); else the channel's front end asks
        if self.entry.required and ("authorization" in headers or video.topics):
            refusal = self.entry.check(AuthMode.BEARER, peer, headers=headers, now=time.monotonic())
            if refusal is not None:
                return Answer(refusal.status, refusal.text)
            authenticated = True
        return await self.peers.offer(sdp, peer, authenticated=authenticated, video=video)


def _bodiless(method: str, path: str) -> Answer:
    """``OPTIONS`` (a CORS preflight: 204) or ``GET`` (the roslib transport, else 404)."""
    if method == "OPTIONS":
        return Answer(204, "")
    if path == ROSLIB_TRANSPORT_PATH:
        return Answer(200, roslib_transport())
    return Answer(404, f"nothing at {path}: the transport is at {ROSLIB_TRANSPORT_PATH}")


@cache
def roslib_transport() -> str:
    """The JavaScript served at ``ROSLIB_TRANSPORT_PATH``, read from the package once."""
    return resources.files(__package__).joinpath("static", "roslib-transport.js").read_text("utf-8")
