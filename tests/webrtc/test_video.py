"""Video tracks: image topics played by a WHEP player (aiortc), shared, keyed, refused.

docs/webrtc.md, "Video tracks".
"""

from __future__ import annotations

import fractions
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager

import anyio
import av
import av.video.codeccontext
import httpx
import numpy as np
import pytest

from tests.webrtc.conftest import CONNECT_TIMEOUT_S, NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from aiortc import (
    MediaStreamTrack,
    RTCConfiguration,
    RTCPeerConnection,
    RTCRtpReceiver,
    RTCSessionDescription,
)
from aiortc.rtp import RTCP_PSFB_APP, RtcpPsfbPacket, pack_remb_fci

from rwt_graph.graph import Graph
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig, rosauth_authenticator
from rwt_transports.webrtc.signalling import MAX_VIDEO_TRACKS, WebRtcOptions
from rwt_transports.webrtc.video import MAX_VIDEO_STREAMS, VideoTrack
from rwt_video.encoders import VideoPacket
from rwt_video.params import StreamParams
from rwt_video.rtp import H264PassThrough, RtpEncoder
from tests.webrtc.peer import RECEIVE_S, Served, offer_sdp, peers_of, rtc_client, serving
from tests.webrtc.whep import Player, image, player, post_offer, recvonly_offer

pytestmark = pytest.mark.anyio

CAMERA = "/camera/image"
RED = (200, 40, 40)


@asynccontextmanager
async def camera(served: Served, size: tuple[int, int] = (160, 120)) -> AsyncIterator[None]:
    """Publish a red ``sensor_msgs/msg/Image`` on ``CAMERA`` at 15 Hz while the block runs."""
    publisher = served.graph.create_publisher(CAMERA, "sensor_msgs/msg/Image", node="/camera")

    async def publish() -> None:
        for stamp in range(1, 1_000_000):
            publisher.publish(image(*size, RED, stamp))
            await anyio.sleep(1 / 15)

    async with anyio.create_task_group() as tg:
        tg.start_soon(publish)
        yield
        tg.cancel_scope.cancel()


def hub_of(served: Served):  # type: ignore[no-untyped-def]
    assert peers_of(served.server).video is not None
    hub = peers_of(served.server).video.hub
    assert hub is not None
    return hub


async def streams_running(served: Served, count: int) -> None:
    """Wait until ``count`` streams run: they start as their peers connect."""
    with anyio.fail_after(RECEIVE_S):
        while len(hub_of(served).streams) < count:
            await anyio.sleep(0.02)


@pytest.mark.parametrize("codec", ["video/VP8", "video/H264"])
async def test_a_whep_player_plays_an_image_topic(served: Served, codec: str) -> None:
    async with camera(served), player(served.base, f"video={CAMERA}", codec=codec) as played:
        frame = await played.frame(after=2)
        assert (frame.width, frame.height) == (160, 120)
        mean = frame.to_ndarray(format="rgb24").reshape(-1, 3).mean(axis=0)
        assert np.abs(mean - RED).max() < 25  # lossy, but red
        assert "a=msid:" in played.answer and "a=sendonly" in played.answer
        assert codec.split("/")[1] in played.answer
        # a video-only peer is a connection too: on its ticket, with no session
        assert served.server.slots_taken == 1 and not served.server.sessions
        (stream,) = hub_of(served).streams
        assert stream.type.value == codec.split("/")[1].lower()


async def test_stream_parameters_resize_the_track(served: Served) -> None:
    async with camera(served), player(served.base, f"video={CAMERA}&width=80&height=60") as played:
        frame = await played.frame()
        assert (frame.width, frame.height) == (80, 60)


async def test_two_players_share_one_encoder_which_stops_with_the_last(served: Served) -> None:
    async with camera(served):
        async with player(served.base, f"video={CAMERA}") as one:
            async with player(served.base, f"video={CAMERA}") as two:
                await one.frame(after=3)
                await two.frame(after=3)
                hub = hub_of(served)
                assert hub.started == 1 and len(hub.streams) == 1
                (stream,) = hub.streams.values()
                assert len(stream.viewers) == 2
            async with httpx.AsyncClient(base_url=served.base) as http:
                assert (await http.delete(one.location)).status_code == 204
            with anyio.fail_after(RECEIVE_S):
                while hub.streams or served.server.slots_taken:
                    await anyio.sleep(0.05)
        assert hub.started == 1


async def test_two_topics_in_one_offer_and_a_data_channel_beside(served: Served) -> None:
    arm = served.graph.create_publisher("/arm/image", "sensor_msgs/msg/Image", node="/arm")
    async with (
        camera(served),
        player(served.base, f"video={CAMERA}&video=/arm/image", tracks=2) as played,
    ):
        for _ in range(30):
            arm.publish(image(64, 48, (20, 20, 220)))
            await anyio.sleep(1 / 15)
            if played.counts[1] > 1:
                break
        red, blue = await played.frame(0), await played.frame(1)
        assert (red.width, blue.width) == (160, 64)
        assert blue.to_ndarray(format="rgb24").reshape(-1, 3).mean(axis=0)[2] > 150


def feedback_target(served: Served, played: Player) -> tuple[RtpEncoder, RTCRtpReceiver, int]:
    """The one stream's encoder, the player's receiver, and the SSRC its RTCP names."""
    (stream,) = hub_of(served).streams.values()
    assert isinstance(stream.encoder, RtpEncoder)
    (transceiver,) = played.pc.getTransceivers()
    (source,) = transceiver.receiver.getSynchronizationSources()
    return stream.encoder, transceiver.receiver, source.source


async def test_a_picture_loss_gets_a_key_frame(served: Served) -> None:
    async with camera(served), player(served.base, f"video={CAMERA}&gop=1000") as played:
        await played.frame(after=3)
        encoder, receiver, ssrc = feedback_target(served, played)
        before = encoder.keyframes
        await receiver._send_rtcp_pli(ssrc)
        with anyio.fail_after(RECEIVE_S):
            while encoder.keyframes == before:
                await anyio.sleep(0.05)
        assert encoder.keyframes > before  # gop=1000: none would come for a minute


async def test_a_receiver_estimate_sets_the_bit_rate(served: Served) -> None:
    async with camera(served), player(served.base, f"video={CAMERA}&bitrate=2000000") as played:
        await played.frame(after=1)
        encoder, receiver, ssrc = feedback_target(served, played)
        # the player's own estimates would race this one: only ours is sent
        receiver._RTCRtpReceiver__remote_bitrate_estimator = None  # type: ignore[attr-defined]
        remb = RtcpPsfbPacket(
            fmt=RTCP_PSFB_APP, ssrc=1, media_ssrc=0, fci=pack_remb_fci(300_000, [ssrc])
        )
        await receiver._send_rtcp(remb)
        with anyio.fail_after(RECEIVE_S):
            while encoder.target_bitrate != 300_000:
                await anyio.sleep(0.05)
        opened = encoder.opened
        with anyio.fail_after(RECEIVE_S):  # the codec is reopened at the new rate
            while encoder.opened == opened:
                await anyio.sleep(0.05)


def test_a_slow_peer_drops_frames_and_resumes_at_a_key_frame() -> None:
    track = VideoTrack(StreamParams(CAMERA), "sensor_msgs/msg/Image")
    track.offer([VideoPacket(b"k", 0, keyframe=True)])
    for pts in range(1, 6):  # never taken by the peer
        track.offer([VideoPacket(b"d", pts, keyframe=False)])
    assert track.dropped == 1 and track._pending is None  # held none, queued none
    track.offer([VideoPacket(b"k2", 9, keyframe=True)])
    assert track._pending == VideoPacket(b"k2", 9, keyframe=True)


async def a_video_offer(tracks: int = 1) -> str:
    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    recvonly_offer(pc, tracks, "video/VP8")
    try:
        return await offer_sdp(pc)
    finally:
        await pc.close()


@pytest.mark.parametrize(
    ("query", "status", "text"),
    [
        ("video=/nowhere", 404, "topic '/nowhere' does not exist"),
        ("video=/chatter", 400, "is a std_msgs/msg/String, not an image topic"),
        (
            f"video={CAMERA}&video={CAMERA}",
            400,
            "2 video parameters but 1 receiving video transceivers",
        ),
        ("&".join([f"video={CAMERA}"] * 1000), 400, f"at most {MAX_VIDEO_TRACKS}"),
        ("video=", 400, "an empty video parameter"),
        (f"video={CAMERA}&bitrate=lots", 400, "bitrate='lots' is not an integer"),
    ],
)
async def test_a_bad_video_request_is_refused_and_a_bystander_served(
    served: Served, query: str, status: int, text: str
) -> None:
    served.graph.create_publisher("/chatter", "std_msgs/msg/String")
    async with camera(served):
        reply = await post_offer(served.base, query, await a_video_offer())
        assert reply.status_code == status and text in reply.text
        assert not served.server.slots_taken and not hub_of(served).streams
        async with player(served.base, f"video={CAMERA}") as played:
            await played.frame()


async def test_a_video_only_offer_without_video_parameters_is_refused(served: Served) -> None:
    reply = await post_offer(served.base, "", await a_video_offer())
    assert reply.status_code == 400 and "no data channel" in reply.text


async def test_access_rules_apply_to_video_topics(stack: str) -> None:
    config = ServerConfig(
        port=0,
        webrtc=WebRtcOptions(connect_timeout_s=CONNECT_TIMEOUT_S, stack=stack),
        session=SessionConfig(access=AccessPolicy(topics=["/camera/*"])),
    )
    async with serving(config) as served:
        served.graph.create_publisher("/secret/image", "sensor_msgs/msg/Image")
        offer = await a_video_offer()
        for topic in ("/secret/image", "/secret/none"):  # the same answer: nothing leaked
            reply = await post_offer(served.base, f"video={topic}", offer)
            assert reply.status_code == 403 and f"topic {topic!r} is not allowed" in reply.text
        async with camera(served), player(served.base, f"video={CAMERA}") as played:
            await played.frame()


async def test_a_data_channel_peer_gets_video_too(served: Served) -> None:
    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    channel = pc.createDataChannel("rosbridge")
    recvonly_offer(pc, 1, "video/VP8")
    opened, frames = anyio.Event(), anyio.Event()
    channel.on("open", opened.set)
    pc.on("track", lambda track: tg.start_soon(_first_frame, track, frames))
    try:
        async with camera(served), anyio.create_task_group() as tg:
            reply = await post_offer(served.base, f"video={CAMERA}", await offer_sdp(pc))
            assert reply.status_code == 201, reply.text
            await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
            with anyio.fail_after(RECEIVE_S):
                await opened.wait()
                await frames.wait()
            assert len(served.server.sessions) == 1
    finally:
        await pc.close()


async def _first_frame(track: MediaStreamTrack, done: anyio.Event) -> None:
    await track.recv()
    done.set()


def h264_frames(count: int, size: tuple[int, int], rgb: tuple[int, int, int]) -> list[bytes]:
    """``count`` H.264 access units (Annex B, Constrained Baseline) of one colour, as a camera's."""
    codec = av.CodecContext.create("libx264", "w")
    assert isinstance(codec, av.video.codeccontext.VideoCodecContext)
    codec.width, codec.height = size
    codec.pix_fmt = "yuv420p"
    codec.time_base = fractions.Fraction(1, 15)
    codec.gop_size = 5
    codec.options = {"preset": "ultrafast", "tune": "zerolatency", "profile": "baseline"}
    pixels = np.empty((size[1], size[0], 3), np.uint8)
    pixels[...] = rgb
    units = []
    for pts in range(count):
        frame = av.VideoFrame.from_ndarray(pixels, format="rgb24")
        frame.pts = pts
        units.extend(bytes(packet) for packet in codec.encode(frame))
    return units


async def test_h264_from_a_compressed_topic_passes_through(served: Served) -> None:
    frames = h264_frames(30, (96, 64), (40, 200, 40))
    topic = "/camera/h264"
    publisher = served.graph.create_publisher(topic, "sensor_msgs/msg/CompressedImage")
    async with player(served.base, f"video={topic}", codec="video/H264") as played:
        await streams_running(served, 1)
        (stream,) = hub_of(served).streams.values()
        assert isinstance(stream.encoder, H264PassThrough)  # no encoder: the bytes as they are
        for stamp, unit in enumerate(frames * 4):
            header = {"stamp": {"sec": stamp, "nanosec": 0}, "frame_id": "camera"}
            publisher.publish({"header": header, "format": "h264", "data": unit})
            await anyio.sleep(1 / 15)
            if played.counts[0] > 2:
                break
        frame = await played.frame(after=2)
        assert (frame.width, frame.height) == (96, 64)
        assert frame.to_ndarray(format="rgb24").reshape(-1, 3).mean(axis=0)[1] > 150


async def test_a_compressed_topic_needs_h264(served: Served) -> None:
    served.graph.create_publisher("/camera/h264", "sensor_msgs/msg/CompressedImage")
    reply = await post_offer(served.base, "video=/camera/h264", await a_video_offer())
    assert reply.status_code == 400 and "only H.264 passes through" in reply.text
    assert not served.server.slots_taken and not hub_of(served).streams


async def test_with_auth_video_needs_the_bearer_token(stack: str) -> None:
    config = ServerConfig(
        port=0,
        webrtc=WebRtcOptions(
            connect_timeout_s=CONNECT_TIMEOUT_S,
            bearer_token=lambda token: token == "live",
            stack=stack,
        ),
        session=SessionConfig(authenticator=rosauth_authenticator("s" * 16, Graph().clock)),
    )
    async with serving(config) as served:
        offer = await a_video_offer()
        refused = await post_offer(served.base, f"video={CAMERA}", offer)
        assert refused.status_code == 401 and "Authorization: Bearer" in refused.text
        async with camera(served):
            reply = await post_offer(
                served.base, f"video={CAMERA}", offer, Authorization="Bearer live"
            )
            assert reply.status_code == 201, reply.text  # (this peer never connects)


async def test_a_video_peer_that_never_connects_runs_no_encoder_and_is_freed(
    served: Served,
) -> None:
    # its stream would start with the answer and encode the camera until the connect
    # deadline, for no viewer; it starts only when a peer connects (D37)
    async with camera(served):
        reply = await post_offer(served.base, f"video={CAMERA}", await a_video_offer())
        assert reply.status_code == 201
        assert served.server.slots_taken == 1  # admitted as it was answered: its ticket
        with anyio.fail_after(CONNECT_TIMEOUT_S + RECEIVE_S):
            while served.server.slots_taken:
                assert not hub_of(served).streams
                await anyio.sleep(0.05)
        assert hub_of(served).started == 0  # no encoder ever ran
        async with httpx.AsyncClient(base_url=served.base) as http:
            assert (await http.delete(reply.headers["Location"])).status_code == 404


async def test_distinct_streams_are_bounded(served: Served) -> None:
    topics = [f"/camera{n}/image" for n in range(MAX_VIDEO_STREAMS + 1)]
    for topic in topics:  # no frame comes: nothing is encoded, the streams only exist
        served.graph.create_publisher(topic, "sensor_msgs/msg/Image")
    per_offer = [topics[n : n + MAX_VIDEO_TRACKS] for n in range(0, len(topics), MAX_VIDEO_TRACKS)]
    async with AsyncExitStack() as players:
        for group in per_offer[:-1]:  # connected players hold the streams
            query = "&".join(f"video={topic}" for topic in group)
            await players.enter_async_context(player(served.base, query, tracks=len(group)))
        await streams_running(served, MAX_VIDEO_STREAMS)
        last = per_offer[-1]
        refused = await post_offer(served.base, f"video={last[0]}", await a_video_offer())
        assert refused.status_code == 503
        assert f"{MAX_VIDEO_STREAMS} distinct streams run already" in refused.text
        assert len(hub_of(served).streams) == MAX_VIDEO_STREAMS
        assert served.server.slots_taken == len(per_offer) - 1  # the refused one holds none
        async with rtc_client(served.base) as bystander:  # a data channel needs no stream
            bystander.send({"op": "call_service", "service": "/rosapi/topics", "id": "b"})
            assert (await bystander.next_op("service_response"))["result"] is True
