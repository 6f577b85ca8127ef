"""The ``rosbridge-lossy`` data channel (D36) from a real WebRTC stack (aiortc).

Subscriptions made on it are delivered on it, latest-only, ahead of the
reliable channel's backlog; replies stay on the reliable channel.
"""

from __future__ import annotations

import json

import anyio
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

import anyio.lowlevel

from tests.webrtc.peer import RECEIVE_S, RtcClient, Served, rtc_client

pytestmark = pytest.mark.anyio

LOSSY = {"ordered": False, "maxRetransmits": 0}
ONE_RETRANSMISSION = {"ordered": False, "maxRetransmits": 1}
"""What rwt's roslib transport asks for (D73)."""


async def _lossy_open(client: RtcClient) -> None:
    assert client.lossy is not None
    with anyio.fail_after(RECEIVE_S):
        while client.lossy.readyState == "connecting":
            await anyio.sleep(0.01)
    assert client.lossy.readyState == "open"


async def _subscribed(client: RtcClient, op_id: str) -> None:
    """Wait until the server handled the ops sent so far on both channels (a call's reply)."""
    client.send({"op": "call_service", "service": "/rosapi/topics", "id": op_id})
    await client.next_op("service_response")


def _lossy_messages(client: RtcClient) -> list[dict[str, object]]:
    return [json.loads(m) for m in client.lossy_inbox]


@pytest.mark.parametrize(
    "options",
    [
        {"ordered": True, "maxRetransmits": 0},
        {"ordered": False},
        {"ordered": False, "maxRetransmits": 2},
        {"ordered": False, "maxPacketLifeTime": 100},
    ],
)
async def test_a_lossy_channel_that_is_ordered_or_retransmits_is_closed(
    served_on: Served, options: dict[str, object], stack: str
) -> None:
    unreliable = "maxPacketLifeTime" in options or "maxRetransmits" in options
    if stack == "reactor" and unreliable and not options.get("ordered", True):
        await _taken_as_lossy_on_the_reactor_stack(served_on, options)
    else:
        await _closed(served_on, options)


async def _closed(served_on: Served, options: dict[str, object]) -> None:
    async with rtc_client(served_on.base, lossy=options) as client:
        assert client.lossy is not None
        with anyio.fail_after(RECEIVE_S):
            while client.lossy.readyState != "closed":
                await anyio.sleep(0.02)
        await _subscribed(client, "still")  # the session goes on, on its reliable channel


async def _taken_as_lossy_on_the_reactor_stack(
    served_on: Served, options: dict[str, object]
) -> None:
    """libwebrtc's binding tells whether a channel is reliable, not its retransmissions or
    lifetime: there an unordered channel that limits either is taken as the lossy one (D70)."""
    counter = served_on.graph.create_publisher("/count", "std_msgs/msg/Int32", node="/robot")
    async with rtc_client(served_on.base, lossy=options) as client:
        await _lossy_open(client)
        client.send_lossy({"op": "subscribe", "topic": "/count", "type": "std_msgs/Int32"})
        await _subscribed(client, "s")
        with anyio.fail_after(RECEIVE_S):
            while not _lossy_messages(client):
                counter.publish({"data": 1})
                await anyio.sleep(0.01)
        assert client.lossy is not None and client.lossy.readyState == "open"


@pytest.mark.parametrize("options", [LOSSY, ONE_RETRANSMISSION], ids=["none", "once"])
async def test_a_subscription_on_the_lossy_channel_is_delivered_only_there(
    served_on: Served, options: dict[str, object]
) -> None:
    """With ``maxRetransmits`` 0, or 1 as rwt's roslib transport asks (D73)."""
    counter = served_on.graph.create_publisher("/count", "std_msgs/msg/Int32", node="/robot")
    async with rtc_client(served_on.base, lossy=options) as client:
        await _lossy_open(client)
        client.send_lossy({"op": "subscribe", "topic": "/count", "type": "std_msgs/Int32"})
        await _subscribed(client, "s")
        for value in range(20):
            counter.publish({"data": value})
            await anyio.lowlevel.checkpoint()
        with anyio.fail_after(RECEIVE_S):
            while not any(m["msg"] == {"data": 19} for m in _lossy_messages(client)):
                await anyio.sleep(0.01)
        await _subscribed(client, "after")
        reliable = [json.loads(m) for m in client.inbox]
    assert not any(m["op"] == "publish" for m in reliable)
    values = [m["msg"]["data"] for m in _lossy_messages(client)]  # type: ignore[index]
    assert values == sorted(values) and set(values) <= set(range(20))


async def test_a_message_over_the_peers_size_limit_is_dropped_with_a_warning(
    served_on: Served,
) -> None:
    text = served_on.graph.create_publisher("/text", "std_msgs/msg/String", node="/robot")
    async with rtc_client(served_on.base, lossy=LOSSY) as client:
        await _lossy_open(client)
        client.send({"op": "set_level", "level": "warning"})
        client.send_lossy({"op": "subscribe", "topic": "/text", "type": "std_msgs/String"})
        await _subscribed(client, "s")
        for _ in range(3):
            text.publish({"data": "x" * 400_000})  # aiortc's max-message-size: 256 KiB
        text.publish({"data": "small"})
        with anyio.fail_after(RECEIVE_S):
            while not client.lossy_inbox:
                await anyio.sleep(0.01)
        warning = await client.next_op("status")
        await _subscribed(client, "after")
        later = [json.loads(m) for m in client.inbox]
    assert [m["msg"] for m in _lossy_messages(client)] == [{"data": "small"}]
    assert warning["level"] == "warning" and "/text" in str(warning["msg"])
    assert "max-message-size" in str(warning["msg"])
    assert not any(m["op"] == "status" and "/text" in str(m["msg"]) for m in later)  # once


async def test_the_lossy_channel_stays_fresh_behind_a_reliable_backlog(served_on: Served) -> None:
    """The lossy channel's last sequence number reaches the publisher's own while the
    reliable channel, carrying 60 KB messages, is hundreds of messages behind."""
    bulk = served_on.graph.create_publisher("/bulk", "std_msgs/msg/String", node="/robot")
    seq = served_on.graph.create_publisher("/seq", "std_msgs/msg/Int32", node="/robot")
    count = 300  # 18 MB of bulk: more than aiortc sends meanwhile
    async with rtc_client(served_on.base, lossy=LOSSY) as client:
        await _lossy_open(client)
        client.send({"op": "subscribe", "topic": "/bulk", "type": "std_msgs/String"})
        client.send_lossy({"op": "subscribe", "topic": "/seq", "type": "std_msgs/Int32"})
        await _subscribed(client, "s")
        payload = "b" * 60_000
        for number in range(count):
            bulk.publish({"data": f"{number:06d}{payload}"})
            seq.publish({"data": number})
            if number % 10 == 9:
                await anyio.lowlevel.checkpoint()  # let the writers run, as a publishing loop would
        with anyio.fail_after(RECEIVE_S * 3):
            while not any(m["msg"] == {"data": count - 1} for m in _lossy_messages(client)):
                await anyio.sleep(0.005)
        reliable_seen = [
            int(json.loads(m)["msg"]["data"][:6])
            for m in client.inbox
            if isinstance(m, str) and '"/bulk"' in m[:40]
        ]
    assert max(reliable_seen, default=-1) < count - 100, "the reliable channel was not behind"
    seen = [m["msg"]["data"] for m in _lossy_messages(client)]  # type: ignore[index]
    assert seen[-1] == count - 1


async def test_when_the_lossy_channel_closes_its_subscriptions_go_on_the_reliable_one(
    served: Served,
) -> None:
    counter = served.graph.create_publisher("/count", "std_msgs/msg/Int32", node="/robot")
    async with rtc_client(served.base, lossy=LOSSY) as client:
        await _lossy_open(client)
        assert client.lossy is not None
        client.send_lossy({"op": "subscribe", "topic": "/count", "type": "std_msgs/Int32"})
        await _subscribed(client, "s")
        client.lossy.close()
        with anyio.fail_after(RECEIVE_S):
            while client.lossy.readyState != "closed":
                await anyio.sleep(0.01)
        await _subscribed(client, "closed")  # the server saw the close before this reply
        counter.publish({"data": 7})
        message = await client.next_op("publish")
    assert message["topic"] == "/count" and message["msg"] == {"data": 7}
