"""The data channel's inbox bound, on real peers (no server: nothing reads it), either stack."""

from __future__ import annotations

import functools

import anyio
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from aiortc import RTCConfiguration, RTCDataChannel, RTCPeerConnection, RTCSessionDescription

from rwt_transports.frontends import FrontEnds
from rwt_transports.rosbridge import rosbridge_frontend
from rwt_transports.webrtc.channel import INBOX_LIMIT_BYTES, DataChannelChannel
from rwt_transports.webrtc.native import (
    Inflow,
    NativeDataChannel,
    NativePeerConnection,
    native_missing,
)
from rwt_transports.webrtc.peers import channel_refusal
from rwt_transports.webrtc.sctp import ANSWER_MAX_MESSAGE_SIZE

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


async def test_the_native_stack_counts_messages_waiting_for_the_loop_in_the_bound() -> None:
    """libdatachannel's threads hop messages onto the loop only within the inbox bound (D51).

    The bound is 1 MiB here (``Inflow``'s limit): past it the native channel reports
    the overflow and the session's channel cuts the peer, an aiortc one sending.
    """
    if (missing := native_missing()) is not None:
        pytest.skip(missing)
    limit = 1 << 20
    channel = DataChannelChannel(None, max_message_size=1 << 20, remote_max_message_size=0)
    inflow = Inflow(limit, lambda: channel.inbox_bytes)
    channel.held_below = lambda: inflow.pending
    labels = FrontEnds(rosbridge_frontend(lambda request: None))  # type: ignore[arg-type,return-value]
    refusal = functools.partial(channel_refusal, labels)  # the registry's labels, rosbridge's
    answerer = NativePeerConnection((), 1 << 20, inflow, ANSWER_MAX_MESSAGE_SIZE, refusal)

    def take(native: NativeDataChannel) -> None:  # before its first message, as the server
        native.on("overflow", channel.overflow)
        channel.attach(native)

    answerer.on("datachannel", take)
    offerer = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    sending = offerer.createDataChannel("rosbridge")
    opened, closed = anyio.Event(), anyio.Event()
    sending.on("open", opened.set)
    sending.on("close", closed.set)
    try:
        await offerer.setLocalDescription(await offerer.createOffer())
        answer = await answerer.answer(offerer.localDescription.sdp)
        await offerer.setRemoteDescription(RTCSessionDescription(answer, "answer"))
        chunk = "n" * 100_000
        with anyio.fail_after(30):
            await opened.wait()
            for _ in range(limit // len(chunk) + 2):  # nothing reads the channel
                sending.send(chunk)
            await closed.wait()  # the native side closed the channel
        assert channel.overflowed
        assert channel.inbox_bytes == 0  # what it held is dropped
        with pytest.raises(anyio.EndOfStream):
            await channel.receive()
    finally:
        await offerer.close()
        await answerer.close()
