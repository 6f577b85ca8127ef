"""B26's churning clients: one cycle of each front end of ``rwt serve``, with real clients.

Each cycle connects, does what a user's client does, checks each answer, and leaves;
``benchmarks/churn.py`` runs each front end's cycles one after another at its rate.
Topic names rotate through a pool of ``POOL`` per front end, so the graph makes and
drops topics without growing a name a cycle. A cycle of an odd number leaves without
saying goodbye (the socket aborted, the peer connection closed without ``DELETE``),
an even one cleanly: both ways of leaving must give back what the client held.

- ``rosbridge``: a ``websockets`` client (JSON ops): advertise, subscribe to its own
  topic and the robot's steady one, a message from the robot, publish and get its own
  message back, call the robot's service (``std_srvs/srv/SetBool``); then unsubscribe,
  unadvertise and close (even) or abort the socket (odd).
- ``foxglove``: a ``websockets`` client of subprotocol ``foxglove.websocket.v1``, as
  Foxglove and Lichtblick connect: subscribe to the steady channel and get a message,
  advertise a client channel (``json``), subscribe to the channel the server then
  advertises for it and get its own message back (CDR), call the service with a CDR
  request (``serviceCallRequest``) and get its response.
- ``http``: ``httpx``: the steady topic's event stream (two events, then closed),
  publish, call the service, and every ``LISTING_EVERY`` cycles ``GET /api/topics``
  and ``/openapi.json``.
- ``mcp``: the official MCP SDK over Streamable HTTP, even cycles a 2025-era session
  (``initialize``, closed with ``DELETE``), odd ones a 2026-07-28 client (no session):
  ``tools/list``, ``echo`` of the steady topic, ``publish``, ``call_service`` and
  ``resources/read`` of the steady topic.
- ``webrtc``: an aiortc peer: offer to ``POST /webrtc``, the ``rosbridge`` data channel,
  then the rosbridge cycle above over it; closed with ``DELETE`` (even) or only closed
  (odd).
- ``ros2-link``: a ``websockets`` client subscribes to the ROS 2 talker's topic
  (``benchmarks/churn_ros2.py``), gets a message and leaves, so that ``rwt serve
  --ros2``'s link makes and drops its rclpy subscription. (The ROS 2 side's own churn,
  nodes that come and go, is that peer's: the ``ros2`` front end.)
"""

from __future__ import annotations

import asyncio
import json
import struct
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Protocol

import httpx
from websockets.asyncio.client import ClientConnection, connect
from websockets.typing import Subprotocol

from .churn_ros2 import CHATTER
from .churn_steady import SERVICE, SERVICE_TYPE, STEADY_TOPIC, STRING

__all__ = ["CYCLES", "POOL", "Target"]

POOL = 8
"""Topic names each front end rotates through."""
LISTING_EVERY = 5
"""The ``http`` front end lists the topics and fetches the OpenAPI document every this
many cycles."""
FOXGLOVE = Subprotocol("foxglove.websocket.v1")
SET_BOOL_TRUE_CDR = b"\x00\x01\x00\x00\x01"
"""``std_srvs/srv/SetBool_Request(data=True)`` in CDR: the little-endian encapsulation
header, then the ``bool``."""

Op = dict[str, Any]


@dataclass(frozen=True)
class Target:
    """The server under soak: its WebSocket URL (``ws://HOST:PORT``) and HTTP base."""

    ws: str

    @property
    def http(self) -> str:
        """``http://HOST:PORT``."""
        return "http" + self.ws.removeprefix("ws")


def churn_topic(front: str, n: int) -> str:
    """The topic a front end's cycle ``n`` publishes on."""
    return f"/soak/churn/{front}/t{n % POOL}"


class OpLink(Protocol):
    """A rosbridge session's JSON ops, whatever carries them."""

    async def send(self, op: Op) -> None:
        """Send one op."""

    async def receive(self) -> str | bytes:
        """The next frame."""


async def until(link: OpLink, match: Callable[[Op], bool]) -> Op:
    """The next op ``match`` accepts, skipping others; an error status raises.

    Raises:
        RuntimeError: the server sent a ``status`` of level ``error`` meanwhile.
    """
    while True:
        op = json.loads(await link.receive())
        if op.get("op") == "status" and op.get("level") == "error":
            raise RuntimeError(f"status: {op.get('msg')}")
        if match(op):
            return op


def _published(topic: str, data: str | None = None) -> Callable[[Op], bool]:
    def match(op: Op) -> bool:
        if op.get("op") != "publish" or op.get("topic") != topic:
            return False
        return data is None or op["msg"].get("data") == data

    return match


async def rosbridge_session(link: OpLink, front: str, n: int, clean: bool) -> None:
    """The rosbridge cycle's ops (module docstring), on ``link``."""
    topic, tag = churn_topic(front, n), f"{front} {n}"
    await link.send({"op": "advertise", "topic": topic, "type": STRING})
    await link.send({"op": "subscribe", "topic": topic, "type": STRING})
    await link.send({"op": "subscribe", "topic": STEADY_TOPIC, "type": STRING})
    await until(link, _published(STEADY_TOPIC))
    await link.send({"op": "publish", "topic": topic, "msg": {"data": tag}})
    await until(link, _published(topic, tag))
    call = {"op": "call_service", "service": SERVICE, "args": {"data": True}, "id": tag}
    await link.send({**call, "type": SERVICE_TYPE})
    reply = await until(link, lambda op: op.get("op") == "service_response")
    if not (reply.get("result") and reply["values"].get("success")):
        raise RuntimeError(f"service_response {reply}")
    if clean:
        await link.send({"op": "unsubscribe", "topic": STEADY_TOPIC})
        await link.send({"op": "unsubscribe", "topic": topic})
        await link.send({"op": "unadvertise", "topic": topic})


class _WsLink:
    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws

    async def send(self, op: Op) -> None:
        await self.ws.send(json.dumps(op))

    async def receive(self) -> str | bytes:
        return await self.ws.recv()


def _leave(ws: ClientConnection, clean: bool) -> None:
    """An odd cycle drops its TCP connection without a closing handshake."""
    if not clean:
        ws.transport.abort()


async def rosbridge_cycle(target: Target, n: int) -> None:
    """One ``rosbridge`` cycle (module docstring)."""
    async with connect(target.ws, max_size=None, compression=None) as ws:
        await rosbridge_session(_WsLink(ws), "rosbridge", n, clean=n % 2 == 0)
        _leave(ws, n % 2 == 0)


async def ros2_link_cycle(target: Target, n: int) -> None:
    """One ``ros2-link`` cycle (module docstring)."""
    async with connect(target.ws, max_size=None, compression=None) as ws:
        link = _WsLink(ws)
        await link.send({"op": "subscribe", "topic": CHATTER, "type": STRING})
        await until(link, _published(CHATTER))
        _leave(ws, n % 2 == 0)


async def _fox_text(ws: ClientConnection, op: str, match: Callable[[Op], bool]) -> Op:
    while True:
        frame = await ws.recv()
        if isinstance(frame, str):
            message = json.loads(frame)
            if message.get("op") == "status" and message.get("level") == 2:
                raise RuntimeError(f"foxglove status: {message.get('message')}")
            if message.get("op") == "serviceCallFailure":
                raise RuntimeError(f"serviceCallFailure: {message.get('message')}")
            if message.get("op") == op and match(message):
                return message


async def _fox_binary(ws: ClientConnection, opcode: int, first_id: int) -> bytes:
    """The next binary frame of ``opcode`` whose first u32 is ``first_id``."""
    while True:
        frame = await ws.recv()
        if (
            isinstance(frame, bytes)
            and frame[0] == opcode
            and struct.unpack_from("<I", frame, 1)[0] == first_id
        ):
            return frame


def _channel_of(topic: str) -> Callable[[Op], bool]:
    return lambda op: any(c["topic"] == topic for c in op["channels"])


def _channel_id(advertised: Op, topic: str) -> int:
    return int(next(c["id"] for c in advertised["channels"] if c["topic"] == topic))


async def foxglove_cycle(target: Target, n: int) -> None:
    """One ``foxglove`` cycle (module docstring)."""
    topic, tag = churn_topic("foxglove", n), f"foxglove {n}"
    async with connect(target.ws, subprotocols=[FOXGLOVE], max_size=None) as ws:
        info = await _fox_text(ws, "serverInfo", lambda _op: True)
        if "clientPublish" not in info["capabilities"]:
            raise RuntimeError(f"serverInfo without clientPublish: {info['capabilities']}")
        steady = _channel_id(
            await _fox_text(ws, "advertise", _channel_of(STEADY_TOPIC)), STEADY_TOPIC
        )
        services = await _fox_text(
            ws, "advertiseServices", lambda op: any(s["name"] == SERVICE for s in op["services"])
        )
        service = next(s["id"] for s in services["services"] if s["name"] == SERVICE)
        subscribe = {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": steady}]}
        await ws.send(json.dumps(subscribe))
        await _fox_binary(ws, 0x01, 1)
        channel = {"id": 1, "topic": topic, "encoding": "json", "schemaName": STRING}
        await ws.send(json.dumps({"op": "advertise", "channels": [channel]}))
        own = _channel_id(await _fox_text(ws, "advertise", _channel_of(topic)), topic)
        subscribe = {"op": "subscribe", "subscriptions": [{"id": 2, "channelId": own}]}
        await ws.send(json.dumps(subscribe))
        await asyncio.sleep(0)  # the subscribe goes first
        await ws.send(b"\x01" + struct.pack("<I", 1) + json.dumps({"data": tag}).encode())
        echoed = await _fox_binary(ws, 0x01, 2)
        if tag.encode() not in echoed:
            raise RuntimeError(f"own message came back as {echoed[13:]!r}")
        encoding = b"cdr"
        request = struct.pack("<BIII", 0x02, service, n, len(encoding)) + encoding
        await ws.send(request + SET_BOOL_TRUE_CDR)
        await _fox_binary(ws, 0x03, service)
        if n % 2 == 0:
            await ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [1, 2]}))
            await ws.send(json.dumps({"op": "unadvertise", "channelIds": [1]}))
        _leave(ws, n % 2 == 0)


async def http_cycle(target: Target, n: int) -> None:
    """One ``http`` cycle (module docstring)."""
    path = churn_topic("http", n).removeprefix("/")
    async with httpx.AsyncClient(base_url=target.http, timeout=20) as http:
        events = 0
        async with http.stream("GET", f"/api/topics{STEADY_TOPIC}/events") as stream:
            stream.raise_for_status()
            async for line in stream.aiter_lines():
                events += line.startswith("data:")
                if events == 2:
                    break
        posted = await http.post(
            f"/api/topics/{path}", params={"type": STRING}, json={"data": f"http {n}"}
        )
        posted.raise_for_status()
        called = await http.post(f"/api/services{SERVICE}", json={"data": True})
        called.raise_for_status()
        if not called.json().get("success"):
            raise RuntimeError(f"service answered {called.text}")
        if n % LISTING_EVERY == 0:
            (await http.get("/api/topics")).raise_for_status()
            (await http.get("/openapi.json")).raise_for_status()


async def _mcp_calls(agent: Any, n: int) -> None:
    """The MCP cycle's requests, on a 2025-era session or a 2026-07-28 client."""
    await agent.list_tools()
    steady = {"topic": STEADY_TOPIC, "timeout_s": 10}
    publish = {"topic": churn_topic("mcp", n), "type": STRING, "msg": {"data": f"mcp {n}"}}
    call = {"service": SERVICE, "type": SERVICE_TYPE, "args": {"data": True}}
    for tool, arguments in (("echo", steady), ("publish", publish), ("call_service", call)):
        result = await agent.call_tool(tool, arguments)
        if result.is_error:
            raise RuntimeError(f"{tool}: {result.content[0].text[:200]}")
    await agent.read_resource(f"ros://topics{STEADY_TOPIC}")


async def mcp_cycle(target: Target, n: int) -> None:
    """One ``mcp`` cycle (module docstring)."""
    from mcp import Client, ClientSession  # noqa: PLC0415 (the mcp extra, optional)
    from mcp.client.streamable_http import streamable_http_client  # noqa: PLC0415

    url = f"{target.http}/mcp"
    if n % 2 == 0:
        async with (
            streamable_http_client(url) as (read, write),
            ClientSession(read, write) as session,
        ):
            await session.initialize()
            await _mcp_calls(session, n)
    else:
        async with Client(url, mode="auto") as agent:
            await _mcp_calls(agent, n)


class _RtcLink:
    def __init__(self, channel: Any) -> None:
        self.channel = channel
        self.inbox: asyncio.Queue[str | bytes] = asyncio.Queue()
        channel.on("message", self.inbox.put_nowait)

    async def send(self, op: Op) -> None:
        self.channel.send(json.dumps(op))

    async def receive(self) -> str | bytes:
        return await self.inbox.get()


async def webrtc_cycle(target: Target, n: int) -> None:
    """One ``webrtc`` cycle (module docstring)."""
    from aiortc import (  # noqa: PLC0415 (the webrtc extra, optional)
        RTCConfiguration,
        RTCPeerConnection,
        RTCSessionDescription,
    )

    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    try:
        channel = pc.createDataChannel("rosbridge")
        opened = asyncio.Event()
        channel.on("open", opened.set)
        link = _RtcLink(channel)
        await pc.setLocalDescription(await pc.createOffer())
        async with httpx.AsyncClient(base_url=target.http, timeout=20) as http:
            sdp = {"Content-Type": "application/sdp"}
            offered = await http.post("/webrtc", content=pc.localDescription.sdp, headers=sdp)
            if offered.status_code != 201:
                raise RuntimeError(f"offer answered {offered.status_code} {offered.text[:200]}")
            await pc.setRemoteDescription(RTCSessionDescription(offered.text, "answer"))
            await opened.wait()
            await rosbridge_session(link, "webrtc", n, clean=n % 2 == 0)
            if n % 2 == 0:
                (await http.delete(offered.headers["Location"])).raise_for_status()
    finally:
        await pc.close()


CYCLES: dict[str, Callable[[Target, int], Awaitable[None]]] = {
    "rosbridge": rosbridge_cycle,
    "foxglove": foxglove_cycle,
    "http": http_cycle,
    "mcp": mcp_cycle,
    "webrtc": webrtc_cycle,
    "ros2-link": ros2_link_cycle,
}
"""Each front end's cycle, by name (the ``ros2`` front end is the rclpy peer's process)."""
