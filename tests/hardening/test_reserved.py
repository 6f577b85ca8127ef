"""Names the server owns cannot be taken over by a client (docs/limits.md, reserved names).

Before, any client could advertise over ``/rosapi/*``, the TF republisher or the
server's client topics; newest-wins then handed it other clients' requests (even
``set_param`` values) and let it forge answers, and the built-in was gone for good
once it left. Every test uses real sockets and checks the built-in still serves
another client afterwards.
"""

from __future__ import annotations

from collections.abc import AsyncIterator

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.clients import TRANSPORTS, Client, Harness, is_op, running_server

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10

ATTEMPTS = {
    "rosapi": {
        "op": "advertise_service",
        "service": "/rosapi/topics",
        "type": "rosapi_msgs/srv/Topics",
    },
    "rosapi-params": {
        "op": "advertise_service",
        "service": "/rosapi/set_param",
        "type": "rosapi_msgs/srv/SetParam",
    },
    "republish_tfs": {
        "op": "advertise_service",
        "service": "republish_tfs",
        "type": "tf2_web_republisher_interfaces/srv/RepublishTFs",
    },
    "tf-action": {
        "op": "advertise_action",
        "action": "/tf2_web_republisher",
        "type": "tf2_web_republisher_msgs/action/TFSubscription",
    },
    "tf-cancel": {
        "op": "advertise_service",
        "service": "/tf2_web_republisher/_action/cancel_goal",
        "type": "action_msgs/srv/CancelGoal",
    },
    "client_count": {"op": "advertise", "topic": "/client_count", "type": "std_msgs/Int32"},
    "connected_clients": {
        "op": "publish",
        "topic": "/connected_clients",
        "msg": {"clients": []},
    },
    "tf_repub": {"op": "advertise", "topic": "/tf_repub_7", "type": "std_msgs/String"},
    "embedded-service": {
        "op": "advertise_service",
        "service": "/lights",
        "type": "std_srvs/srv/SetBool",
    },
}


def robot() -> Graph:
    graph = Graph()
    graph.create_service("/lights", "std_srvs/srv/SetBool", lambda req: {"success": True})
    return graph


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    async with running_server(graph=robot()) as h:
        yield h


async def rosapi_topics(client: Client, tag: str) -> list[str]:
    await client.send({"op": "call_service", "service": "/rosapi/topics", "id": tag})
    reply = await client.expect(is_op("service_response", id=tag))
    assert reply["result"] is True, reply
    return reply["values"]["topics"]  # type: ignore[no-any-return]


@pytest.mark.parametrize("attempt", ATTEMPTS)
@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_a_reserved_name_cannot_be_taken(
    harness: Harness, transport: str, attempt: str
) -> None:
    attacker = await harness.connect(transport, "attacker")
    other = await harness.connect("ws", "other")
    with anyio.fail_after(TIMEOUT_S):
        await attacker.send({**ATTEMPTS[attempt], "id": "take"})
        status = await attacker.expect(is_op("status", id="take"))
        assert status["level"] == "error"
        assert "is reserved by the server" in status["msg"]
        # the built-ins answer the other client, not the attacker
        assert "/client_count" in await rosapi_topics(other, "after")
        await other.send(
            {"op": "call_service", "service": "/lights", "args": {"data": True}, "id": "l"}
        )
        assert (await other.expect(is_op("service_response", id="l")))["values"]["success"]
        await other.send({"op": "subscribe", "topic": "/client_count", "id": "count"})
        count = await other.expect(is_op("publish", topic="/client_count"))
        assert count["msg"]["data"] >= 1  # the server's own count
    if transport != "stdio":  # the stdio session is the server's lifeline: it stays
        await attacker.aclose()
    with anyio.fail_after(TIMEOUT_S):
        assert "/client_count" in await rosapi_topics(other, "gone")  # still there


#: rosapi services only the other dialect has, and a service type this dialect knows.
OTHER_DIALECT = {
    Dialect.ROS1: (
        [
            "/rosapi/get_ros_version",
            "/rosapi/interfaces",
            "/rosapi/action_type",
            "/rosapi/action_goal_details",
            "/rosapi/action_result_details",
            "/rosapi/action_feedback_details",
        ],
        "std_srvs/Trigger",
    ),
    Dialect.ROS2: (["/rosapi/search_param", "/rosapi/service_host"], "std_srvs/srv/Trigger"),
}


@pytest.mark.parametrize("dialect", [Dialect.ROS1, Dialect.ROS2])
@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_rosapi_names_of_the_other_dialect_are_reserved(
    transport: str, dialect: Dialect
) -> None:
    names, type_name = OTHER_DIALECT[dialect]
    with anyio.fail_after(TIMEOUT_S):
        async with running_server(graph=Graph(TypeRegistry(dialect))) as harness:
            attacker = await harness.connect(transport, "attacker")
            other = await harness.connect("memory", "other")
            for name in names:
                await attacker.send(
                    {"op": "advertise_service", "service": name, "type": type_name, "id": name}
                )
                status = await attacker.expect(is_op("status", id=name))
                assert status["level"] == "error"
                assert (
                    status["msg"] == f"advertise_service: service {name} is reserved by the server"
                )
            # no forged answer: the call finds no provider
            await other.send({"op": "call_service", "service": names[0], "id": "forged?"})
            reply = await other.expect(is_op("service_response", id="forged?"))
            assert reply["result"] is False, reply
            await other.send({"op": "call_service", "service": "/rosapi/nodes", "id": "n"})
            assert (await other.expect(is_op("service_response", id="n")))["result"] is True


async def test_a_client_service_can_still_be_replaced_by_another_client(harness: Harness) -> None:
    # D15 (newest advertiser wins) holds between clients.
    first, second = await harness.connect("ws", "first"), await harness.connect("ws", "second")
    with anyio.fail_after(TIMEOUT_S):
        await first.send({"op": "set_level", "level": "warning"})
        for client in (first, second):
            await client.send(
                {"op": "advertise_service", "service": "/mine", "type": "std_srvs/srv/Trigger"}
            )
        lost = await first.expect(is_op("status"))
        assert "replaced by a newer advertiser" in lost["msg"]


async def test_rosapi_is_exempt_from_service_rules_only_for_calls() -> None:
    config = ServerConfig(
        rosapi=False, session=SessionConfig(access=AccessPolicy(services=("/robot/*",)))
    )
    async with running_server(config) as harness:
        client = await harness.connect("ws")
        with anyio.fail_after(TIMEOUT_S):
            await client.send(
                {
                    "op": "advertise_service",
                    "service": "/rosapi/topics",
                    "type": "rosapi_msgs/srv/Topics",
                    "id": "a",
                }
            )
            status = await client.expect(is_op("status", id="a"))
            assert "is not allowed on this server" in status["msg"]
