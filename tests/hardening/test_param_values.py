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

#: A parameter name each dialect accepts on a fresh server (ROS 2: on a node that exists).
NAMES = {Dialect.ROS1: "/robot/bad", Dialect.ROS2: "/rosapi:bad"}
GOOD = {Dialect.ROS1: "/robot/speed", Dialect.ROS2: "/rosapi:speed"}


@asynccontextmanager
async def server_in(dialect: Dialect) -> AsyncIterator[Harness]:
    async with running_server(graph=Graph(TypeRegistry(dialect))) as harness:
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
            reply = await set_param(client, "/rosapi:gain", "[NaN, Infinity, 1]", "nan")
            assert reply["values"]["successful"] is True, reply
            stored = harness.server.graph.params.get("/rosapi:gain")
            assert isinstance(stored, list) and stored[1:] == [math.inf, 1]
            assert isinstance(stored[0], float) and math.isnan(stored[0])
            reply = await rosapi(
                client, "get_param", {"name": "/rosapi:gain", "default_value": ""}, "g"
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
