"""Video tracks on the native stack: H.264 and VP8 sent by libdatachannel (docs/webrtc.md, D51).

What is the native stack's own: that libdatachannel answers (``o=rtc``), what its answer
holds, the sections' plan, an audio section made inactive, a PLI flood. Every test of
test_video.py runs on the native stack too (its ``served`` is each stack's). Each test
here skips where libdatachannel-py does not import (Python 3.11); ``.ci/run`` runs them
on Python 3.12 (``-k native``). The player is aiortc's, as in test_video.py; Chromium
plays one in test_whep_player.py.
"""

from __future__ import annotations

import re
import time
from collections.abc import AsyncIterator

import anyio
import numpy as np
import pytest

from tests.webrtc.conftest import CONNECT_TIMEOUT_S, NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from aiortc import MediaStreamTrack, RTCConfiguration, RTCPeerConnection, RTCSessionDescription

from rwt_transports.server import ServerConfig
from rwt_transports.webrtc.native import native_missing
from rwt_transports.webrtc.native_video import NativeVideoTrack, native_video_plan
from rwt_transports.webrtc.signalling import WebRtcOptions
from rwt_video.rtp import KEYFRAME_MIN_INTERVAL_S
from tests.webrtc.peer import RECEIVE_S, Served, offer_sdp, serving
from tests.webrtc.test_video import CAMERA, RED, camera, feedback_target, hub_of
from tests.webrtc.whep import player, post_offer, recvonly_offer

pytestmark = pytest.mark.anyio

H264 = "video/H264"


@pytest.fixture
async def native() -> AsyncIterator[Served]:
    """A server answering on the native stack where it can (``--webrtc-stack native``)."""
    if (missing := native_missing()) is not None:
        pytest.skip(missing)
    options = WebRtcOptions(connect_timeout_s=CONNECT_TIMEOUT_S, stack="native")
    async with serving(ServerConfig(port=0, webrtc=options)) as running:
        yield running


def answered_natively(answer: str) -> bool:
    """libdatachannel's answer (its origin line), not aiortc's."""
    return answer.startswith("v=0") and "\no=rtc " in answer.replace("\r\n", "\n")


def native_viewers(served: Served) -> list[NativeVideoTrack]:
    return [
        viewer
        for stream in hub_of(served).streams.values()
        for viewer in stream.viewers
        if isinstance(viewer, NativeVideoTrack)
    ]


async def test_native_h264_player_plays_the_camera_from_libdatachannel(native: Served) -> None:
    async with camera(native), player(native.base, f"video={CAMERA}", codec=H264) as played:
        frame = await played.frame(after=2)
        assert (frame.width, frame.height) == (160, 120)
        mean = frame.to_ndarray(format="rgb24").reshape(-1, 3).mean(axis=0)
        assert np.abs(mean - RED).max() < 25
        answer = played.answer
        assert answered_natively(answer), answer
        assert "a=sendonly" in answer and "a=msid:" in answer and "H264/90000" in answer
        # one payload type, sent with an SSRC and a stream id of its own
        (line,) = re.findall(r"m=video \d+ UDP/TLS/RTP/SAVPF ([\d ]+)", answer)
        assert len(line.split()) == 1
        assert re.search(r"a=ssrc:\d+ msid:\w+ video0", answer)
        assert native.server.slots_taken == 1 and not native.server.sessions
        (params,) = hub_of(native).streams
        assert params.type.value == "h264"
        (viewer,) = native_viewers(native)
        assert viewer.sent >= 2


async def test_native_vp8_player_plays_the_camera_from_libdatachannel(native: Served) -> None:
    """VP8 cut by aiortc's payloader, sent through libdatachannel's chain."""
    async with camera(native), player(native.base, f"video={CAMERA}") as played:
        frame = await played.frame(after=3)
        assert (frame.width, frame.height) == (160, 120)
        mean = frame.to_ndarray(format="rgb24").reshape(-1, 3).mean(axis=0)
        assert np.abs(mean - RED).max() < 25
        assert answered_natively(played.answer), played.answer
        assert "VP8/90000" in played.answer and "H264" not in played.answer
        (params,) = hub_of(native).streams
        assert params.type.value == "vp8"
        (viewer,) = native_viewers(native)
        assert viewer.rtp is not None and viewer.sent >= 3


async def test_native_offer_with_audio_gets_it_inactive(native: Served) -> None:
    """A player's audio transceiver is answered inactive, as aiortc answers it."""
    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    pc.addTransceiver("audio", direction="recvonly")
    recvonly_offer(pc, 1, H264)
    frames = anyio.Event()

    async def play(track: MediaStreamTrack) -> None:
        await track.recv()
        frames.set()

    try:
        async with camera(native), anyio.create_task_group() as tg:
            pc.on("track", lambda track: track.kind == "video" and tg.start_soon(play, track))
            reply = await post_offer(native.base, f"video={CAMERA}", await offer_sdp(pc))
            assert reply.status_code == 201, reply.text
            assert answered_natively(reply.text)
            audio, video = reply.text.split("m=video")
            assert "m=audio" in audio and "a=inactive" in audio
            assert "a=sendonly" in video
            await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
            with anyio.fail_after(RECEIVE_S):
                await frames.wait()
            tg.cancel_scope.cancel()
    finally:
        await pc.close()


async def test_native_video_plan_binds_sections_as_aiortc_does() -> None:
    """Receiving video sections to the topics in order, the rest inactive; else aiortc."""

    async def offer(*codecs: str, audio: bool = False, data: bool = False) -> str:
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        try:
            if audio:
                pc.addTransceiver("audio", direction="recvonly")
            for codec in codecs:
                recvonly_offer(pc, 1, codec)
            if data:
                pc.createDataChannel("rosbridge")
            return await offer_sdp(pc)
        finally:
            await pc.close()

    h264 = await offer(H264)
    plan = native_video_plan(h264, 1)
    assert plan is not None and not plan.inactive
    (section,) = plan.sections
    assert (section.mid, section.codec) == ("0", "H264") and section.mid_extension is not None
    assert native_video_plan(h264, 2) is None  # a topic without its section: aiortc's 400
    assert native_video_plan(h264, 0) is None
    with_audio = native_video_plan(await offer(H264, "video/VP8", audio=True), 1)
    assert with_audio is not None
    assert [(s.mid, s.codec) for s in with_audio.sections] == [("1", "H264")]
    assert with_audio.inactive == ("0", "2")  # the audio, and the video past the topics
    mixed = native_video_plan(await offer(H264, "video/VP8", data=True), 2)
    assert mixed is not None and [s.codec for s in mixed.sections] == ["H264", "VP8"]
    assert native_video_plan("v=0\r\nnot sdp", 1) is None
    # H.264 profiles match as aiortc matches them: by profile, not level
    level_52 = h264.replace("42001f", "42e034").replace("42e01f", "42e034")
    matched = native_video_plan(level_52, 1)
    assert matched is not None and matched.sections[0].codec == "H264"
    high = h264.replace("42001f", "640c1f").replace("42e01f", "640c1f")
    assert native_video_plan(high, 1) is None  # no codec in common: aiortc's 400
    same_mid = (await offer(H264, H264)).replace("a=mid:1", "a=mid:0")
    assert native_video_plan(same_mid, 2) is None  # aiortc answers (and refuses) it


async def test_native_pli_flood_gets_key_frames_at_their_bound(native: Served) -> None:
    """2,000 PLIs: a key frame per ``KEYFRAME_MIN_INTERVAL_S`` at most, the track plays on."""
    async with (
        camera(native),
        player(native.base, f"video={CAMERA}&gop=1000", codec=H264) as played,
    ):
        await played.frame(after=2)
        encoder, receiver, ssrc = feedback_target(native, played)
        before = encoder.keyframes
        await anyio.sleep(KEYFRAME_MIN_INTERVAL_S + 0.1)  # past the joining key frame's bound
        start = time.monotonic()
        for index in range(2000):  # over about a second
            await receiver._send_rtcp_pli(ssrc)
            if index % 100 == 0:
                await anyio.sleep(0.05)
        elapsed = time.monotonic() - start
        await played.frame(after=played.counts[0] + 3)  # still playing
        keyframes = encoder.keyframes - before
        assert 1 <= keyframes <= (time.monotonic() - start) / KEYFRAME_MIN_INTERVAL_S + 2, (
            keyframes,
            elapsed,
        )
