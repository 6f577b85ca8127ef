"""Inflating ``png`` ops is charged to the sender (docs/limits.md, per connection).

Before, a client sending 17 KB ``png`` ops that each inflate to 9 MB had them
inflated on the event loop, one after another, and other clients' round trips
waited 0.34-0.57 s behind them. Now each connection's inflating is paced by a
token bucket (``--png-inflate-rate``) and done in a worker thread: the sender
waits for its own budget, everyone else is served meanwhile.
"""

from __future__ import annotations

import json
from dataclasses import replace

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_protocol.codecs.png import encode_png
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.clients import TRANSPORTS, is_op, running_server

pytestmark = pytest.mark.anyio

TIMEOUT_S = 30
FLOOD = 20
INFLATED = 9_000_000  # bytes one op inflates to, from about 17 KB on the wire
RATE = 1024 * 1024  # bytes per second the test's server inflates per connection


def bomb(num: int) -> dict[str, object]:
    """A ``png`` op of ~17 KB whose image holds a 9 MB ``publish`` on /flood."""
    text = json.dumps({"op": "publish", "topic": "/flood", "msg": {"data": str(num)}})
    padded = text[:-1] + " " * (INFLATED - len(text)) + "}"  # JSON whitespace inflates well
    return {"op": "png", "data": encode_png(padded.encode())}


@pytest.fixture(scope="module")
def bombs() -> list[bytes]:
    """The ``FLOOD`` ops as sent, built once (compressing 9 MB takes the test's CPU):
    the first publishes ``0``, the others ``1``, so ``arrived`` tells whether any
    but the first was inflated."""
    first, rest = (json.dumps(bomb(num)).encode() for num in (0, 1))
    return [first] + [rest] * (FLOOD - 1)


@pytest.mark.parametrize("transport", TRANSPORTS)
async def test_a_png_flood_waits_for_its_own_budget_while_others_are_served(
    transport: str, bombs: list[bytes]
) -> None:
    graph = Graph()
    arrived: list[str] = []
    graph.create_subscription(
        "/flood", lambda msg: arrived.append(str(msg["data"])), "std_msgs/String"
    )
    config = ServerConfig(session=replace(SessionConfig(), png_inflate_rate=RATE))
    async with running_server(config, graph=graph) as harness:
        attacker = await harness.connect(transport, "attacker")
        bystander = await harness.connect("tcp" if transport == "ws" else "ws", "bystander")

        async def flood() -> None:  # in a task: a stream's sends wait once the server stops reading
            for data in bombs:
                await attacker.send_raw(data + attacker.terminator)

        async with anyio.create_task_group() as tg:
            with anyio.fail_after(TIMEOUT_S):
                await attacker.send(
                    {"op": "advertise", "topic": "/flood", "type": "std_msgs/String"}
                )
                await attacker.send({"op": "set_level", "level": "info", "id": "advertised"})
                await attacker.expect(is_op("status", id="advertised"))
                tg.start_soon(flood)
                while not arrived:  # the flood is being inflated
                    await anyio.sleep(0.01)
                for i in range(5):  # a bystander's round trips complete while it runs
                    await bystander.send({"op": "set_level", "level": "info", "id": f"rt{i}"})
                    await bystander.expect(is_op("status", id=f"rt{i}"))
                # Its first op went at once (a burst of --max-message-size); the next waits
                # for the budget (9 s at the test's 1 MiB/s): the bystander did not wait for it.
                assert arrived == ["0"]
                tg.cancel_scope.cancel()
        harness.server.stop()  # the attacker's session waits for its budget: end it now
