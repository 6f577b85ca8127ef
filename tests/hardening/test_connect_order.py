"""What a new connection sent first is in effect before what others sent after it.

A client connects, subscribes, and only then tells a client connected long before
to publish (here: the same thread sends the publish right after the subscribe
went out). The server must read the new connection before the older one's later
publish, so the new subscriber gets the message every time, over WebSocket and
TCP, without a pause between subscribing and publishing. Repeated, since a
missed read order shows only now and then. With the ``direct-read`` shortcut off
the server cannot see input anyio already read, and lets the loop turn instead
(admission.py); the order holds either way (docs/limits.md).
"""

from __future__ import annotations

import anyio.to_thread
import pytest

from tests.hardening.peers import Peer, open_peer, settle
from tests.support.clients import Harness

pytestmark = pytest.mark.anyio

TRIALS = 100
TOPIC = "/order"


def _trials(transport: str, ports: dict[str, int]) -> list[int]:
    """Run the trials; return those whose new subscriber missed the publish."""
    old = open_peer("ws", ports)
    missed: list[int] = []
    try:
        old.send({"op": "advertise", "topic": TOPIC, "type": "std_msgs/String"})
        settle(old, "advertised")
        for trial in range(TRIALS):
            new: Peer = open_peer(transport, ports)
            try:
                new.send({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String"})
                old.send({"op": "publish", "topic": TOPIC, "msg": {"data": f"first-{trial}"}})
                # Once the new connection answered a call sent after its subscribe, it
                # is subscribed for sure: the old one's next publish ends the trial.
                new.send({"op": "call_service", "service": "/rosapi/topics", "id": "sure"})
                got = []
                while True:
                    message = new.receive()
                    if message.get("op") == "publish":
                        got.append(message["msg"]["data"])
                    elif message.get("id") == "sure":
                        old.send({"op": "publish", "topic": TOPIC, "msg": {"data": "last"}})
                    if got[-1:] == ["last"]:
                        break
                if got != [f"first-{trial}", "last"]:
                    missed.append(trial)
            finally:
                new.close()
    finally:
        old.close()
    return missed


@pytest.mark.parametrize("transport", ["ws", "tcp"])
async def test_a_new_subscriber_gets_a_publish_sent_after_its_subscribe(
    harness: Harness, transport: str
) -> None:
    ports = {kind: harness.port(kind) for kind in ("websocket", "tcp")}
    missed = await anyio.to_thread.run_sync(_trials, transport, ports)
    assert missed == [], f"{len(missed)} of {TRIALS} new subscribers missed the publish"
