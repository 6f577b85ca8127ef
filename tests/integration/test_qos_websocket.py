"""Protocol 2.1.0's ``qos`` from a plain WebSocket client (the ``websockets`` library), D62-D64.

What a new user tries by hand: a transient-local topic of depth 1 and of depth 5 and a
late subscriber; a stored message past its lifespan; a bad ``qos``; and what the server
says of its version, to ``GET /version`` and to ``rwt conformance``.

The graph's clock runs ahead of the real one by an offset the test moves, so a
message "ages" without the test waiting (``Ahead``); the subscribers' queues take
frames by the real clock, behind the graph's, so nothing there expires early.
"""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING

import anyio
import httpx
import pytest
from websockets.asyncio.client import connect

import rwt
from rwt_protocol.server.compat import Compat
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.cli import run_rwt
from tests.support.clients import running_server

if TYPE_CHECKING:
    from websockets.asyncio.client import ClientConnection

pytestmark = pytest.mark.anyio

STRING = "std_msgs/msg/String"


class Ahead:
    """The real clocks plus ``offset`` seconds (an ``rwt.Clock``)."""

    def __init__(self) -> None:
        self.offset = 0.0

    def monotonic(self) -> float:
        return time.monotonic() + self.offset

    def wall(self) -> float:
        return time.time() + self.offset


async def _ws(port: int) -> ClientConnection:
    return await connect(f"ws://127.0.0.1:{port}", ping_interval=None)


async def _send(ws: ClientConnection, **op: object) -> None:
    await ws.send(json.dumps(op))


async def _sync(ws: ClientConnection) -> list[dict[str, object]]:
    """Everything the server sent before it answered a call sent now (in order)."""
    await _send(ws, op="call_service", service="/rosapi/get_time", id="sync")
    got: list[dict[str, object]] = []
    with anyio.fail_after(20):
        while True:
            op = json.loads(await ws.recv())
            if op.get("id") == "sync" and op["op"] == "service_response":
                return got
            got.append(op)


def _data(ops: list[dict[str, object]]) -> list[object]:
    return [op["msg"]["data"] for op in ops if op["op"] == "publish"]  # type: ignore[index]


async def test_late_subscribers_get_the_last_n_of_a_transient_local_topic_in_order() -> None:
    async with running_server() as server:
        port = server.port("websocket")
        pub = await _ws(port)
        for depth in (1, 5):
            topic = f"/map_{depth}"
            qos = {"durability": "transient_local", "depth": depth}
            await _send(pub, op="advertise", topic=topic, type=STRING, qos=qos)
            for i in range(8):
                await _send(pub, op="publish", topic=topic, msg={"data": f"m{i}"})
            await _sync(pub)
            late, volatile = await _ws(port), await _ws(port)
            await _send(late, op="subscribe", topic=topic, qos=qos)
            await _send(volatile, op="subscribe", topic=topic, qos={"durability": "volatile"})
            assert _data(await _sync(late)) == [f"m{i}" for i in range(8 - depth, 8)]
            assert _data(await _sync(volatile)) == []
            await late.close()
            await volatile.close()
        await pub.close()


async def test_a_stored_message_past_its_lifespan_is_not_delivered_a_fresh_one_is() -> None:
    clock = Ahead()
    async with running_server(graph=rwt.Graph(clock=clock)) as server:
        port = server.port("websocket")
        pub = await _ws(port)
        qos = {"durability": "transient_local", "depth": 5, "lifespan": 2.0}
        await _send(pub, op="advertise", topic="/t", type=STRING, qos=qos)
        await _send(pub, op="publish", topic="/t", msg={"data": "old"})
        await _sync(pub)
        clock.offset += 10  # "old" is ten seconds old now
        await _send(pub, op="publish", topic="/t", msg={"data": "fresh"})
        await _sync(pub)
        late = await _ws(port)
        await _send(late, op="subscribe", topic="/t", qos={"durability": "transient_local"})
        assert _data(await _sync(late)) == ["fresh"]


async def test_a_bad_qos_is_refused_naming_the_field_and_the_topic_is_usable_after() -> None:
    async with running_server() as server:
        port = server.port("websocket")
        pub, sub = await _ws(port), await _ws(port)
        bad = {"depth": -3, "durability": "forever"}
        await _send(pub, op="advertise", topic="/t", type=STRING, qos=bad, id="a1")
        [status] = [op for op in await _sync(pub) if op["op"] == "status"]
        assert status == {
            "op": "status",
            "level": "error",
            "msg": "advertise: expected a number >= 0, got -3 at $.qos.depth",
            "id": "a1",
        }
        await _send(sub, op="subscribe", topic="/t", qos={"durability": "forever"}, id="s1")
        [status] = [op for op in await _sync(sub) if op["op"] == "status"]
        assert status["id"] == "s1" and str(status["msg"]).endswith("at $.qos.durability")
        good = {"durability": "transient_local", "depth": 1}
        await _send(pub, op="advertise", topic="/t", type=STRING, qos=good, id="a2")
        await _send(pub, op="publish", topic="/t", msg={"data": "ok"})
        assert [op for op in await _sync(pub) if op["op"] == "status"] == []
        await _send(sub, op="subscribe", topic="/t", qos=good)
        assert _data(await _sync(sub)) == ["ok"]


async def test_the_server_says_2_1_0_and_the_conformance_suite_judges_it_so() -> None:
    async with running_server() as server:
        port = server.port("websocket")
        async with httpx.AsyncClient() as http:
            version = (await http.get(f"http://127.0.0.1:{port}/version")).json()
        assert version["protocol"] == {"major": 2, "minor": 1, "patch": 0}
        url = f"ws://127.0.0.1:{port}"
        run = await anyio.to_thread.run_sync(lambda: run_rwt("conformance", url, "--only", "qos.*"))
    assert "spec version 2.1.0 (from GET /version)" in run.stdout, run.stdout + run.stderr
    assert run.returncode == 0, run.stdout + run.stderr


async def _status(ws: ClientConnection) -> dict[str, object]:
    """The next status the server sends ``ws`` (other frames skipped)."""
    with anyio.fail_after(20):
        while True:
            op = json.loads(await ws.recv())
            if op["op"] == "status":
                return op  # type: ignore[no-any-return]


async def test_a_publisher_is_told_of_a_subscription_its_offer_cannot_meet() -> None:
    # ROS 2's "offered incompatible QoS", which rosbridge_suite never passes on (D64)
    async with running_server() as server:
        port = server.port("websocket")
        pub, sub = await _ws(port), await _ws(port)
        await _send(pub, op="set_level", level="warning")
        await _send(
            pub,
            op="advertise",
            topic="/scan",
            type=STRING,
            id="adv",
            qos={"reliability": "best_effort"},
        )
        await _sync(pub)
        await _send(sub, op="subscribe", topic="/scan", qos={"reliability": "reliable"})
        told = await _status(pub)
        assert told["level"] == "warning" and told["id"] == "adv"
        assert str(told["msg"]).startswith("advertise: /scan offers keep_last 10, best_effort")
        assert "(reliability: reliable asked of a best_effort publisher)" in str(told["msg"])
        await _send(pub, op="publish", topic="/scan", msg={"data": "lost"})
        assert _data(await _sync(sub)) == []  # as ROS 2: the pair is not matched
        await pub.close()
        await sub.close()


async def test_a_publisher_that_misses_its_offered_deadline_is_told() -> None:
    # ROS 2's "offered deadline missed" (D65): the client advertised with a deadline
    async with running_server() as server:
        pub = await _ws(server.port("websocket"))
        await _send(pub, op="set_level", level="warning")
        await _send(pub, op="advertise", topic="/beat", type=STRING, id="b", qos={"deadline": 0.2})
        await _send(pub, op="publish", topic="/beat", msg={"data": "once"})
        assert await _status(pub) == {
            "op": "status",
            "level": "warning",
            "msg": "advertise: /beat missed its offered deadline: nothing published for 0.2 s",
            "id": "b",
        }
        await pub.close()


async def test_compat_rosbridge_2_1_ignores_a_malformed_qos_as_any_unknown_field() -> None:
    # rosbridge_suite 2.1.0 (protocol 2.0.0) knows no qos: whatever it holds is not read (D62)
    config = ServerConfig(session=SessionConfig(compat=Compat.ROSBRIDGE_2_1))
    async with running_server(config) as server:
        port = server.port("websocket")
        pub, sub = await _ws(port), await _ws(port)
        for ws in (pub, sub):  # statuses only once asked for, as rosbridge_suite sends none
            await _send(ws, op="set_level", level="warning")
        bad = {"depth": -3, "durability": "forever"}
        await _send(pub, op="advertise", topic="/t", type=STRING, qos=bad, id="a1")
        await _send(sub, op="subscribe", topic="/t", qos={"lifespan": "soon", "history": 7})
        assert await _sync(sub) == []
        await _send(pub, op="publish", topic="/t", msg={"data": "ok"}, qos=[1, 2])
        assert await _sync(pub) == []  # no error, no warning
        assert await _sync(sub) == [{"op": "publish", "topic": "/t", "msg": {"data": "ok"}}]
        await pub.close()
        await sub.close()
