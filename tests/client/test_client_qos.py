"""The Python client sends protocol 2.1.0's ``qos`` (``rwt.Topic(..., qos=...)``), D62-D63."""

from __future__ import annotations

import anyio
import pytest

import rwt
from rwt.types import Durability
from rwt_protocol.qos import QosProfile

pytestmark = pytest.mark.anyio

STRING = "std_msgs/msg/String"


async def test_a_late_transient_local_topic_gives_the_last_n(url: str) -> None:
    durable = QosProfile(durability=Durability.TRANSIENT_LOCAL, depth=2)
    async with rwt.Ros(url) as pub, rwt.Ros(url) as sub:
        topic = rwt.Topic(pub, "/kept", STRING, qos=durable)
        for text in ("a", "b", "c"):
            await topic.publish({"data": text})
        await pub.get_topics()  # every publish was handled
        got: list[object] = []
        late = rwt.Topic(sub, "/kept", STRING, qos=durable)
        await late.subscribe(lambda msg: got.append(msg["data"]), confirm=True)
        with anyio.fail_after(10):
            while len(got) < 2:
                await anyio.sleep(0.01)
        assert got == ["b", "c"]


async def test_a_volatile_subscription_gets_nothing_kept(url: str) -> None:
    durable = QosProfile(durability=Durability.TRANSIENT_LOCAL, depth=2)
    async with rwt.Ros(url) as pub, rwt.Ros(url) as sub:
        topic = rwt.Topic(pub, "/kept", STRING, qos=durable)
        await topic.publish({"data": "kept"})
        await pub.get_topics()  # the publish was handled
        got: list[object] = []
        volatile = rwt.Topic(sub, "/kept", STRING, qos=QosProfile())
        await volatile.subscribe(lambda msg: got.append(msg["data"]), confirm=True)
        await sub.get_topics()  # anything kept would have come before its answer
        assert got == []
        await topic.publish({"data": "new"})
        with anyio.fail_after(10):
            while not got:
                await anyio.sleep(0.01)
        assert got == ["new"]
