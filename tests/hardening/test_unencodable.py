"""Unencodable values over every transport: the server stays up, everyone else is served.

A lone surrogate (JSON ``"\\ud800"``) or an integer too large to print (a CBOR
bignum) in an ``id``, a name or a service response once made the reply fail to
encode: the exception ended the whole server over UDP and stdio, and the
connection over WebSocket and TCP. Now such values are refused at the edge with
an error status (docs/limits.md), and a reply that still cannot be encoded is
replaced by its failure reply.
"""

from __future__ import annotations

import json

import anyio
import cbor2
import pytest

from tests.support.clients import (
    TRANSPORTS,
    Client,
    Harness,
    MemoryClient,
    WsClient,
    is_op,
)

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10
TRIGGER = "std_srvs/srv/Trigger"

# Written as JSON text: json.dumps would escape a Python surrogate the same way.
SURROGATE_FRAMES = {
    "id": b'{"op":"call_service","service":"/rosapi/topics","id":"\\ud800"}',
    "topic": b'{"op":"advertise","topic":"/bad\\ud800","type":"std_msgs/String","id":"t"}',
    "service": b'{"op":"advertise_service","service":"/s\\udfff","type":"std_srvs/srv/Trigger"}',
    "param-name": (
        b'{"op":"call_service","service":"/rosapi/set_param",'
        b'"args":{"name":"/rwt:\\ud800","value":"1"}}'
    ),
    "message-field": b'{"op":"publish","topic":"/probe","msg":{"data":"\\ud800"}}',
}


async def still_served(client: Client, harness: Harness, tag: str) -> None:
    """The sender keeps being served, a fresh client too, and rosapi answers."""
    await client.send({"op": "set_level", "level": "info", "id": f"{tag}-alive"})
    assert (await client.expect(is_op("status", id=f"{tag}-alive")))["level"] == "info"
    fresh = await harness.connect("ws", f"fresh-{tag}")
    await fresh.send({"op": "call_service", "service": "/rosapi/topics", "id": "topics"})
    reply = await fresh.expect(is_op("service_response", id="topics"))
    assert reply["result"] is True, reply
    assert all("\\" not in name for name in reply["values"]["topics"])
    await fresh.send({"op": "call_service", "service": "/rosapi/get_param_names", "id": "p"})
    assert (await fresh.expect(is_op("service_response", id="p")))["result"] is True


async def send_cbor(client: Client, op: dict[str, object]) -> None:
    await send_binary(client, cbor2.dumps(op))


async def send_binary(client: Client, data: bytes) -> None:
    """Send one CBOR item as the transport carries binary frames."""
    if isinstance(client, MemoryClient):
        assert client.connection is not None
        await client.connection.send_frame(data, binary=True)
    elif isinstance(client, WsClient):
        assert client.ws is not None
        await client.ws.send(data)  # a binary message
    else:
        await client.send_raw(data)  # TCP and UDP tell CBOR from JSON by its first byte


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize("field", SURROGATE_FRAMES)
async def test_a_lone_surrogate_gets_an_error_status(
    harness: Harness, transport: str, field: str
) -> None:
    client = await harness.connect(transport)
    with anyio.fail_after(TIMEOUT_S):
        await client.send_raw(SURROGATE_FRAMES[field] + client.terminator)
        status = await client.expect(is_op("status"))
        assert status["level"] == "error" and "lone surrogate" in status["msg"]
        await still_served(client, harness, field)


@pytest.mark.parametrize("transport", [t for t in TRANSPORTS if t != "stdio"])  # stdio: JSON lines
async def test_a_cbor_integer_too_large_to_print_gets_an_error_status(
    harness: Harness, transport: str
) -> None:
    client = await harness.connect(transport)
    with anyio.fail_after(TIMEOUT_S):
        await send_cbor(client, {"op": "call_service", "service": "/rosapi/topics", "id": 10**5000})
        status = await client.expect(is_op("status"))
        assert status["level"] == "error" and "integer out of range" in status["msg"]
        await still_served(client, harness, "cbor")


@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_a_caller_with_a_timeout_hears_back_when_the_provider_answers_garbage(
    harness: Harness, transport: str
) -> None:
    provider = await harness.connect(transport, "provider")
    caller = await harness.connect("ws", "caller")
    with anyio.fail_after(TIMEOUT_S):
        await provider.send({"op": "advertise_service", "service": "/trig", "type": TRIGGER})
        await provider.send({"op": "set_level", "level": "info", "id": "ready"})
        await provider.expect(is_op("status", id="ready"))
        await caller.send({"op": "call_service", "service": "/trig", "id": "c", "timeout": 0.5})
        request = await provider.expect(is_op("call_service"))
        bad = json.dumps(
            {
                "op": "service_response",
                "service": "/trig",
                "id": request["id"],
                "result": True,
                "values": {"success": True, "message": "\ud800"},
            }
        )
        await provider.send_raw(bad.encode() + provider.terminator)
        status = await provider.expect(is_op("status", level="error"))
        assert "lone surrogate" in status["msg"]
        reply = await caller.expect(is_op("service_response", id="c"))
        assert reply["result"] is False and "timed out" in reply["values"]
        await still_served(provider, harness, "provider")
