"""The data channel's inbox bound, on two real aiortc peers (no server: nothing reads it)."""

from __future__ import annotations

import anyio
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from aiortc import RTCConfiguration, RTCDataChannel, RTCPeerConnection

from rwt_transports.webrtc import INBOX_LIMIT_BYTES, DataChannelChannel

pytestmark = pytest.mark.anyio


async def test_a_peer_sending_past_the_inbox_bound_is_disconnected() -> None:
    offerer = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    answerer = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    sending = offerer.createDataChannel("rosbridge")
    arrived: list[RTCDataChannel] = []
    answerer.on("datachannel", arrived.append)
    opened = anyio.Event()
    sending.on("open", opened.set)
    try:
        await offerer.setLocalDescription(await offerer.createOffer())
        await answerer.setRemoteDescription(offerer.localDescription)
        await answerer.setLocalDescription(await answerer.createAnswer())
        await offerer.setRemoteDescription(answerer.localDescription)
        with anyio.fail_after(10):
            await opened.wait()
            while not arrived:
                await anyio.sleep(0.01)
        channel = DataChannelChannel(
            arrived[0], max_message_size=1 << 20, remote_max_message_size=0
        )
        chunk = "z" * 200_000
        closed = anyio.Event()
        sending.on("close", closed.set)
        with anyio.fail_after(30):
            for _ in range(INBOX_LIMIT_BYTES // len(chunk) + 2):  # nothing reads the channel
                if closed.is_set():
                    break
                sending.send(chunk)
                while sending.bufferedAmount > 1 << 20:
                    await anyio.sleep(0.005)
            await closed.wait()  # the receiving side closed the channel
        assert channel.overflowed
        with pytest.raises(anyio.EndOfStream):
            await channel.receive()  # what it held is dropped: the session ends
    finally:
        await offerer.close()
        await answerer.close()
