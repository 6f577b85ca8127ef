"""One way in: a data channel's label picks its protocol from the registry; a video peer a ticket.

docs/webrtc.md, "Data channels and protocols": the server's one front-end registry names
the labels (rosbridge's ``rosbridge`` and ``rosbridge-lossy``, a registered protocol's
own); a channel of another label is closed, and the log says which labels are served.
A video-only peer is admitted on the server's public ticket (``admit``): it counts
against ``--max-connections`` as any connection does and holds no session. Real aiortc
peers against an in-process server.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import anyio
import httpx
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from tests.support.echo import ECHO, FRONTEND
from tests.webrtc.conftest import CONNECT_TIMEOUT_S, NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from aiortc import RTCConfiguration, RTCDataChannel, RTCPeerConnection, RTCSessionDescription

from rwt_transports.server import ServerConfig
from rwt_transports.webrtc.signalling import WebRtcOptions
from tests.webrtc.peer import RECEIVE_S, offer_sdp, serving
from tests.webrtc.whep import SDP, post_offer, recvonly_offer

pytestmark = pytest.mark.anyio

OPTIONS = WebRtcOptions(connect_timeout_s=CONNECT_TIMEOUT_S, stack="aiortc")


async def _closed(channel: RTCDataChannel) -> None:
    closed = anyio.Event()
    channel.on("close", closed.set)
    if channel.readyState != "closed":
        await closed.wait()


async def test_a_label_picks_its_registered_protocol_and_an_unknown_one_is_refused(
    stack: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="rwt.webrtc")
    options = replace(OPTIONS, stack=stack)  # on both stacks: libdatachannel's judges on its thread
    async with serving(ServerConfig(port=0, webrtc=options)) as served:
        # a protocol registered with a label of its own: WebRTC finds it in the registry
        served.server.add_frontend(replace(FRONTEND, labels=(ECHO,)))
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        echo = pc.createDataChannel(ECHO)
        unknown = pc.createDataChannel("bogus")
        messages: list[str] = []
        arrived = anyio.Event()
        echo.on("message", lambda text: (messages.append(text), arrived.set()))
        opened = anyio.Event()
        echo.on("open", opened.set)
        try:
            async with httpx.AsyncClient(base_url=served.base) as http:
                reply = await http.post("/webrtc", content=await offer_sdp(pc), headers=SDP)
            assert reply.status_code == 201, reply.text
            await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
            with anyio.fail_after(RECEIVE_S):
                await opened.wait()
                echo.send("hello over a data channel")
                await arrived.wait()
                await _closed(unknown)  # the server closed it
                # not the session's protocol; on a stream of its own, not the refused
                # channel's (which aiortc would give it again): one refusal a stream
                assert echo.id is not None
                rosbridge = pc.createDataChannel("rosbridge", id=echo.id + 16)
                await _closed(rosbridge)
            assert messages == ["hello over a data channel"]
            (session,) = served.server.sessions.values()
            assert session.protocol == "echo"  # type: ignore[attr-defined]
        finally:
            await pc.close()
    logged = caplog.text
    assert "event=channel_refused" in logged and "label='bogus'" in logged
    assert "unknown label (served: rosbridge, rosbridge-lossy, rwt.test.echo)" in logged
    assert "label='rosbridge' reason=another protocol than the session's (echo)" in logged


async def test_a_protocol_that_cuts_no_frame_gets_a_large_text_frame_whole(stack: str) -> None:
    """A text frame above 64 KiB is its front end's to cut (``FrontEnd.split_text``, D74):
    rosbridge's become ``fragment`` ops; a protocol that cuts none has it sent whole,
    as aiortc's peer states it takes messages of 256 KiB."""
    options = replace(OPTIONS, stack=stack)
    async with serving(ServerConfig(port=0, webrtc=options)) as served:
        served.server.add_frontend(replace(FRONTEND, labels=(ECHO,)))
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        echo = pc.createDataChannel(ECHO)
        messages: list[str] = []
        arrived = anyio.Event()
        echo.on("message", lambda text: (messages.append(text), arrived.set()))
        opened = anyio.Event()
        echo.on("open", opened.set)
        large = "x" * (100 * 1024)  # over MAX_TEXT_FRAME_BYTES, under the peer's 256 KiB
        try:
            async with httpx.AsyncClient(base_url=served.base) as http:
                reply = await http.post("/webrtc", content=await offer_sdp(pc), headers=SDP)
            assert reply.status_code == 201, reply.text
            await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
            with anyio.fail_after(RECEIVE_S):
                await opened.wait()
                echo.send(large)
                await arrived.wait()
            assert messages == [large]  # one message, its text as sent
        finally:
            await pc.close()


async def test_a_video_only_peer_holds_a_ticket_counted_by_the_connection_budget(
    stack: str,
) -> None:
    options = WebRtcOptions(connect_timeout_s=CONNECT_TIMEOUT_S, stack=stack)
    config = ServerConfig(port=0, max_connections=1, webrtc=options)
    async with serving(config) as served:
        served.graph.create_publisher("/camera/image", "sensor_msgs/msg/Image")
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        recvonly_offer(pc, 1, "video/VP8")
        try:
            offer = await offer_sdp(pc)
        finally:
            await pc.close()  # it never connects: its ticket holds the slot until freed
        reply = await post_offer(served.base, "video=/camera/image", offer)
        assert reply.status_code == 201, reply.text
        assert served.server.slots_taken == 1 and not served.server.sessions
        websocket = served.base.replace("http://", "ws://")
        with pytest.raises(InvalidStatus) as refused:  # the same budget as every connection
            async with connect(websocket):
                pass
        assert refused.value.response.status_code == 503
        async with httpx.AsyncClient(base_url=served.base) as http:
            assert (await http.delete(reply.headers["Location"])).status_code == 204
        with anyio.fail_after(RECEIVE_S):
            while served.server.slots_taken:
                await anyio.sleep(0.02)
        async with connect(websocket) as ws:  # its slot is back
            await ws.send('{"op": "call_service", "service": "/rosapi/topics", "id": "1"}')
            assert '"service_response"' in str(await ws.recv())
