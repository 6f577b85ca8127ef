"""Video tracks on the native stack: sent by libdatachannel (docs/webrtc.md, D51).

Measured (``python -m benchmarks.webrtc_track_cost``), a viewer of a 30 frames/s
track costs the robot about a third of aiortc's CPU when libdatachannel protects
and sends the packets in C++. So with the native stack an offer's video is answered
by libdatachannel, its sections bound as aiortc binds them: the receiving video
sections to the topics in order, the other video sections and every audio section
inactive, and each track in the first codec of its section's list that the server
sends (VP8, or H.264 in packetization mode 1 with a Baseline profile, matched as
aiortc matches it). An offer aiortc would refuse stays on aiortc, which says why.

Each section's answer sends that one payload type, with an SSRC and a media stream
id of its own (a WHEP player shows a track only inside a stream), the MID header
extension and nothing it would not send (no retransmission payload type, no other
extension). H.264 is cut into RTP packets by libdatachannel's packetizer (Annex B
in). VP8, which libdatachannel-py does not packetize, is cut by aiortc's VP8
payloader (``Vp8Encoder.pack``, the payload descriptors aiortc's own sender makes)
into RTP packets (``aiortc.rtp.RtpPacket``) handed to the track whole. Either way
the track's chain is libdatachannel's: sender reports, a NACK responder (a lost
packet is sent again from its history) and the feedback handlers: a PLI or FIR asks
the shared encoder for a key frame and a REMB sets its rate (``FrameFeed``), as
aiortc's tracks do.

Threads (D51): the feedback handlers are called on libdatachannel's thread pool (the
DTLS transport's receiving task, which unprotects RTCP; never libjuice's polling
thread, whose lock the loop may need), as the data channels' callbacks are, so
each only sets a flag and, if none was set, hops once onto the loop
(``call_soon_threadsafe``): a flood of PLIs costs the loop one call a hop, and the
encoder gives at most one key frame per ``rtp.KEYFRAME_MIN_INTERVAL_S``. Frames are
sent from the loop (packetized, protected and written to the UDP socket at once,
nothing queued in libdatachannel), so a slow peer's frames are lost in the network as
any RTP; it asks for them again (NACK) or for a key frame to resume (PLI).
"""

from __future__ import annotations

import contextlib
import fractions
import logging
import secrets
import threading
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import av
from aiortc.codecs import CODECS
from aiortc.codecs.vpx import Vp8Encoder
from aiortc.rtcpeerconnection import find_common_codecs
from aiortc.rtcrtpparameters import RTCRtpHeaderExtensionParameters, RTCRtpParameters
from aiortc.rtp import HeaderExtensionsMap, RtpPacket
from aiortc.sdp import SessionDescription

from rwt_video.params import StreamParams, StreamType

from .signalling import Answer
from .video import FrameFeed

if TYPE_CHECKING:
    import asyncio
    from collections.abc import Sequence

    from rwt_video.encoders import VideoPacket

    from .video import VideoBinding

__all__ = [
    "NativeVideoTrack",
    "VideoPlan",
    "VideoSection",
    "Vp8Rtp",
    "native_video_plan",
    "prepare_native_tracks",
]

logger = logging.getLogger("rwt.webrtc")

_MID_URI = "urn:ietf:params:rtp-hdrext:sdes:mid"
_CNAME = "rwt"
_COMPRESSED = "sensor_msgs/msg/CompressedImage"
_CLOCK_RATE = 90_000
_MS = fractions.Fraction(1, 1000)
_CODECS = {"VP8": StreamType.VP8, "H264": StreamType.H264}


@dataclass(frozen=True)
class VideoSection:
    """One receiving video section of an offer the native stack can answer.

    Attributes:
        mid: its media id.
        codec: ``VP8`` or ``H264``.
        payload_type: the codec's payload type it will be sent in.
        mid_extension: the MID header extension's id in the offer; None: not offered.
    """

    mid: str
    codec: str
    payload_type: int
    mid_extension: int | None


def _first_sent(codecs: list[Any]) -> tuple[str, int] | None:
    """The codec aiortc's answer would send for a section offering ``codecs``, with its type.

    The first of the offer's list that aiortc has (its ``find_common_codecs`` over its
    capabilities, so an H.264 profile matches as aiortc matches it): (``VP8`` or
    ``H264``, its payload type); None: none in common.
    """
    for codec in find_common_codecs(CODECS["video"], codecs):
        name = codec.mimeType.lower()
        if name in ("video/vp8", "video/h264") and codec.payloadType is not None:
            return ("VP8" if name == "video/vp8" else "H264"), codec.payloadType
    return None


@dataclass(frozen=True)
class VideoPlan:
    """How the native stack answers an offer's audio and video sections.

    Attributes:
        sections: the sections sending a topic each, in the topics' order.
        inactive: the mids of the other audio and video sections, answered inactive.
    """

    sections: tuple[VideoSection, ...] = ()
    inactive: tuple[str, ...] = ()

    @property
    def tracks(self) -> bool:
        """The offer has audio or video sections (their answer is made by hand)."""
        return bool(self.sections or self.inactive)


def native_video_plan(offer: str, topics: int) -> VideoPlan | None:
    """How the native stack answers an offer with ``topics`` video tracks; None: aiortc.

    As aiortc's answer does (``webrtc.video.VideoBinding``), the receiving video
    sections are bound to the topics in order, and the other video sections and every
    audio section are answered inactive.

    Args:
        offer: the offer's SDP (checked already, ``webrtc.offer.check_offer``).
        topics: how many ``video`` parameters the offer came with.

    Returns:
        The plan, when every section has a mid of its own and each bound section
        a codec the server sends (the first of its list: VP8, or H.264 in mode 1
        with a Baseline profile); None when aiortc answers, or refuses, the offer
        (too few receiving video sections, no codec in common, a bad mid).
    """
    try:
        parsed = SessionDescription.parse(offer)
    except Exception:  # the offer's checks passed it; aiortc then says what is wrong
        return None
    sections: list[VideoSection] = []
    inactive: list[str] = []
    mids: set[str] = set()
    for media in parsed.media:
        mid = media.rtp.muxId
        if not mid or mid in mids:
            return None  # aiortc says what is wrong with it
        mids.add(mid)
        if media.kind == "application":
            continue
        receiving = media.kind == "video" and media.direction in ("recvonly", "sendrecv")
        if not receiving or len(sections) == topics:
            inactive.append(mid)
            continue
        sent = _first_sent(media.rtp.codecs)
        if sent is None:
            return None
        extension = next((e.id for e in media.rtp.headerExtensions if e.uri == _MID_URI), None)
        sections.append(VideoSection(mid, sent[0], sent[1], extension))
    if topics == 0 or len(sections) < topics:
        return None
    return VideoPlan(tuple(sections), tuple(inactive))


class _Feedback:
    """A track's PLI and REMB, from libdatachannel's threads to the loop: one hop at a time."""

    def __init__(self, loop: asyncio.AbstractEventLoop, track: NativeVideoTrack) -> None:
        self.loop = loop
        self.track: NativeVideoTrack | None = track
        self._lock = threading.Lock()
        self._keyframe = False
        self._bitrate: int | None = None
        self._posted = False

    def pli(self) -> None:
        """A PLI or FIR arrived (libdatachannel's thread)."""
        with self._lock:
            self._keyframe = True
            self._post()

    def remb(self, bitrate: int) -> None:
        """A REMB arrived (libdatachannel's thread), bit/s."""
        with self._lock:
            self._bitrate = bitrate
            self._post()

    def _post(self) -> None:
        if not self._posted and self.track is not None:
            self._posted = True
            with contextlib.suppress(RuntimeError):  # the loop is closed: nothing to tell
                self.loop.call_soon_threadsafe(self._deliver)

    def _deliver(self) -> None:
        """On the loop: pass what came on to the track's stream."""
        with self._lock:
            keyframe, bitrate = self._keyframe, self._bitrate
            self._keyframe, self._bitrate, self._posted = False, None, False
        track = self.track
        if track is None:
            return
        if keyframe:
            track.request_keyframe()
        if bitrate is not None:
            track.on_remb(bitrate)


class NativeVideoTrack(FrameFeed):
    """One peer's libdatachannel track of a shared stream, H.264 or VP8.

    Args:
        params: the stream (its ``type`` the section's codec).
        type_name: the topic's type.
        track: libdatachannel's ``Track`` for the section, its chain set
            (``prepare_native_tracks``, which also sets ``feedback``: where its PLIs
            and REMBs hop to the loop).
        rtp: VP8's packetizer; None: libdatachannel's H.264 packetizer is in the chain.
    """

    def __init__(
        self, params: StreamParams, type_name: str, track: Any, rtp: Vp8Rtp | None = None
    ) -> None:
        super().__init__(params, type_name)
        self.track = track
        self.rtp = rtp
        self.feedback: _Feedback | None = None

    def deliver(self, packet: VideoPacket) -> None:
        """Packetize and send ``packet`` now (on the loop; libdatachannel queues nothing)."""
        track = self.track
        if track is None or not track.is_open():
            return
        try:
            if self.rtp is None:
                info = _ldc().FrameInfo(packet.pts_ms * _CLOCK_RATE // 1000)
                track.send_frame(packet.data, info)
            else:
                for rtp_packet in self.rtp.packets(packet):
                    track.send(rtp_packet)
        except RuntimeError:  # closed under us: the peer connection's end comes next
            return
        self.sent += 1

    def stop(self) -> None:
        """Send no more, and drop the feedback's way back to this track."""
        self.track = None
        if self.feedback is not None:
            self.feedback.track = None


class Vp8Rtp:
    """A VP8 track's RTP packets: aiortc's payloader, this track's header fields.

    Args:
        ssrc: the track's SSRC.
        payload_type: VP8's payload type in the answer.
        mid: the section's mid, sent in the MID header extension when
            ``mid_extension`` (its id) is not None.
        mid_extension: the MID header extension's id; None: no extension.
    """

    def __init__(self, ssrc: int, payload_type: int, mid: str, mid_extension: int | None) -> None:
        self.ssrc = ssrc
        self.payload_type = payload_type
        self.mid = mid if mid_extension is not None else None
        self.extensions = HeaderExtensionsMap()
        if mid_extension is not None:
            self.extensions.configure(
                RTCRtpParameters(
                    headerExtensions=[RTCRtpHeaderExtensionParameters(mid_extension, _MID_URI)]
                )
            )
        self.payloader = Vp8Encoder()  # only its ``pack``: no codec is opened
        self.sequence = secrets.randbits(16)
        self.timestamp_offset = secrets.randbits(32)

    def packets(self, frame: VideoPacket) -> list[bytes]:
        """``frame`` (one encoded VP8 frame) as RTP packets, the marker bit on the last."""
        encoded = av.Packet(frame.data)
        encoded.pts = frame.pts_ms
        encoded.time_base = _MS
        payloads, timestamp = self.payloader.pack(encoded)
        out = []
        for index, payload in enumerate(payloads):
            rtp = RtpPacket(
                payload_type=self.payload_type,
                marker=int(index == len(payloads) - 1),
                sequence_number=self.sequence,
                timestamp=(timestamp + self.timestamp_offset) & 0xFFFFFFFF,
                ssrc=self.ssrc,
                payload=payload,
            )
            rtp.extensions.mid = self.mid
            out.append(rtp.serialize(self.extensions))
            self.sequence = (self.sequence + 1) & 0xFFFF
        return out


def _ldc() -> Any:
    import libdatachannel  # noqa: PLC0415 (optional: the native stack, Python 3.12+)

    return libdatachannel


def prepare_native_tracks(
    binding: VideoBinding,
    offered: Sequence[Any],
    plan: VideoPlan,
    loop: asyncio.AbstractEventLoop,
) -> Answer | None:
    """After the offer is set, before the answer: each planned section sends its topic.

    Args:
        binding: the offer's tracks (``WebRtcVideo.binding``); its tracks are
            replaced by ``NativeVideoTrack``s.
        offered: libdatachannel's tracks of the offer's media sections.
        plan: ``native_video_plan``'s: the sections sending a topic each, in order,
            and those answered inactive.
        loop: where the feedback hops to.

    Returns:
        None, or the refusal: 400 for a compressed topic not sent as H.264 (it is
        passed through), 503 when the streams this offer would add pass the hub's
        bound with those running; 400 when libdatachannel has no track for a section.

    Raises:
        RuntimeError, ValueError: libdatachannel refused a description (the caller
            answers 400).
    """
    ldc = _ldc()
    by_mid = {track.mid(): track for track in offered}
    for mid in plan.inactive:
        if (other := by_mid.get(mid)) is not None:
            media = other.description()
            media.set_direction(ldc.Description.Direction.Inactive)
            other.set_description(media)
    stream_id = secrets.token_hex(8)
    tracks: list[FrameFeed] = []
    for index, (section, asked) in enumerate(zip(plan.sections, binding.tracks, strict=True)):
        track = by_mid.get(section.mid)
        if track is None:
            return Answer(400, f"the offer cannot be answered: no track for mid {section.mid!r}")
        if asked.type_name == _COMPRESSED and section.codec != "H264":
            return Answer(400, f"{asked.params.topic} is compressed: only H.264 passes through")
        if section.payload_type not in track.description().payload_types():
            return Answer(400, f"the offer cannot be answered: no codec for mid {section.mid!r}")
        ssrc = secrets.randbits(31) + 1
        _describe(track, section, ssrc, stream_id, f"video{index}")
        params = replace(asked.params, type=_CODECS[section.codec])
        tracks.append(_chained(track, section, ssrc, params, asked.type_name, loop))
    return binding.adopt(tracks)


def _describe(track: Any, section: VideoSection, ssrc: int, stream_id: str, name: str) -> None:
    """The section's answer: its one payload type, its SSRC and stream id, the MID extension."""
    media = track.description()
    for payload_type in list(media.payload_types()):
        if payload_type != section.payload_type:
            media.remove_rtp_map(payload_type)
    for attribute in list(media.attributes()):
        if attribute.startswith(("msid:", "ssrc-group:")):  # the offer's own, reflected
            media.remove_attribute(attribute)
    for extension in list(media.ext_ids()):
        if extension != section.mid_extension:
            media.remove_ext_map(extension)
    media.clear_ssrcs()
    media.add_ssrc(ssrc, _CNAME, stream_id, name)
    track.set_description(media)


def _chained(
    track: Any,
    section: VideoSection,
    ssrc: int,
    params: StreamParams,
    type_name: str,
    loop: asyncio.AbstractEventLoop,
) -> NativeVideoTrack:
    """``track``'s handlers: packetizer (H.264), reports, NACKs, PLI and REMB."""
    ldc = _ldc()
    config = ldc.RtpPacketizationConfig(ssrc, _CNAME, section.payload_type, _CLOCK_RATE)
    if section.mid_extension is not None:
        config.mid = section.mid
        config.mid_id = section.mid_extension
    rtp = None
    if section.codec == "H264":
        track.set_media_handler(ldc.H264RtpPacketizer(ldc.NalUnit.Separator.StartSequence, config))
        track.chain_media_handler(ldc.RtcpSrReporter(config))
    else:  # the packets are made here (Vp8Rtp) and handed to the chain whole
        rtp = Vp8Rtp(ssrc, section.payload_type, section.mid, section.mid_extension)
        track.set_media_handler(ldc.RtcpSrReporter(config))
    native = NativeVideoTrack(params, type_name, track, rtp)
    feedback = native.feedback = _Feedback(loop, native)
    track.chain_media_handler(ldc.RtcpNackResponder())
    track.chain_media_handler(ldc.PliHandler(feedback.pli))
    track.chain_media_handler(ldc.RembHandler(feedback.remb))
    return native
