"""JSON text a client puts in a parameter value obeys the rules of frames (docs/limits.md).

rosapi's ``set_param`` carries its value as JSON text inside a string field, so the
frame decoder's rules never saw it: ``"\\ud800"`` (a lone surrogate) was stored,
after which ROS 1's ``get_param`` of ``/`` (and of every enclosing namespace)
failed for every client and the ROS 2 parameter could not be read; a value nested
100,000 deep raised a traceback per request. Now such text is refused with a clear
reason, on every transport and in both dialects, and the tree stays readable by the
other clients (raw clients and the unmodified roslibpy).
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from tests.support.clients import TRANSPORTS, Client, Harness, running_server
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio

TIMEOUT_S = 20
DEEP = 20_000  # far past the limit of 100 and the interpreter's recursion limit; fits a datagram

#: Hostile value texts and a part of the reason each is refused with.
HOSTILE = {
    "lone surrogate": ('"\\ud800"', "lone surrogate"),
    "surrogate in a dict": ('{"k": ["ok", "\\udfff"]}', "lone surrogate"),
    "deep nesting": ("[" * DEEP + "]" * DEEP, "nesting deeper than 100"),
    "70-bit integer": (str(2**70), "does not fit in 64 bits"),
    "5000 digits": ("7" * 5000, "invalid JSON"),
}

#: A parameter name each dialect accepts on a fresh server (ROS 2: on a node that exists
#: and is the robot's, not the server's: docs/decisions.md, D34).
NAMES = {Dialect.ROS1: "/robot/bad", Dialect.ROS2: "/robot:bad"}
GOOD = {Dialect.ROS1: "/robot/speed", Dialect.ROS2: "/robot:speed"}


@asynccontextmanager
async def server_in(dialect: Dialect) -> AsyncIterator[Harness]:
    graph = Graph(TypeRegistry(dialect))
    graph.create_publisher("/robot/state", "std_msgs/msg/String", node="/robot")
    async with running_server(graph=graph) as harness:
        yield harness


async def rosapi(client: Client, service: str, args: dict[str, Any], call_id: str) -> Any:
    await client.send(
        {"op": "call_service", "service": f"/rosapi/{service}", "args": args, "id": call_id}
    )
    return await client.expect(
        lambda m: m.get("op") == "service_response" and m.get("id") == call_id
    )


def accepted(reply: dict[str, Any], dialect: Dialect) -> bool:
    if dialect is Dialect.ROS2:
        return reply["result"] is True and reply["values"]["successful"] is True
    return reply["result"] is True


def refusal(reply: dict[str, Any], dialect: Dialect) -> str:
    """The reason of a refused ``set_param``: ROS 2 ``successful: false``, ROS 1 a failed call."""
    if dialect is Dialect.ROS2:
        assert reply["result"] is True and reply["values"]["successful"] is False, reply
        return str(reply["values"]["reason"])
    assert reply["result"] is False, reply
    return str(reply["values"])


async def set_param(client: Client, name: str, text: str, call_id: str) -> Any:
    return await rosapi(client, "set_param", {"name": name, "value": text}, call_id)


async def tree(client: Client, dialect: Dialect) -> object:
    """What another client reads: ROS 1 the whole tree ``/``, ROS 2 every parameter by name."""
    if dialect is Dialect.ROS1:
        reply = await rosapi(client, "get_param", {"name": "/", "default": ""}, "tree")
        assert reply["result"] is True, reply
        return json.loads(reply["values"]["value"])
    names = (await rosapi(client, "get_param_names", {}, "names"))["values"]["names"]
    values = {}
    for name in names:
        reply = await rosapi(client, "get_param", {"name": name, "default_value": ""}, name)
        assert reply["result"] is True and reply["values"]["successful"] is True, reply
        values[name] = json.loads(reply["values"]["value"])
    return values


@pytest.mark.parametrize("dialect", [Dialect.ROS1, Dialect.ROS2])
@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_hostile_value_text_is_refused_and_the_tree_stays_readable(
    transport: str, dialect: Dialect
) -> None:
    with anyio.fail_after(TIMEOUT_S):
        async with server_in(dialect) as harness:
            client = await harness.connect(transport)
            other = await harness.connect("memory", "other")
            assert accepted(await set_param(client, GOOD[dialect], "1.5", "good"), dialect)
            for label, (text, reason) in HOSTILE.items():
                reply = await set_param(client, NAMES[dialect], text, label)
                assert reason in refusal(reply, dialect), (label, reply)
            expected = (
                {"robot": {"speed": 1.5}} if dialect is Dialect.ROS1 else {GOOD[dialect]: 1.5}
            )
            assert await tree(other, dialect) == expected
            assert await tree(client, dialect) == expected


async def test_nan_and_infinity_from_python_clients_are_kept_and_read_back_as_null() -> None:
    with anyio.fail_after(TIMEOUT_S):
        async with server_in(Dialect.ROS2) as harness:
            client = await harness.connect("ws")
            reply = await set_param(client, "/robot:gain", "[NaN, Infinity, 1]", "nan")
            assert reply["values"]["successful"] is True, reply
            stored = harness.server.graph.params.get("/robot:gain")
            assert isinstance(stored, tuple) and stored[1:] == (math.inf, 1)
            assert isinstance(stored[0], float) and math.isnan(stored[0])
            reply = await rosapi(
                client, "get_param", {"name": "/robot:gain", "default_value": ""}, "g"
            )
            assert json.loads(reply["values"]["value"]) == [None, None, 1.0]  # D10


@pytest.mark.parametrize("dialect", [Dialect.ROS1, Dialect.ROS2])
async def test_roslibpy_lone_surrogate_is_refused_and_others_read_the_tree(
    dialect: Dialect,
) -> None:
    async with server_in(dialect) as harness:
        port = harness.port("websocket")
        out = await run_python(
            f"""
            import os, sys
            import roslibpy
            ros = roslibpy.Ros("127.0.0.1", {port})
            ros.run(timeout=20)
            roslibpy.Param(ros, {GOOD[dialect]!r}).set(2.5, timeout=20)
            failed = []
            try:  # ROS 1 fails the call; ROS 2 answers successful: false
                reply = roslibpy.Service(ros, "/rosapi/set_param", "rosapi/SetParam").call(
                    {{"name": {NAMES[dialect]!r}, "value": '"\\\\ud800"'}}, timeout=20
                )
                failed.append(reply["reason"])
            except Exception as exc:
                failed.append(str(exc))
            print("refused:", "lone surrogate" in failed[0])
            reader = roslibpy.Ros("127.0.0.1", {port})
            reader.run(timeout=20)
            name = "/" if {dialect is Dialect.ROS1} else {GOOD[dialect]!r}
            print("read:", roslibpy.Param(reader, name).get(timeout=20))
            print("bad:", roslibpy.Param(reader, {NAMES[dialect]!r}).get(timeout=20))
            sys.stdout.flush()
            os._exit(0)  # two connections: roslibpy's terminate() stops the shared reactor
            """
        )
    expected_tree = "{'robot': {'speed': 2.5}}" if dialect is Dialect.ROS1 else "2.5"
    assert out.splitlines() == ["refused: True", f"read: {expected_tree}", "bad: None"]


async def test_a_flood_of_deep_values_logs_little_and_others_are_served(
    caplog: pytest.LogCaptureFixture,
) -> None:
    deep = "[" * 2000 + "]" * 2000  # past the interpreter's recursion limit
    with anyio.fail_after(120):
        async with server_in(Dialect.ROS1) as harness:
            client = await harness.connect("ws")
            other = await harness.connect("memory", "other")
            caplog.clear()
            with caplog.at_level(logging.INFO):
                for i in range(1000):
                    await client.send(
                        {
                            "op": "call_service",
                            "service": "/rosapi/set_param",
                            "args": {"name": "/deep", "value": deep},
                            "id": i,
                        }
                    )
                replies = [
                    await client.expect(lambda m: m.get("op") == "service_response")
                    for _ in range(1000)
                ]
                assert all(r["result"] is False for r in replies)
                assert "nesting deeper than 100" in replies[-1]["values"]
                assert await tree(other, Dialect.ROS1) == {}
            logged = [r for r in caplog.records if r.name.startswith("rwt")]
            assert len(logged) <= 5, [r.getMessage()[:200] for r in logged]
            assert sum(len(r.getMessage()) + len(r.exc_text or "") for r in logged) < 2000


async def own_node(client: Client, tag: str) -> str:
    """The node of ``client``'s connection: the publisher of a topic it advertises."""
    await client.send({"op": "advertise", "topic": f"/owner_{tag}", "type": "std_msgs/String"})
    reply = await rosapi(client, "publishers", {"topic": f"/owner_{tag}"}, f"who_{tag}")
    [node] = reply["values"]["publishers"]
    return str(node)


async def test_one_client_cannot_fill_the_store_on_every_node_it_can_name() -> None:
    per_node = 700  # 2,800 in all, past its share of 1,250 (the store holds 10,000)
    with anyio.fail_after(120):
        async with server_in(Dialect.ROS2) as harness:
            params = harness.server.graph.params
            flood = await harness.connect("ws", "flood")
            bystander = await harness.connect("ws", "bystander")
            mine, theirs = await own_node(flood, "flood"), await own_node(bystander, "by")
            targets = [mine, theirs, "/rosapi", "/robot"]
            for node in targets:  # sent at once, answered in order
                for n in range(per_node):
                    args = {"name": f"{node}:p{n:04}", "value": str(n)}
                    call = {"op": "call_service", "service": "/rosapi/set_param", "args": args}
                    await flood.send({**call, "id": f"{node}:{n}"})
            replies = [
                await flood.expect(lambda m: m.get("op") == "service_response")
                for _ in range(per_node * len(targets))
            ]
            taken = [r["id"] for r in replies if r["values"]["successful"]]
            reasons = {r["values"]["reason"].split(":")[0] for r in replies if r["id"] not in taken}
            # its own node, then the robot's until its share was spent; never the others'
            share = params.max_client_params
            assert len(taken) == share == 1250
            assert taken[:per_node] == [f"{mine}:{n}" for n in range(per_node)]
            assert all(each.startswith("/robot:") for each in taken[per_node:])
            assert reasons == {
                "this client holds its share of the parameter store (1250 parameters)",
                f"node {theirs} is another client's",
                "node /rosapi is the server's",
            }
            # the bystander's own set goes on, and it is served
            reply = await set_param(bystander, f"{theirs}:speed", "1.5", "by")
            assert accepted(reply, Dialect.ROS2)
            assert (await rosapi(bystander, "get_time", {}, "t"))["result"] is True
            await flood.aclose()
            # the flood's node goes with it; what it left on the robot stays, within a share
            for n in range(200):
                reply = await rosapi(bystander, "get_param_names", {}, f"n{n}")
                names = reply["values"]["names"]
                if not any(name.startswith(f"{mine}:") for name in names):
                    break
                await anyio.sleep(0.05)
            assert not any(name.startswith(f"{mine}:") for name in names)
            assert sum(name.startswith("/robot:") for name in names) == share - per_node
            assert f"{theirs}:speed" in names
