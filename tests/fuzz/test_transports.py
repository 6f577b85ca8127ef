"""Fuzzed frames over every transport keep the hardening invariant.

For each transport, hypothesis sends short bursts of grammar-built frames (every
op of the spec, valid and with hostile fields, JSON and CBOR, and raw hostile
frames) on a fresh connection, then a barrier. The server must answer only with
status frames or replies of the ops sent, or close cleanly (``driver``); and after
every burst, the bystanders connected since the start (memory, WebSocket, TCP,
UDP) still get their subscribe/publish round trip and a ``/rosapi/topics`` answer,
which also shows the server is still up.
"""

from __future__ import annotations

import itertools

import anyio
import pytest
from hypothesis import given
from websockets.asyncio.client import connect

from tests.fuzz import driver
from tests.fuzz.conftest import FUZZ, Live
from tests.fuzz.strategies import sequences
from tests.support.clients import TRANSPORTS, Client, Harness, is_op

TIMEOUT_S = 5.0
UDP_FRAME_BYTES = 60_000  # under the 65,507-byte datagram limit
_tags = itertools.count()
_stdio: dict[int, driver.Wire | None] = {}


async def connect_bystanders(harness: Harness) -> list[Client]:
    """One client per socket transport, each subscribed to and advertising its own topic."""
    bystanders = []
    for transport in ("memory", "ws", "tcp", "udp"):
        client = await harness.connect(transport, f"bystander-{transport}")
        topic = f"/bystander/{transport}"
        with anyio.fail_after(TIMEOUT_S):
            await client.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
            await client.send({"op": "advertise", "topic": topic, "type": "std_msgs/String"})
            await client.send({"op": "set_level", "level": "info", "id": "ready"})
            await client.expect(is_op("status", id="ready"))
        bystanders.append(client)
    return bystanders


async def check_bystanders(bystanders: list[Client], tag: str) -> None:
    """Each bystander gets its own publish back and a ``/rosapi/topics`` answer."""
    for client in bystanders:
        topic = f"/bystander/{client.name.removeprefix('bystander-')}"
        try:
            with anyio.fail_after(TIMEOUT_S):
                await client.send({"op": "publish", "topic": topic, "msg": {"data": tag}})
                await client.expect(
                    lambda m: m.get("op") == "publish" and m.get("msg") == {"data": tag}
                )
                await client.send({"op": "call_service", "service": "/rosapi/topics", "id": tag})
                reply = await client.expect(is_op("service_response", id=tag))
        except Exception as exc:
            raise driver.Violation(f"bystander {client.name} not served: {exc!r}") from exc
        if reply.get("result") is not True or topic not in reply["values"]["topics"]:
            raise driver.Violation(f"bystander {client.name}: bad /rosapi/topics answer {reply}")
        client.backlog.clear()  # publishes of fuzzed ops on shared names are not its business


async def _exchange_on(
    harness: Harness, transport: str, frames: list[tuple[bytes, bool]], tag: str
) -> None:
    if transport == "memory":
        async with harness.server.connect_memory() as connection:
            await driver.exchange(driver.memory_wire(connection), frames, tag, TIMEOUT_S)
    elif transport == "ws":
        async with connect(f"ws://127.0.0.1:{harness.port('websocket')}", max_size=None) as ws:
            await driver.exchange(driver.ws_wire(ws), frames, tag, TIMEOUT_S)
    elif transport == "tcp":
        async with await anyio.connect_tcp("127.0.0.1", harness.port("tcp")) as stream:
            await driver.exchange(
                driver.stream_wire(stream, eof_after=True), frames, tag, TIMEOUT_S
            )
    elif transport == "udp":
        async with await anyio.create_connected_udp_socket(
            "127.0.0.1", harness.port("udp")
        ) as sock:
            wire = driver.udp_wire(sock)
            await driver.udp_handshake(wire)
            await driver.exchange(wire, frames, tag, TIMEOUT_S)
    else:  # stdio: one session for the server's life; after a clean close, nothing to send
        key = id(harness)
        if key not in _stdio:
            _stdio[key] = driver.stream_wire(harness.stdio_client, eof_after=False)
        wire = _stdio[key]
        if wire is not None and not await driver.exchange(wire, frames, tag, TIMEOUT_S):
            _stdio[key] = None


async def one_example(live: Live, transport: str, frames: list[tuple[bytes, bool]]) -> None:
    assert live.harness is not None
    tag = f"fuzz-{next(_tags)}"
    try:
        await _exchange_on(live.harness, transport, frames, tag)
        await check_bystanders(live.bystanders, tag)
    except Exception as exc:
        await anyio.sleep(0.05)  # let a dying server finish dying, to name the cause
        if (death := live.died()) is not None:
            raise driver.Violation(f"the server died: {death!r:.500}") from exc
        raise


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_fuzzed_frames_keep_the_invariant(live: Live, transport: str) -> None:
    binary_ok = transport != "stdio"  # stdio is JSON lines (D22); CBOR goes as hex text there
    max_bytes = UDP_FRAME_BYTES if transport == "udp" else None

    @FUZZ
    @given(frames=sequences(binary_ok=binary_ok, max_bytes=max_bytes))
    def burst(frames: list[tuple[bytes, bool]]) -> None:
        live.ensure()
        live.portal.call(one_example, live, transport, frames)

    burst()
