"""Every parameter text of the fuzz grammar leaves the parameters readable by everyone.

``grammar.PARAM_TEXTS`` are the JSON texts the fuzzer puts in rosapi's
``set_param`` ``value`` and ``get_param`` ``default_value`` (lone surrogates, huge
integers, 100,000-deep nesting, NaN, giant strings). Each is sent by one client;
each call is answered, and another client then reads every parameter (ROS 2) or
the whole tree (ROS 1) successfully, in both dialects.
"""

from __future__ import annotations

import json
import random
from typing import Any

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from tests.fuzz import grammar
from tests.support.clients import Client, is_op, running_server

pytestmark = pytest.mark.anyio

TIMEOUT_S = 60
#: ROS 2: a node of the program, where a client may create parameters (D34)
NAME = {Dialect.ROS1: "/fuzz/p", Dialect.ROS2: "/robot:fuzz"}


async def call(client: Client, service: str, args: dict[str, Any], tag: str) -> Any:
    await client.send(
        {"op": "call_service", "service": f"/rosapi/{service}", "args": args, "id": tag}
    )
    return await client.expect(is_op("service_response", id=tag))


async def read_all(client: Client, dialect: Dialect, tag: str) -> None:
    """Read every parameter; each read must succeed with JSON text."""
    if dialect is Dialect.ROS1:
        reply = await call(client, "get_param", {"name": "/", "default": ""}, tag)
        assert reply["result"] is True, reply
        json.loads(reply["values"]["value"])
        return
    names = (await call(client, "get_param_names", {}, tag))["values"]["names"]
    for name in names:
        reply = await call(client, "get_param", {"name": name, "default_value": ""}, tag + name)
        assert reply["result"] is True and reply["values"]["successful"] is True, reply
        json.loads(reply["values"]["value"])


@pytest.mark.parametrize("dialect", [Dialect.ROS1, Dialect.ROS2])
async def test_every_grammar_text_is_answered_and_parameters_stay_readable(
    dialect: Dialect,
) -> None:
    rng = random.Random(7)
    default_key = "default" if dialect is Dialect.ROS1 else "default_value"
    with anyio.fail_after(TIMEOUT_S):
        graph = Graph(TypeRegistry(dialect))
        graph.create_publisher("/robot/state", "std_msgs/msg/String", node="/robot")
        async with running_server(graph=graph) as harness:
            sender = await harness.connect("ws", "sender")
            reader = await harness.connect("ws", "reader")
            for index, gen in enumerate(grammar.PARAM_TEXTS):
                text = gen(rng)
                args = {"name": NAME[dialect], "value": text}
                reply = await call(sender, "set_param", args, f"set{index}")
                assert reply["op"] == "service_response", reply
                args = {"name": "/unset" if dialect is Dialect.ROS1 else "/robot:unset"}
                reply = await call(sender, "get_param", {**args, default_key: text}, f"get{index}")
                assert reply["result"] is True, (index, reply)
                json.loads(reply["values"]["value"])
                await read_all(reader, dialect, f"read{index}")
