"""Incomplete fragments draw from one server-wide budget (docs/limits.md, per server).

Before, each connection could hold ``--max-message-size`` of incomplete parts
(20-30 MB of memory each, counting Python's objects), and with ~20 000
connections allowed, a few thousand of them exhausted the machine's memory.
"""

from __future__ import annotations

import anyio
import pytest

from rwt_transports.server import ServerConfig
from tests.support.clients import TRANSPORTS, Client, is_op, running_server

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10
BUDGET = 100_000
PART = 30_000  # characters of one held part: three fill most of the budget


def part(op_id: str, data: str, num: int, total: int) -> dict[str, object]:
    return {"op": "fragment", "id": op_id, "data": data, "num": num, "total": total}


async def synced(client: Client, tag: str) -> None:
    """Wait until the server handled everything ``client`` sent before."""
    await client.send({"op": "set_level", "level": "error", "id": tag})
    await client.send({"op": "set_level", "level": "info", "id": tag})
    await client.expect(is_op("status", id=tag))


@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_a_part_past_the_server_wide_budget_is_refused_and_the_connection_goes_on(
    transport: str,
) -> None:
    async with running_server(ServerConfig(max_fragment_memory=BUDGET)) as harness:
        hog = await harness.connect("tcp" if transport == "ws" else "ws", "hog")
        client = await harness.connect(transport)
        with anyio.fail_after(TIMEOUT_S):
            for i in range(3):  # each connection is far within its own 10 MiB bound
                await hog.send(part(f"hog{i}", "x" * PART, 0, 2))
            await synced(hog, "held")
            await client.send(part("mine", "y" * PART, 0, 2))
            refused = await client.expect(is_op("status", id="mine"))
            assert refused["level"] == "error"
            assert "incomplete messages from all connections" in refused["msg"]
            assert str(BUDGET) in refused["msg"]
            await synced(client, "alive")  # the connection goes on
            for i in range(3):  # the hog's messages complete (as garbage): their bytes return
                await hog.send(part(f"hog{i}", "x", 1, 2))
            await synced(hog, "released")
            text = '{"op": "set_level", "level": "info", "id": "whole"}'
            await client.send(part("again", text[:20], 0, 2))
            await client.send(part("again", text[20:], 1, 2))
            assert (await client.expect(is_op("status", id="whole")))["level"] == "info"
        assert harness.server.fragment_budget.used == 0


async def test_a_closed_connection_returns_what_its_parts_held() -> None:
    async with running_server(ServerConfig(max_fragment_memory=BUDGET)) as harness:
        hog = await harness.connect("ws", "hog")
        client = await harness.connect("tcp")
        with anyio.fail_after(TIMEOUT_S):
            for i in range(3):
                await hog.send(part(f"hog{i}", "x" * PART, 0, 2))
            await synced(hog, "held")
            await hog.aclose()
            while any(c.startswith("ws:") for c in harness.server.sessions):
                await anyio.sleep(0.01)
            await client.send(part("mine", "y" * PART, 0, 2))
            await synced(client, "after")
            assert not [m for m in client.backlog if m.get("id") == "mine"]  # not refused
