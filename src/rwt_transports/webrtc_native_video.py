"""Video tracks on the native stack: H.264 sent by libdatachannel (docs/webrtc.md, D51).

Measured (``python -m benchmarks.webrtc_track_cost``), a viewer of a 30 frames/s
H.264 track costs the robot about a third of aiortc's CPU when libdatachannel
packetizes and protects the frames in C++. libdatachannel-py packetizes H.264 (and
not VP8), so with the native stack an offer whose video the server would send as
H.264 is answered by libdatachannel: the offer's receiving video sections are the
topics' (one each, no audio section), and the first codec of each section's list
that the server sends (VP8, or H.264 in packetization mode 1 with a baseline
profile) is H.264. Any other offer with video stays on aiortc, as before.

Each section's answer sends that one H.264 payload type, with an SSRC and a media
stream id of its own (a WHEP player shows a track only inside a stream), the MID
header extension and nothing it would not send (no retransmission payload type,
no other extension). The track's chain is libdatachannel's: the H.264 packetizer
(Annex B in, RTP out), sender reports, a NACK responder (a lost packet is sent
again from its history) and the feedback handlers: a PLI or FIR asks the shared
encoder for a key frame and a REMB sets its rate (``FrameFeed``), as aiortc's
tracks do.

Threads (D51): the feedback handlers are called on libdatachannel's threads, so
each only sets a flag and, if none was set, hops once onto the loop
(``call_soon_threadsafe``): a flood of PLIs costs the loop one call a hop, and the
encoder gives at most one key frame per ``rtp.KEYFRAME_MIN_INTERVAL_S``. Frames are
sent from the loop (``send_frame``: packetized, protected and written to the UDP
socket at once, nothing queued in libdatachannel), so a slow peer's frames are lost
in the network as any RTP; it asks for a key frame to resume.
"""

from __future__ import annotations

import contextlib
import logging
import secrets
import threading
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from aiortc.sdp import SessionDescription

from rwt_video.params import StreamParams, StreamType

from .webrtc_signal import Answer
from .webrtc_video import FrameFeed

if TYPE_CHECKING:
    import asyncio
    from collections.abc import Sequence

    from rwt_video.encoders import VideoPacket

    from .webrtc_video import VideoBinding

__all__ = ["NativeVideoTrack", "native_video_plan", "prepare_native_tracks"]

logger = logging.getLogger("rwt.webrtc")

_MID_URI = "urn:ietf:params:rtp-hdrext:sdes:mid"
_CNAME = "rwt"
_CLOCK_RATE = 90_000
_BASELINE = ("42001f", "42e01f")
"""The H.264 profiles sent (Baseline and Constrained Baseline, level 3.1), as aiortc's:
the shared encoder's constrained baseline stream plays on either."""


@dataclass(frozen=True)
class VideoSection:
    """One receiving video section of an offer the native stack can answer.

    Attributes:
        mid: its media id.
        payload_type: the H.264 payload type it will be sent in.
        mid_extension: the MID header extension's id in the offer; None: not offered.
    """

    mid: str
    payload_type: int
    mid_extension: int | None


def _sent_codec(codec: Any) -> str | None:
    """``VP8`` or ``H264`` if the server sends ``codec`` (an aiortc ``RTCRtpCodecParameters``)."""
    name = codec.mimeType.lower()
    if name == "video/vp8":
        return "VP8"
    if name == "video/h264":
        params = codec.parameters
        mode = str(params.get("packetization-mode", "0"))
        profile = str(params.get("profile-level-id", "")).lower()
        if mode == "1" and profile in _BASELINE:
            return "H264"
    return None


def native_video_plan(offer: str, topics: int) -> list[VideoSection] | None:
    """The sections the native stack answers with H.264 tracks, or None: aiortc answers.

    Args:
        offer: the offer's SDP (checked already, ``webrtc_offer.check_offer``).
        topics: how many ``video`` parameters the offer came with.

    Returns:
        One ``VideoSection`` a topic, in order, when the offer has no audio
        section, exactly ``topics`` video sections, each receiving, with a mid of
        its own, and each section's first codec the server sends is H.264; else None.
    """
    try:
        parsed = SessionDescription.parse(offer)
    except Exception:  # the offer's checks passed it; aiortc then says what is wrong
        return None
    sections: list[VideoSection] = []
    for media in parsed.media:
        if media.kind == "application":
            continue
        if media.kind != "video" or media.direction not in ("recvonly", "sendrecv"):
            return None
        sent = [(c, kind) for c in media.rtp.codecs if (kind := _sent_codec(c)) is not None]
        payload_type = sent[0][0].payloadType if sent else None
        if not sent or sent[0][1] != "H264" or payload_type is None or not media.rtp.muxId:
            return None
        extension = next((e.id for e in media.rtp.headerExtensions if e.uri == _MID_URI), None)
        sections.append(VideoSection(media.rtp.muxId, payload_type, extension))
    if len({section.mid for section in sections}) != len(sections):
        return None  # a mid twice: aiortc says what is wrong with it
    return sections if len(sections) == topics and topics > 0 else None


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
    """One peer's libdatachannel H.264 track of a shared stream.

    Args:
        params: the stream (its ``type`` H.264).
        type_name: the topic's type.
        track: libdatachannel's ``Track`` for the section, its chain set
            (``prepare_native_tracks``, which also sets ``feedback``: where its PLIs
            and REMBs hop to the loop).
    """

    def __init__(self, params: StreamParams, type_name: str, track: Any) -> None:
        super().__init__(params, type_name)
        self.track = track
        self.feedback: _Feedback | None = None

    def deliver(self, packet: VideoPacket) -> None:
        """Packetize and send ``packet`` now (on the loop; libdatachannel queues nothing)."""
        track = self.track
        if track is None or not track.is_open():
            return
        ldc = _ldc()
        try:
            track.send_frame(packet.data, ldc.FrameInfo(packet.pts_ms * _CLOCK_RATE // 1000))
        except RuntimeError:  # closed under us: the peer connection's end comes next
            return
        self.sent += 1

    def stop(self) -> None:
        """Send no more, and drop the feedback's way back to this track."""
        self.track = None
        if self.feedback is not None:
            self.feedback.track = None


def _ldc() -> Any:
    import libdatachannel  # noqa: PLC0415 (optional: the native stack, Python 3.12+)

    return libdatachannel


def prepare_native_tracks(
    binding: VideoBinding,
    offered: Sequence[Any],
    plan: Sequence[VideoSection],
    loop: asyncio.AbstractEventLoop,
) -> Answer | None:
    """After the offer is set, before the answer: each planned section sends its topic.

    Args:
        binding: the offer's tracks (``WebRtcVideo.binding``); its tracks are
            replaced by ``NativeVideoTrack``s sending H.264.
        offered: libdatachannel's tracks of the offer's media sections.
        plan: ``native_video_plan``'s sections, one a topic, in order.
        loop: where the feedback hops to.

    Returns:
        None, or the refusal: 503 when the streams this offer would add pass the
        hub's bound with those running; 400 when libdatachannel has no track for a
        section.

    Raises:
        RuntimeError, ValueError: libdatachannel refused a description (the caller
            answers 400).
    """
    ldc = _ldc()
    by_mid = {track.mid(): track for track in offered}
    stream_id = secrets.token_hex(8)
    tracks: list[FrameFeed] = []
    for index, (section, asked) in enumerate(zip(plan, binding.tracks, strict=True)):
        track = by_mid.get(section.mid)
        if track is None:
            return Answer(400, f"the offer cannot be answered: no track for mid {section.mid!r}")
        ssrc = secrets.randbits(31) + 1
        media = track.description()
        for payload_type in list(media.payload_types()):
            if payload_type != section.payload_type:
                media.remove_rtp_map(payload_type)
        for attribute in list(media.attributes()):
            if attribute.startswith(("msid:", "ssrc-group:")):
                media.remove_attribute(attribute)
        for extension in list(media.ext_ids()):
            if extension != section.mid_extension:
                media.remove_ext_map(extension)
        media.clear_ssrcs()
        media.add_ssrc(ssrc, _CNAME, stream_id, f"video{index}")
        track.set_description(media)
        config = ldc.RtpPacketizationConfig(ssrc, _CNAME, section.payload_type, _CLOCK_RATE)
        if section.mid_extension is not None:
            config.mid = section.mid
            config.mid_id = section.mid_extension
        params = replace(asked.params, type=StreamType.H264)
        native = NativeVideoTrack(params, asked.type_name, track)
        feedback = native.feedback = _Feedback(loop, native)
        track.set_media_handler(ldc.H264RtpPacketizer(ldc.NalUnit.Separator.StartSequence, config))
        track.chain_media_handler(ldc.RtcpSrReporter(config))
        track.chain_media_handler(ldc.RtcpNackResponder())
        track.chain_media_handler(ldc.PliHandler(feedback.pli))
        track.chain_media_handler(ldc.RembHandler(feedback.remb))
        tracks.append(native)
    return binding.adopt(tracks)
