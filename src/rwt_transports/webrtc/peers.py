"""The server's WebRTC peer connections: an offer in, sessions on the pump out (docs/webrtc.md).

An offer is admitted as any connection is, with the server's public ticket
(``FrontEndHost.admit``: ``--max-connections``, host shares), then answered by
aiortc, libdatachannel or libwebrtc (``--webrtc-stack``, ``_plan``, D51, D70), with every
ICE candidate gathered (no trickle): host candidates, and
with ``--ice-server`` the server-reflexive and relayed ones its STUN and TURN
servers give (aioice waits at most 5 s for them). The ticket holds the peer's slot;
no session exists yet. A data channel's label chooses its protocol from the
server's one front-end registry (``FrontEnds.by_label``, ``frontends_registry``):
rosbridge's ``rosbridge`` (reliable, ordered), or a registered protocol's label.
The first such channel opens the session on the ticket (``open_session(ticket=)``,
counted in ``/connected_clients`` from then), which runs on the connection pump
like a WebSocket's once the channel is open (channel.py). A lossy label of the same
front end (``rosbridge-lossy``: unordered, ``maxRetransmits`` 0 or 1) belongs to the same
session: it opens the session's lossy lane (D36). A label the registry does not
name is refused: the channel is closed and the log names the label and the ones
served (``event=channel_refused``). Bounds, each enforced here (docs/limits.md):

- the offer's form (offer.py, D38): checked before anything else, so a
  malformed or oversized one (media sections, candidates and the addresses they
  name) costs a read of its text.
- ``MAX_CONNECTING``: offers being answered plus peers not yet connected, over
  the server, shared per host as the connections are (``admission.shares.HostShares``,
  D37); more get 503. Each holds UDP sockets and aiortc's ICE and DTLS state,
  and answering one makes a key pair, so a burst of offers is bounded, and one
  host cannot hold every slot.
- ``OFFER_TIMEOUT_S``: answering one offer (ICE gathering, a TURN allocation
  included); after it, 503.
- ``WebRtcOptions.connect_timeout_s``: from the answer to an open data channel
  (ICE, DTLS, SCTP); a peer that never gets there is freed.
- what a peer's SCTP holds below its session (sctp.py, D39): messages
  over the size abandoned as they arrive, held fragments counted in the inbox.

A session ends when its data channel or peer connection closes or fails, on
``DELETE /webrtc/<id>``, on its idle timeout, or as any session does; its peer
connection is closed with it, and the ticket's slot is given back.

Video tracks (``?video=``, video.py; native_video.py on the native
stack) are bound to the offer's video transceivers before the answer, join their
shared streams when the peer connects (D37: a peer that never connects runs no
encoder) and leave them when the peer connection ends. An offer with video and no
data channel is a video-only peer: it holds its ticket (admitted and counted as
any connection, by the same budget and host shares) and never a session, and lasts
as long as its peer connection (until it fails or closes, ``DELETE``, shutdown).
"""

from __future__ import annotations

import asyncio
import logging
import re
import secrets
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import anyio
from aiortc import RTCConfiguration, RTCIceServer, RTCPeerConnection, RTCSessionDescription

from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.errors import ConfigError
from rwt_protocol.runtime.commands import CloseCode
from rwt_protocol.runtime.contract import LossySession

from ..admission.shares import HostShares, address_of
from ..pump import CLOSE_WAIT_S, ConnectionPump, run_connection
from .channel import INBOX_LIMIT_BYTES, MAX_TEXT_FRAME_BYTES, DataChannelChannel
from .ice import parse_ice_servers
from .native import Inflow, NativeDataChannel, NativePeerConnection
from .native_video import VideoPlan, native_video_plan, prepare_native_tracks
from .offer import OfferError, check_offer
from .reactor import ReactorPeerConnection
from .sctp import (
    ANSWER_MAX_MESSAGE_SIZE,
    SctpBound,
    bound_sctp,
    incoming_message_limit,
)
from .signalling import WEBRTC_PATH, Answer, WebRtcOptions, WebRtcSignalling
from .video import WebRtcVideo

if TYPE_CHECKING:
    from aiortc import RTCSctpTransport
    from anyio.abc import TaskGroup

    from rwt_protocol.runtime.contract import ServerSession

    from ..frontends import ChannelLabel, FrontEnd, FrontEnds
    from ..host import Admitted, FrontEndHost
    from .channel import AnyDataChannel
    from .offer import OfferShape
    from .signalling import VideoRequest
    from .video import VideoBinding

__all__ = [
    "LOSSY_MAX_RETRANSMITS",
    "MAX_CONNECTING",
    "OFFER_TIMEOUT_S",
    "WebRtcPeers",
    "channel_refusal",
    "webrtc_endpoint",
]

logger = logging.getLogger("rwt.webrtc")

MAX_CONNECTING = 16
"""Offers being answered plus peers not yet connected, over the server; more get 503."""

OFFER_TIMEOUT_S = 10.0
"""Seconds answering one offer (ICE gathering) may take; then 503."""

LOSSY_MAX_RETRANSMITS = 1
"""The most ``maxRetransmits`` a lossy channel may ask for (D73; 0 or 1, rwt's roslib
transport asks for 1): each send of a message that is lost leaves a gap only a FORWARD
TSN closes, one gap a round trip in libwebrtc's SCTP, fewer than a 1 kHz topic opens
on a 2 % loss link; a message sent again once closes its gap itself."""

_NO_DATA_CHANNEL = "the offer has no data channel (m=application) and asks for no video"
_MAX_MESSAGE_SIZE = re.compile(r"^a=max-message-size:(\d+)\s*$", re.MULTILINE)


def channel_refusal(
    frontends: FrontEnds,
    label: str,
    ordered: bool,
    max_retransmits: int | None,
    max_lifetime: float | None,
) -> str | None:
    """Why a data channel the peer opened is closed (None: it is taken).

    Its label must be one the registry names (``frontends.by_label``): a front end's
    reliable label must come on a reliable, ordered channel, its lossy one on an
    unordered channel with ``maxRetransmits`` 0 or 1 (D36, D73:
    ``LOSSY_MAX_RETRANSMITS``) and no packet lifetime. (A second channel of a label
    is refused too, by its peer connection.) Safe on libdatachannel's threads.

    Args:
        frontends: the server's front ends (the one registry).
        label: the channel's label.
        ordered: its messages arrive in order (RFC 8832's open message).
        max_retransmits: how often a message is sent again; None: until it arrives.
        max_lifetime: how long a message is sent again, seconds; None: no bound.

    Returns:
        None, or the reason for the log: ``unknown label (served: rosbridge,
        rosbridge-lossy)``, ``not_unordered_unreliable``, ``not_reliable_ordered``.
    """
    chosen = frontends.by_label(label)
    if chosen is None:
        return f"unknown label (served: {', '.join(frontends.labels()) or 'none'})"
    if chosen.lossy:
        lossy = (
            not ordered
            and max_retransmits is not None
            and 0 <= max_retransmits <= LOSSY_MAX_RETRANSMITS
            and max_lifetime is None
        )
        return None if lossy else "not_unordered_unreliable"
    reliable = max_retransmits is None and max_lifetime is None
    return None if ordered and reliable else "not_reliable_ordered"


def remote_max_message_size(sdp: str) -> int:
    """The largest message the peer accepts: its ``a=max-message-size`` (0: any size).

    Without the attribute, 64 KiB (RFC 8841 6.1).
    """
    found = _MAX_MESSAGE_SIZE.search(sdp)
    return int(found.group(1)) if found else MAX_TEXT_FRAME_BYTES


@dataclass(eq=False)
class _Peer:
    """One peer connection: its ticket, and the session its data channels carry once open."""

    session_id: str
    pc: RTCPeerConnection | NativePeerConnection | ReactorPeerConnection
    ticket: Admitted
    """Its slot of the server's connection budget (``FrontEndHost.admit``), from the offer."""
    authenticated: bool
    """The offer carried a live bearer token (its sessions start authenticated)."""
    remote_max: int
    dc: DataChannelChannel
    session: ServerSession | None = None
    """Opened on the ticket by the first data channel of a registered label; None before
    (and for ever, video only)."""
    frontend: FrontEnd | None = None
    """The protocol its session speaks (its first channel's label chose it)."""
    ready: anyio.Event = field(default_factory=anyio.Event)
    data: bool = True
    """It carries data channels (an SCTP association); False: video only."""
    channel: AnyDataChannel | None = None
    lossy: AnyDataChannel | None = None
    running: bool = False
    scope: anyio.CancelScope = field(default_factory=anyio.CancelScope)
    wake: list[ConnectionPump] = field(default_factory=list)
    video: VideoBinding | None = None
    host: str | None = None
    """The host whose connecting slot it holds (``WebRtcPeers``); None once connected."""

    @property
    def client_id(self) -> str:
        """Its id in logs: its ticket's, which its session takes."""
        return self.ticket.client_id

    @property
    def pumped(self) -> bool:
        """Its session runs on the pump (a data channel open), so it ends by ``request_close``."""
        return self.running and self.channel is not None and self.session is not None

    def on_output(self) -> None:
        """The session's output callback: the pump's, once the data channel opened."""
        if self.wake:
            self.wake[0].wake()


class WebRtcPeers:
    """Answers offers and runs each peer's session until it ends.

    Args:
        host: admits the peers (``admit``), makes their sessions
            (``open_session``) and names the protocols of their channels
            (``frontends``, the one registry).
        options: the WebRTC settings.
        max_message_size: the largest incoming message, bytes (``--max-message-size``).
        video: the video tracks' streams (``?video=``); None: an offer asking for
            video gets 501.

    Call ``bind`` with the task group the sessions run in before the first offer.
    """

    def __init__(
        self,
        host: FrontEndHost,
        options: WebRtcOptions,
        max_message_size: int,
        video: WebRtcVideo | None = None,
    ) -> None:
        self.host = host
        self.video = video
        self.options = options
        self.max_message_size = incoming_message_limit(max_message_size)
        self.ice_servers = parse_ice_servers(options.ice_servers)
        self.hosts = host.host_prefixes
        self.peers: dict[str, _Peer] = {}
        self.connecting = 0
        """Offers being answered plus peers whose data channel is not open yet."""
        self._shares = HostShares(MAX_CONNECTING)  # the free slots bound each host (D37)
        self._refusals = EpisodeLog(logger)
        self._tg: TaskGroup | None = None

    def bind(self, tg: TaskGroup | None) -> None:
        """Run sessions in ``tg`` (the server's connections); None: take no offers."""
        self._tg = tg
        if self.video is not None:
            self.video.bind(tg)

    async def offer(
        self, sdp: str, peer: str, *, authenticated: bool, video: VideoRequest | None = None
    ) -> Answer:
        """Admit and answer an offer, with the video tracks ``video`` asks for.

        The offer is checked first (``webrtc.offer.check_offer``, D38), then it
        takes a connecting slot of its host's share (D37), which its peer holds
        until it connects.

        Returns:
            201 with the answer SDP and the session's path; 400 (the offer is not
            usable SDP or passes its bounds, has neither a data channel nor video, or
            cannot be answered), 503 (server full, too many peers connecting or too
            many of its host's, stopping, or answering took over
            ``OFFER_TIMEOUT_S``); for video, ``WebRtcVideo.binding``'s and
            ``VideoBinding.negotiate``'s refusals.
        """
        if self._tg is None:
            return Answer(503, "the server is not serving")
        try:  # before anything is held or built (D38)
            shape = check_offer(sdp)
        except OfferError as exc:
            return Answer(400, str(exc))
        if not shape.data_channel and not (video and video.topics):
            return Answer(400, _NO_DATA_CHANNEL)
        host = self.hosts.host(address_of(peer))
        if not self._take_slot(host):
            return Answer(503, "too many WebRTC peers connecting: try again later")
        answer = Answer(503, "the server is stopping")
        try:
            binding = self._video_binding(video, peer)
            if isinstance(binding, Answer):
                answer = binding
            else:
                stack, plan = self._plan(shape, sdp, binding)
                answer = await self._answer(
                    sdp, peer, host, authenticated, binding, (stack, plan), shape.data_channel
                )
            return answer
        finally:
            if answer.status != 201:  # refused: else its peer holds the slot until it connects
                self._free_slot(host)

    def _plan(
        self, shape: OfferShape, sdp: str, video: VideoBinding | None
    ) -> tuple[str, VideoPlan | None]:
        """Which stack answers this offer, and the native stack's media sections (D51, D70).

        An offer of data channels only (no media section): the chosen stack
        (``WebRtcOptions.data_stack``). One asking for video tracks: libdatachannel
        where ``WebRtcOptions.native`` and it can send them (``native_video_plan``).
        Any other offer stays on aiortc: an audio or video section without
        ``?video=``, or an offer aiortc refuses.

        Returns:
            (``reactor``, ``native`` or ``aiortc``; the native stack's plan, else None).
        """
        if video is None:
            if set(shape.kinds) != {"application"}:
                return "aiortc", None
            stack = self.options.data_stack
            return stack, (VideoPlan() if stack == "native" else None)
        plan = native_video_plan(sdp, len(video.tracks)) if self.options.native else None
        return ("aiortc", None) if plan is None else ("native", plan)

    def _take_slot(self, host: str) -> bool:
        """Take a connecting slot for ``host``; False when there is none for it (D37).

        Fewer than ``MAX_CONNECTING`` must be taken, and past three quarters of
        them ``host`` must hold fewer than are free (``admission.shares.HostShares``).
        """
        taken = self.connecting
        if taken >= MAX_CONNECTING or not self._shares.admits(host, taken, MAX_CONNECTING):
            self._refusals.log(
                logging.WARNING,
                f"connecting:{host}",
                "event=refused transport=webrtc host=%s reason='peers connecting' held=%d "
                "connecting=%d",
                host,
                self._shares.held(host),
                taken,
            )
            return False
        self.connecting += 1
        self._shares.add(host)
        return True

    def _free_slot(self, host: str) -> None:
        self.connecting -= 1
        self._shares.remove(host)

    def _release(self, item: _Peer) -> None:
        """``item`` connected or ended: its connecting slot is free."""
        if item.host is not None:
            self._free_slot(item.host)
            item.host = None

    def _video_binding(self, video: VideoRequest | None, peer: str) -> VideoBinding | Answer | None:
        """The tracks ``video`` asks for (None: none), or why not (video.py)."""
        if video is None or not video.topics:
            return None
        if self.video is None:
            return Answer(501, "this server sends no video tracks")
        return self.video.binding(video, f"webrtc:{peer}")

    async def _answer(
        self,
        sdp: str,
        peer: str,
        host: str,
        authenticated: bool,
        video: VideoBinding | None,
        chosen: tuple[str, VideoPlan | None],
        data: bool,
    ) -> Answer:
        """Admit the peer (a ticket), answer the offer, start its run.

        ``chosen``: the stack that answers and the native stack's video sections
        (``_plan``). ``data``: the offer has a data channel.
        """
        ticket = self.host.admit("webrtc", peer)
        if ticket is None:
            return Answer(503, "too many connections")
        remote_max = remote_max_message_size(sdp)
        dc = DataChannelChannel(None, self.max_message_size, remote_max)
        stack, plan = chosen
        pc = self._peer_connection(stack, dc, authenticated, plan)
        item = _Peer(secrets.token_urlsafe(16), pc, ticket, authenticated, remote_max, dc)
        item.video = video
        pc.on("datachannel", lambda channel: self._on_channel(item, channel))
        pc.on("connectionstatechange", lambda: self._on_state(item))
        refusal: Answer | None = Answer(503, "answering the offer took too long")
        answer: str | None = None
        try:
            with anyio.move_on_after(OFFER_TIMEOUT_S):
                if isinstance(pc, NativePeerConnection):
                    item.data = data
                    refusal, answer = await self._negotiate_native(
                        pc, sdp, video, plan or VideoPlan()
                    )
                elif isinstance(pc, ReactorPeerConnection):
                    refusal, answer = await _negotiate_reactor(pc, sdp)
                else:
                    refusal, answer = await self._negotiate(item, pc, sdp)
        finally:  # refused, failed or cancelled (shutdown): the ticket and the sockets go
            if refusal is not None or answer is None or self._tg is None:
                self._end(item)
                await _close_pc(pc)
        if refusal is not None or answer is None or self._tg is None:
            return refusal or Answer(503, "the server is stopping")
        item.host = host  # its connecting slot, until it connects (_release)
        self.peers[item.session_id] = item
        self._tg.start_soon(self._run, item)
        return Answer(201, answer, f"{WEBRTC_PATH}/{item.session_id}")

    def _end(self, item: _Peer) -> None:
        """Free what ``item`` holds of the server: its session, its ticket, its video."""
        if item.session is not None:
            item.session.close()
        self.host.release(item.ticket)  # none if its session took it
        if item.video is not None:
            item.video.close()

    def _peer_connection(
        self, stack: str, dc: DataChannelChannel, authenticated: bool, plan: VideoPlan | None
    ) -> RTCPeerConnection | NativePeerConnection | ReactorPeerConnection:
        """``stack``'s peer connection for ``dc`` (aiortc's, ``_native_pc``'s)."""
        if stack == "aiortc":
            return RTCPeerConnection(self._configuration())
        return self._native_pc(dc, authenticated, tracks=bool(plan and plan.tracks), stack=stack)

    def _native_pc(
        self, dc: DataChannelChannel, authenticated: bool, *, tracks: bool, stack: str
    ) -> NativePeerConnection | ReactorPeerConnection:
        """A libdatachannel (D51) or libwebrtc (D70) peer connection for ``dc``.

        Its messages waiting for the loop count in ``dc``'s inbox bound. Its channels
        are judged on the stack's thread, before they have callbacks (closing
        one from the loop ends its peer connection): the registry's labels
        (``channel_refusal``), and one protocol a peer, its first channel's.
        """
        inflow = Inflow(INBOX_LIMIT_BYTES, lambda: dc.inbox_bytes)
        dc.held_below = lambda: inflow.pending
        frontends = self.host.frontends
        first: list[FrontEnd] = []  # the protocol the first channel chose (that thread's)

        def refusal(
            label: str, ordered: bool, retransmits: int | None, lifetime: float | None
        ) -> str | None:
            reason = channel_refusal(frontends, label, ordered, retransmits, lifetime)
            chosen = frontends.by_label(label)
            if reason is None and chosen is not None:
                reason = self._refusal(chosen, first[0] if first else None, authenticated)
                if reason is None and not first:
                    first.append(chosen.frontend)
            return reason

        if stack == "reactor":
            return ReactorPeerConnection(self.ice_servers, self.max_message_size, inflow, refusal)
        return NativePeerConnection(
            self.ice_servers,
            self.max_message_size,
            inflow,
            ANSWER_MAX_MESSAGE_SIZE,
            refusal,
            tracks=tracks,
        )

    @staticmethod
    async def _negotiate_native(
        pc: NativePeerConnection,
        sdp: str,
        video: VideoBinding | None,
        plan: VideoPlan,
    ) -> tuple[Answer | None, str]:
        """Answer with libdatachannel, its tracks sending ``plan``'s sections.

        Returns:
            (None, the answer SDP), or (why not, "").
        """
        try:
            offered = pc.set_offer(sdp)
        except ValueError as exc:
            return Answer(400, f"the offer is not a usable SDP offer: {exc}"), ""
        if video is not None and plan.tracks:
            loop = asyncio.get_running_loop()
            try:
                refusal = prepare_native_tracks(video, offered, plan, loop)
            except (RuntimeError, ValueError, TypeError) as exc:  # the binding's C++ errors
                return Answer(400, f"the offer cannot be answered: {exc}"), ""
            if refusal is not None:
                return refusal, ""
        try:
            return None, await pc.local_answer()
        except ValueError as exc:
            return Answer(400, f"the offer cannot be answered: {exc}"), ""

    async def _negotiate(
        self, item: _Peer, pc: RTCPeerConnection, sdp: str
    ) -> tuple[Answer | None, str | None]:
        """Set the offer and the answer (gathering every candidate); None when it worked.

        The peer's SCTP transport is bounded before it starts (sctp.py);
        its video tracks are bound to the offer's transceivers before the answer
        and their codecs checked after it (their streams start when it connects).

        Returns:
            (None, the answer SDP), or (why not, None).
        """
        video = item.video
        try:
            await pc.setRemoteDescription(RTCSessionDescription(sdp=sdp, type="offer"))
        except Exception as exc:  # aiortc raises ValueError and others for a bad offer
            reason = exc or type(exc).__name__
            return Answer(400, f"the offer is not a usable SDP offer: {reason}"), None
        item.data = pc.sctp is not None
        if pc.sctp is not None:
            self._bound_sctp(item, pc.sctp)
        if video is not None and (refusal := video.prepare(pc, sdp)) is not None:
            return refusal, None
        if pc.sctp is None and video is None:
            return Answer(400, _NO_DATA_CHANNEL), None
        try:
            await pc.setLocalDescription(await pc.createAnswer())
        except Exception as exc:  # an offer aiortc accepted but cannot answer
            return Answer(400, f"the offer cannot be answered: {exc or type(exc).__name__}"), None
        refusal = video.negotiate(pc) if video is not None else None
        local = pc.localDescription
        return refusal, None if local is None else local.sdp

    def _bound_sctp(self, item: _Peer, transport: RTCSctpTransport) -> None:
        """Bound what ``item``'s SCTP holds below its session (D39, sctp.py)."""
        bound = SctpBound(
            self.max_message_size,
            INBOX_LIMIT_BYTES,
            lambda: item.dc.inbox_bytes,
            lambda stream_id: self._on_oversized(item, stream_id),
            lambda: self._on_overflow(item),
        )
        bound_sctp(transport, bound)
        item.dc.held_below = lambda: bound.held_bytes

    @staticmethod
    def _on_oversized(item: _Peer, stream_id: int) -> None:
        """A message over the size was abandoned as it arrived: tell the session."""
        if any(c is not None and c.id == stream_id for c in (item.channel, item.lossy)):
            item.dc.oversized()

    @staticmethod
    def _on_overflow(item: _Peer) -> None:
        """The peer sent more than its session may hold: it is disconnected."""
        item.dc.overflow()
        if not item.pumped:
            item.scope.cancel()

    def _configuration(self) -> RTCConfiguration:
        """A peer connection's ICE servers: ``--ice-server``'s, or none.

        None at all (not aiortc's default, a public STUN server) without
        ``--ice-server``: the server then sends nothing to any other host.
        """
        servers = [
            RTCIceServer(urls=s.url, username=s.username, credential=s.credential)
            for s in self.ice_servers
        ]
        return RTCConfiguration(iceServers=servers)

    def _on_channel(self, item: _Peer, channel: AnyDataChannel) -> None:
        """Take a channel of a registered label: the first opens the session (module text).

        One reliable channel and one lossy one (unordered, ``maxRetransmits`` 0 or 1,
        D36, D73), of one front end; any other channel is closed, the reason logged. A
        native channel reports the inbox bounds itself (native.py): a
        message over the size, or past the bound.
        """
        if isinstance(channel, NativeDataChannel):
            channel.on("oversized", item.dc.oversized)
            channel.on("overflow", lambda: self._on_overflow(item))
        frontends = self.host.frontends
        label = channel.label
        refusal = channel_refusal(
            frontends, label, channel.ordered, channel.maxRetransmits, channel.maxPacketLifeTime
        )
        chosen = frontends.by_label(label)
        if refusal is None and chosen is not None:
            refusal = self._taken(item, chosen)
        if refusal is not None or chosen is None:
            self._refused(item, channel, refusal or "unknown label")
            return
        if item.session is None and not self._open(item, chosen.frontend):
            self._refused(item, channel, "the server is full or stopping")
            item.scope.cancel()
            return
        if chosen.lossy:
            self._on_lossy(item, channel)
            return
        item.channel = channel
        item.dc.attach(channel)  # its messages wait for the session from now on
        if channel.readyState == "open":
            item.ready.set()
        else:
            channel.on("open", item.ready.set)

    def _taken(self, item: _Peer, chosen: ChannelLabel) -> str | None:
        """Why a channel of a registered label is not taken by ``item`` (None: it is)."""
        refusal = self._refusal(chosen, item.frontend, item.authenticated)
        if refusal is None and (item.lossy if chosen.lossy else item.channel) is not None:
            refusal = "second"
        return refusal

    def _refusal(
        self, chosen: ChannelLabel, frontend: FrontEnd | None, authenticated: bool
    ) -> str | None:
        """Why a peer whose session speaks ``frontend`` (None: none yet) refuses ``chosen``.

        One protocol a peer; a front end whose clients prove who they are with the
        request (``AuthMode.at_entry``) only when the offer carried the bearer token.
        """
        if frontend is not None and chosen.frontend is not frontend:
            return f"another protocol than the session's ({frontend.name})"
        if self.host.entry.required and chosen.frontend.auth.at_entry and not authenticated:
            return f"{chosen.frontend.name} needs the offer's bearer token"
        return None

    def _open(self, item: _Peer, frontend: FrontEnd) -> bool:
        """Open ``item``'s session on its ticket for ``frontend``; False: it was refused."""
        session = self.host.open_session(
            "webrtc",
            item.ticket.peer,
            item.on_output,
            frontend=frontend,
            authenticated=item.authenticated,
            ticket=item.ticket,
        )
        if session is None:
            return False
        item.session, item.frontend = session, frontend
        item.dc.charge_to(session.memory)  # what waits for it is the connection's (D44)
        item.dc.split_text = frontend.split_text  # a text frame too large: its front end's
        return True

    @staticmethod
    def _refused(item: _Peer, channel: AnyDataChannel, reason: str) -> None:
        logger.info(
            "event=channel_refused client=%s label=%r reason=%s",
            item.client_id,
            channel.label[:64],
            reason,
        )
        channel.close()

    def _on_lossy(self, item: _Peer, channel: AnyDataChannel) -> None:
        """Take a lossy channel, opening the session's lossy lane (D36).

        Its messages go to the session as any; the subscriptions made on it get
        their messages there.
        """
        session = item.session
        assert session is not None  # opened by the caller
        if not isinstance(session, LossySession):  # its protocol sends on one way only
            self._refused(item, channel, "no lossy lane in its protocol")
            return
        item.lossy = channel
        item.dc.attach_lossy(channel)
        session.open_lossy_lane(item.remote_max, item.dc.lossy_ready)
        # closed: its subscriptions' next messages go on the reliable channel at once
        channel.on("close", session.close_lossy_lane)
        logger.info(
            "event=lossy_channel client=%s max_message_bytes=%d",
            item.client_id,
            item.remote_max,
        )

    def _on_state(self, item: _Peer) -> None:
        """A failed or closed peer connection ends its session."""
        if item.pc.connectionState == "connected" and not item.data:
            item.ready.set()  # video only: connected is all it waits for
        if item.pc.connectionState in ("failed", "closed"):
            item.ready.set()
            if item.pumped and item.session is not None:
                item.session.request_close(CloseCode.GOING_AWAY, "peer connection closed")
            else:
                item.scope.cancel()

    async def _run(self, item: _Peer) -> None:
        """Wait for a data channel, run its session on the pump, then free everything."""
        try:
            with item.scope:
                with anyio.move_on_after(self.options.connect_timeout_s):
                    await item.ready.wait()
                if not item.data:
                    await self._run_video_only(item)
                    return
                channel, session = item.channel, item.session
                if channel is None or session is None or channel.readyState != "open":
                    self._not_connected(item)
                    return
                if not self._connected(item):
                    return
                pump = ConnectionPump(item.dc, self.host.flow, self.host.admission)
                item.wake.append(pump)
                item.running = True
                await run_connection(pump, session, f"webrtc={item.session_id}")
        finally:
            self._release(item)
            self.peers.pop(item.session_id, None)
            self._end(item)
            await _close_pc(item.pc)

    def _connected(self, item: _Peer) -> bool:
        """``item`` connected: its connecting slot is free, its video streams start (D37).

        False when a stream cannot start (the streams' bound reached since the
        answer): the peer connection is then ended.
        """
        self._release(item)
        reason = item.video.start() if item.video is not None else None
        if reason is not None:
            self._refusals.log(
                logging.WARNING,
                "webrtc_video_refused",
                "event=webrtc_video_refused client=%s reason=%r: peer connection closed",
                item.client_id,
                reason,
            )
        return reason is None

    @staticmethod
    def _not_connected(item: _Peer) -> None:
        logger.info(
            "event=webrtc_not_connected client=%s state=%s",
            item.client_id,
            item.pc.connectionState,
        )

    async def _run_video_only(self, item: _Peer) -> None:
        """A peer with video and no data channel: on its ticket, as long as its peer connection."""
        if item.pc.connectionState != "connected":
            self._not_connected(item)
            return
        if not self._connected(item):
            return
        item.running = True
        logger.info(
            "event=connect client=%s transport=webrtc protocol=video peer=%s webrtc=%s stack=%s",
            item.client_id,
            item.ticket.peer,
            item.session_id,
            _stack_of(item.pc),
        )
        await anyio.sleep_forever()  # until failed, closed, DELETE or shutdown cancels it

    def delete(self, session_id: str) -> bool:
        """End the session ``session_id`` (``DELETE /webrtc/<id>``); False if there is none."""
        item = self.peers.get(session_id)
        if item is None:
            return False
        if item.pumped and item.session is not None:
            item.session.request_close(CloseCode.NORMAL, "ended by DELETE")
        else:
            item.scope.cancel()
        return True

    def stop_connecting(self) -> None:
        """Free the peers that are not connected yet, and video-only ones (server stopping)."""
        for item in list(self.peers.values()):
            if not item.pumped:
                item.scope.cancel()


def _stack_of(pc: RTCPeerConnection | NativePeerConnection | ReactorPeerConnection) -> str:
    """The name of the stack ``pc`` is of, for the logs (``--webrtc-stack``'s names)."""
    if isinstance(pc, ReactorPeerConnection):
        return "reactor"
    return "native" if isinstance(pc, NativePeerConnection) else "aiortc"


async def _negotiate_reactor(pc: ReactorPeerConnection, sdp: str) -> tuple[Answer | None, str]:
    """Answer with libwebrtc (reactor.py): (None, the answer SDP), or (why not, "")."""
    try:
        return None, await pc.answer(sdp)
    except ValueError as exc:
        return Answer(400, f"the offer is not a usable SDP offer: {exc}"), ""


async def _close_pc(pc: RTCPeerConnection | NativePeerConnection | ReactorPeerConnection) -> None:
    """Close a peer connection, within ``CLOSE_WAIT_S`` even while cancelled."""
    with anyio.CancelScope(shield=True), anyio.move_on_after(CLOSE_WAIT_S):
        await pc.close()


def webrtc_endpoint(host: FrontEndHost, options: object) -> WebRtcSignalling:
    """WebRTC signalling of ``host``, its peers and their video (``frontends_registry.WEBRTC``).

    Raises:
        ConfigError: ``options`` is not a ``WebRtcOptions``.
        ImportError: aiortc is not installed (``rwt-rosbridge[webrtc]``).
    """
    if not isinstance(options, WebRtcOptions):
        raise ConfigError(f"WebRTC's options must be WebRtcOptions, not {type(options).__name__}")
    video = WebRtcVideo(host.graph, host.rules.access)
    peers = WebRtcPeers(host, options, host.settings.max_message_size, video)
    entry = host.entry
    if options.bearer_token is not None:  # its own check of the tokens, set by embedding code
        entry = replace(entry, token=options.bearer_token)
    return WebRtcSignalling(peers, options, host.settings.allowed_origins, entry=entry)
