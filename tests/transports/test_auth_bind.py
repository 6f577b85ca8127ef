"""``--auth-bind-connection``: an ``auth`` op is good for the connection it was made for (D31).

rosauth's MAC names no connection: a captured ``auth`` op is accepted on any new
connection until its ``end``, and moving a digit of ``t`` into ``rand`` keeps the
MAC valid (docs/server.md, authentication). With connection binding the server
sends each connection a challenge first, ``rand`` must be it, and the MAC is an
HMAC over the fields one per line. Tested with the unmodified roslib in Node
(the trusted web server's part, signing the challenge, done in the same script)
and with raw clients replaying a captured op on every transport.
"""

from __future__ import annotations

import json
import time
from collections.abc import AsyncIterator
from typing import Any

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_protocol.auth import AUTH_CHALLENGE_ID, bound_mac, rosauth_mac
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig, rosauth_authenticator
from tests.support.clients import Client, Harness, is_op, running_server
from tests.support.realclients import node_missing, run_node

pytestmark = pytest.mark.anyio

SECRET = "1234567890abcdef"
TIMEOUT_S = 20


@pytest.fixture
async def harness() -> AsyncIterator[Harness]:
    graph = Graph()

    def add_two_ints(request: dict[str, Any]) -> dict[str, object]:
        return {"sum": request["a"] + request["b"]}

    graph.create_service("/add", "example_interfaces/srv/AddTwoInts", add_two_ints)
    authenticator = rosauth_authenticator(SECRET, graph.clock, bind_connection=True)
    config = ServerConfig(session=SessionConfig(auth_challenge=True))
    with anyio.fail_after(TIMEOUT_S):
        async with running_server(config, graph=graph, authenticator=authenticator) as h:
            yield h


def signed(nonce: str, secret: str = SECRET) -> dict[str, object]:
    """What the trusted web server hands the client for the connection's challenge."""
    now = time.time()
    fields = {
        "client": "127.0.0.1",
        "dest": "127.0.0.1",
        "rand": nonce,
        "t": int(now),
        "level": "user",
        "end": int(now + 60),
    }
    return {"op": "auth", "mac": bound_mac(secret, **fields), **fields}  # type: ignore[arg-type]


async def challenge(client: Client) -> str:
    status = await client.expect(is_op("status", id=AUTH_CHALLENGE_ID))
    assert status["level"] == "info" and len(status["msg"]) == 32, status
    return str(status["msg"])


async def add(client: Client, tag: str) -> dict[str, object]:
    await client.send(
        {"op": "call_service", "service": "/add", "args": {"a": 20, "b": 22}, "id": tag}
    )
    return await client.expect(is_op("service_response", id=tag))


@pytest.mark.parametrize("transport", ["memory", "ws", "tcp"])
async def test_a_captured_auth_op_is_refused_on_another_connection(
    harness: Harness, transport: str
) -> None:
    first = await harness.connect(transport, "first")
    thief = await harness.connect(transport, "thief")
    captured = signed(await challenge(first))
    await first.send(captured)
    assert (await add(first, "a"))["values"] == {"sum": 42}
    other_nonce = await challenge(thief)
    assert other_nonce != captured["rand"]  # one challenge per connection
    await thief.send(captured)
    refused = await thief.expect(is_op("status"))
    assert refused["level"] == "error" and "authentication failed" in refused["msg"]
    await first.send({"op": "call_service", "service": "/add", "args": {"a": 1, "b": 2}, "id": "b"})
    assert (await first.expect(is_op("service_response", id="b")))["values"] == {"sum": 3}


async def test_an_auth_signed_for_the_challenge_in_rosauth_form_is_refused(
    harness: Harness,
) -> None:
    client = await harness.connect("ws")
    op = signed(await challenge(client))
    fields = {k: v for k, v in op.items() if k not in ("op", "mac")}
    op["mac"] = rosauth_mac(SECRET, **fields)  # type: ignore[arg-type]
    await client.send(op)
    refused = await client.expect(is_op("status"))
    assert "authentication failed" in refused["msg"]


def test_the_bound_mac_tells_fields_apart() -> None:
    # rosauth signs the concatenation: a digit moved from t into rand keeps the MAC.
    one = {"client": "c", "dest": "d", "level": "user", "end": 1_900_000_000}
    moved = {"rand": "r1", "t": 800_000_000}
    original = {"rand": "r", "t": 1_800_000_000}
    assert rosauth_mac(SECRET, **one, **moved) == rosauth_mac(SECRET, **one, **original)  # type: ignore[arg-type]
    assert bound_mac(SECRET, **one, **moved) != bound_mac(SECRET, **one, **original)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="line breaks"):
        bound_mac(SECRET, client="c\nd", dest="", rand="r", t=1, level="user", end=2)


@pytest.mark.skipif(node_missing() is not None, reason=str(node_missing()))
async def test_roslib_authenticates_with_the_connection_challenge(harness: Harness) -> None:
    out = await run_node(
        f"""
        import {{ createHmac }} from "node:crypto";
        import * as ROSLIB from "roslib";
        const timer = setTimeout(() => {{ console.error("timed out"); process.exit(2); }}, 20000);
        const ros = new ROSLIB.Ros({{ url: "ws://127.0.0.1:{harness.port("websocket")}" }});
        ros.on("status:{AUTH_CHALLENGE_ID}", (status) => {{
          // the trusted web server's part: sign this connection's challenge
          const t = Math.floor(Date.now() / 1000), end = t + 60;
          const text = ["rwt-auth-bound-1", "127.0.0.1", "127.0.0.1", status.msg,
                        String(t), "user", String(end)].join("\\n");
          const mac = createHmac("sha512", {json.dumps(SECRET)}).update(text).digest("hex");
          ros.authenticate(mac, "127.0.0.1", "127.0.0.1", status.msg, t, "user", end);
          const add = new ROSLIB.Service({{
            ros, name: "/add", serviceType: "example_interfaces/AddTwoInts" }});
          add.callService({{ a: 1, b: 2 }}, (result) => {{
            console.log(result.sum); clearTimeout(timer); ros.close();
          }}, (error) => {{ console.error(error); process.exit(3); }});
        }});
        """
    )
    assert out.split() == ["3"]
