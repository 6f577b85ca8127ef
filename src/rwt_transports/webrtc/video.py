"""WebRTC video tracks: image topics sent as VP8 or H.264 to any WHEP player (docs/webrtc.md).

``POST /webrtc?video=/camera/image`` binds the offer's receiving video
transceivers, in order, to image topics; the answer sends on them (``sendonly``,
with aiortc's ``a=msid``) in the first codec of the offer's list that aiortc
has (VP8 or H.264). Audio transceivers stay inactive.

Encoding once per topic and codec. aiortc 1.16's ``RTCRtpSender`` reads its
track's ``recv()``: an ``av.VideoFrame`` it encodes with an encoder of its own
(one per sender, so one per peer), an ``av.Packet`` it only cuts into RTP
packets (``Encoder.pack``). aiortc's ``MediaRelay`` relays decoded frames, which
each sender would encode again. So a ``VideoTrack`` yields packets: the frames
one shared stream (``rwt_video.hub.StreamHub`` with ``rwt_video.rtp``'s
encoders) encoded for every peer of that topic and codec, the stream starting
with the first viewer to connect (never at the answer: an offer that never
connects runs no encoder, D37) and stopping with the last.

Feedback. The sender handles RTCP itself: a PLI or FIR sets its own encoder's
key-frame flag, a REMB its own encoder's bit rate, neither of which exists for
packets. Each track therefore wraps its sender's RTCP handler
(``_handle_rtcp_packet``, aiortc's one hook for it) to pass them on to the
shared encoder first: a key frame (at most one per
``rtp.KEYFRAME_MIN_INTERVAL_S``), and the lowest estimate of the stream's
peers as its bit rate. aiortc then handles the packet as before (NACKs,
reports).

A slow peer drops frames, never queues them: a track holds one frame; a frame
arriving before the peer took the last one replaces it, and since the next
frames refer to the dropped one, the track waits for a key frame (and asks for
one) before sending again.
"""

from __future__ import annotations

import contextlib
import fractions
import logging
import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Self

import anyio
import av
from aiortc import MediaStreamTrack
from aiortc.mediastreams import MediaStreamError
from aiortc.rtp import RTCP_PSFB_APP, RTCP_PSFB_FIR, RTCP_PSFB_PLI, RtcpPsfbPacket, unpack_remb_fci
from aiortc.sdp import SessionDescription

from rwt_protocol.errors import RwtError
from rwt_protocol.names import resolve_name
from rwt_protocol.runtime.access import AccessDeniedError, Family, TopicUse, gate
from rwt_video.encoders import VideoPacket
from rwt_video.hub import StreamHub
from rwt_video.params import StreamParamError, StreamParams, StreamType, parse_stream_params
from rwt_video.rtp import RtpFrameEncoder, make_rtp_encoder

from .signalling import Answer

if TYPE_CHECKING:
    from collections.abc import Callable, Coroutine, Sequence

    from aiortc import RTCPeerConnection, RTCRtpSender
    from aiortc.rtp import AnyRtcpPacket
    from anyio.abc import TaskGroup

    from rwt_graph.graph import Graph
    from rwt_protocol.runtime.access import AccessPolicy
    from rwt_video.encoders import Part
    from rwt_video.hub import SharedStream

    from .signalling import VideoRequest

__all__ = [
    "DEFAULT_BITRATE",
    "MAX_VIDEO_STREAMS",
    "VIDEO_NODE",
    "FrameFeed",
    "VideoBinding",
    "VideoTrack",
    "WebRtcVideo",
]

logger = logging.getLogger("rwt.webrtc")

DEFAULT_BITRATE = 1_000_000
"""A video track's highest bit rate without a ``bitrate`` parameter, bit/s (the
receivers' estimates lower it; the HTTP streams' default, 100 kbit/s, is too low
for a 640x480 camera)."""

MAX_VIDEO_STREAMS = 16
"""Distinct video streams (topic, codec and parameters: one encoder each) at once over
the server's WebRTC peers; an offer for another one gets 503."""

VIDEO_NODE = "/rwt_webrtc_video"
"""The node the video tracks' streams subscribe as (rosapi lists it on their topics)."""

_MS = fractions.Fraction(1, 1000)
_IMAGE = "sensor_msgs/msg/Image"
_COMPRESSED = "sensor_msgs/msg/CompressedImage"
_CODECS = {"video/vp8": StreamType.VP8, "video/h264": StreamType.H264}


class FrameFeed:
    """One peer's track of a shared stream, whatever the stack sends it with.

    What both stacks' tracks share: the stream they are bound to, the key frame
    they wait for after a drop, and the feedback they pass on to the shared
    encoder (a PLI or FIR: a key frame; a REMB: the stream's rate is its peers'
    lowest estimate).

    Args:
        params: the stream asked for (its ``type`` is set by the negotiated codec).
        type_name: the topic's type.

    Attributes:
        sent: frames handed to the peer's stack.
        dropped: frames dropped because the peer had not taken the one before.
        remb: the peer's last receiver estimate, bit/s (None before one).
    """

    def __init__(self, params: StreamParams, type_name: str) -> None:
        self.params = params
        self.type_name = type_name
        self.stream: SharedStream | None = None
        self.sent = 0
        self.dropped = 0
        self.remb: int | None = None
        self._waiting_for_keyframe = True

    def bind(self, stream: SharedStream) -> Self:
        """Take frames from ``stream`` (``StreamHub.watching``'s ``make_viewer``)."""
        self.stream = stream
        return self

    def offer(self, items: list[Part] | list[VideoPacket]) -> None:
        """The stream's newest frames: each goes to ``deliver`` from a key frame on."""
        for packet in items:
            if isinstance(packet, VideoPacket):
                self._take(packet)

    def _take(self, packet: VideoPacket) -> None:
        if self._waiting_for_keyframe and not packet.keyframe:
            return
        self._waiting_for_keyframe = False
        self.deliver(packet)

    def deliver(self, packet: VideoPacket) -> None:
        """Hand one frame to the peer's stack; must not block (a stack's own)."""
        raise NotImplementedError

    def resync(self) -> None:
        """A frame was dropped: wait for a key frame, and ask for one."""
        self.dropped += 1
        self._waiting_for_keyframe = True
        self.request_keyframe()

    def stop(self) -> None:
        """End the track: nothing more is sent to its peer."""

    def request_keyframe(self) -> None:
        """Ask the shared encoder for a key frame (a PLI or FIR, or this peer resuming)."""
        if self.stream is not None:
            self.stream.request_keyframe()

    def on_remb(self, bitrate: int) -> None:
        """The peer's estimate (REMB): the stream's rate is its peers' lowest."""
        self.remb = bitrate
        stream = self.stream
        if stream is None or not isinstance(stream.encoder, RtpFrameEncoder):
            return
        estimates = [v.remb for v in stream.viewers if isinstance(v, FrameFeed) and v.remb]
        stream.encoder.set_bitrate(min(estimates, default=bitrate))


class VideoTrack(MediaStreamTrack, FrameFeed):
    """One peer's aiortc video track of a shared stream: yields its encoded frames as packets.

    Args:
        params: the stream asked for (its ``type`` is set by the negotiated codec).
        type_name: the topic's type.
    """

    kind = "video"

    def __init__(self, params: StreamParams, type_name: str) -> None:
        MediaStreamTrack.__init__(self)
        FrameFeed.__init__(self, params, type_name)
        self._pending: VideoPacket | None = None
        self._ready = anyio.Event()

    def offer(self, items: list[Part] | list[VideoPacket]) -> None:
        """Keep the newest frame; one the peer did not take yet is dropped (never queued)."""
        for packet in items:
            if not isinstance(packet, VideoPacket):
                continue
            if self._pending is not None:  # the peer is behind: drop, resume at a key frame
                self._pending = None
                self.resync()
            self._take(packet)

    def deliver(self, packet: VideoPacket) -> None:
        """Hold ``packet`` until the sender takes it (``recv``)."""
        self._pending = packet
        self._ready.set()

    async def recv(self) -> av.Packet[Any]:
        """The next frame as an ``av.Packet`` (pts in ms), for the sender to packetize.

        Raises:
            MediaStreamError: the track ended.
        """
        while self._pending is None:
            if self.readyState != "live":
                raise MediaStreamError
            await self._ready.wait()
            self._ready = anyio.Event()
        frame, self._pending = self._pending, None
        packet = av.Packet(frame.data)
        packet.pts = frame.pts_ms
        packet.time_base = _MS
        self.sent += 1
        return packet

    def stop(self) -> None:
        """End the track (its sender's loop then ends)."""
        super().stop()
        self._ready.set()


def _hook_rtcp(sender: RTCRtpSender, track: VideoTrack) -> None:
    """Pass ``sender``'s PLI, FIR and REMB on to the shared encoder, then to aiortc."""
    handle: Callable[[AnyRtcpPacket], Coroutine[None, None, None]] = sender._handle_rtcp_packet

    async def handle_rtcp(packet: AnyRtcpPacket) -> None:
        if isinstance(packet, RtcpPsfbPacket):
            if packet.fmt in (RTCP_PSFB_PLI, RTCP_PSFB_FIR):
                track.request_keyframe()
            elif packet.fmt == RTCP_PSFB_APP:
                with contextlib.suppress(ValueError):  # an APP packet that is not a REMB
                    bitrate, ssrcs = unpack_remb_fci(packet.fci)
                    if sender._ssrc in ssrcs:
                        track.on_remb(bitrate)
        await handle(packet)

    sender._handle_rtcp_packet = handle_rtcp  # type: ignore[method-assign]


class VideoBinding:
    """One offer's video tracks, from the offer to the end of its peer connection.

    Args:
        hub: the shared streams.
        tracks: one per ``video`` parameter, in order.
    """

    def __init__(self, hub: StreamHub, tracks: Sequence[FrameFeed]) -> None:
        self.hub = hub
        self.tracks = list(tracks)
        self._stack = contextlib.ExitStack()

    def prepare(self, pc: RTCPeerConnection, offer: str) -> Answer | None:
        """After the offer is set: give each receiving video transceiver its track, in order.

        Returns:
            None, or 400 when the offer has fewer receiving video transceivers than tracks.
        """
        receiving = []
        for media in SessionDescription.parse(offer).media:
            if media.kind == "video" and media.direction in ("recvonly", "sendrecv"):
                receiving.append(media.rtp.muxId)
        if len(self.tracks) > len(receiving):
            return Answer(
                400,
                f"{len(self.tracks)} video parameters but {len(receiving)} receiving "
                "video transceivers in the offer: one recvonly transceiver a topic",
            )
        by_mid = {t.mid: t for t in pc.getTransceivers()}
        for transceiver in by_mid.values():
            transceiver.direction = "inactive"  # audio, and video beyond the topics
        for mid, track in zip(receiving, self.tracks, strict=False):
            transceiver = by_mid[mid]
            assert isinstance(track, VideoTrack)  # aiortc answers with aiortc's tracks
            transceiver.sender.replaceTrack(track)
            transceiver.direction = "sendonly"
            _hook_rtcp(transceiver.sender, track)
        return None

    def negotiate(self, pc: RTCPeerConnection) -> Answer | None:
        """After the answer: each track's codec, and whether its stream could start.

        Nothing starts here: the streams start when the peer connects (``start``),
        so an offer that never connects runs no encoder (D37).

        Returns:
            None, or the refusal: 400 when the offer has no video codec in common or
            a compressed topic is not sent as H.264; 503 when the streams this offer
            would add pass ``max_streams`` with those running.
        """
        assert pc.localDescription is not None
        codecs = {
            media.rtp.muxId: _CODECS.get(media.rtp.codecs[0].mimeType.lower())
            for media in SessionDescription.parse(pc.localDescription.sdp).media
            if media.kind == "video" and media.rtp.codecs
        }
        by_track = {id(t.sender.track): t.mid for t in pc.getTransceivers()}
        for track in self.tracks:
            codec = codecs.get(by_track.get(id(track)) or "")
            if codec is None:
                return Answer(400, "the offer has no video codec in common: offer VP8 or H.264")
            if track.type_name == _COMPRESSED and codec is not StreamType.H264:
                return Answer(400, f"{track.params.topic} is compressed: only H.264 passes through")
            track.params = replace(track.params, type=codec)
        return self._bounded()

    def adopt(self, tracks: Sequence[FrameFeed]) -> Answer | None:
        """The native stack's tracks in place of these (native_video.py), checked.

        Returns:
            None, or 503 when the streams they would add pass ``max_streams``.
        """
        self.tracks = list(tracks)
        return self._bounded()

    def _bounded(self) -> Answer | None:
        """503 when the streams this offer would add pass ``max_streams`` with those running."""
        new = {t.params for t in self.tracks} - set(self.hub.streams)
        if new and len(self.hub.streams) + len(new) > self.hub.max_streams:
            return Answer(503, f"{self.hub.max_streams} distinct streams run already")
        return None

    def start(self) -> str | None:
        """The peer connected: start (or join) each track's stream.

        Returns:
            None, or why a stream could not start (``max_streams`` reached since
            the answer, the topic gone): the caller ends the peer connection.
        """
        try:
            for track in self.tracks:
                self._stack.enter_context(
                    self.hub.watching(track.params, track.type_name, track.bind)
                )
        except (StreamParamError, RwtError) as exc:
            self._stack.close()
            return str(exc)
        return None

    def close(self) -> None:
        """Stop the tracks and leave their streams (the last viewer stops a stream)."""
        for track in self.tracks:
            track.stop()
        self._stack.close()


class WebRtcVideo:
    """The video tracks of the server's WebRTC peers: checks offers, shares the streams.

    Args:
        graph: where the image topics are.
        access: the server's access rules; a topic they deny is refused as a
            subscription would be (``--topics-sub-glob``, D50).
        max_streams: the most distinct streams at once (``MAX_VIDEO_STREAMS``).
        encoder_threads: the most frames encoded at once; None: the image threads
            every front end shares (``hub.ENCODER_THREADS``).

    Call ``bind`` with the task group the streams' encoders run in.
    """

    def __init__(
        self,
        graph: Graph,
        access: AccessPolicy,
        max_streams: int = MAX_VIDEO_STREAMS,
        encoder_threads: int | None = None,
    ) -> None:
        self.graph = graph
        self.access = access
        self.max_streams = max_streams
        self.encoder_threads = encoder_threads
        self.hub: StreamHub | None = None

    def bind(self, tg: TaskGroup | None) -> None:
        """Run the encoders in ``tg`` (the server's connections); None: start no stream."""
        if tg is None:
            self.hub = None
            return
        self.hub = StreamHub(
            self.graph,
            tg,
            self.max_streams,
            self.encoder_threads,
            make=make_rtp_encoder,
            node=VIDEO_NODE,
        )

    def binding(self, request: VideoRequest, client: str = "webrtc") -> VideoBinding | Answer:
        """The tracks ``request`` asks for, or why not.

        A topic the access rules deny is refused through the one access gate and
        its log line (``access.gate``; ``client`` names the peer there).

        Returns:
            The binding, or 403 (a topic the access rules deny), 404 (no such
            topic), 400 (not an image topic, a bad stream parameter), 503 (not serving).
        """
        hub = self.hub
        if hub is None:
            return Answer(503, "the server is not serving")
        types = dict(self.graph.topic_names_and_types())
        tracks = []
        for name in request.topics:
            topic = resolve_name(name)
            shown = topic if len(topic) <= 80 else topic[:77] + "..."
            try:
                gate(
                    self.access,
                    Family.TOPICS,
                    topic,
                    client=client,
                    op="video",
                    use=TopicUse.SUBSCRIBE,
                    now=time.monotonic(),
                )
            except AccessDeniedError:
                return Answer(403, f"topic {shown!r} is not allowed")
            type_name = _full(types.get(topic))
            if type_name is None:
                return Answer(404, f"topic {shown!r} does not exist")
            if type_name not in (_IMAGE, _COMPRESSED):
                return Answer(400, f"topic {shown!r} is a {type_name}, not an image topic")
            query = {"bitrate": str(DEFAULT_BITRATE), **request.query}
            query |= {"topic": topic, "type": StreamType.VP8.value}  # the codec: negotiated
            try:
                params = parse_stream_params(query)
            except StreamParamError as exc:
                return Answer(400, str(exc))
            tracks.append(VideoTrack(params, type_name))
        return VideoBinding(hub, tracks)


def _full(type_name: str | None) -> str | None:
    """``sensor_msgs/Image`` (ROS 1 spelling) as ``sensor_msgs/msg/Image``."""
    if type_name is None or "/msg/" in type_name:
        return type_name
    package, _, name = type_name.partition("/")
    return f"{package}/msg/{name}"
