"""A real WebRTC client (aiortc) for the server's ``rosbridge`` data channel (docs/webrtc.md).

Imported by the tests of this folder after their ``pytest.importorskip("aiortc")``.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import anyio
import cbor2
import httpx
import msgspec
from aiortc import (
    RTCConfiguration,
    RTCDataChannel,
    RTCIceServer,
    RTCPeerConnection,
    RTCSessionDescription,
)

from rwt_graph.graph import Graph
from rwt_transports.server import RosbridgeServer, ServerConfig
from rwt_transports.webrtc.peers import WebRtcPeers
from rwt_transports.webrtc.signalling import WebRtcSignalling

RECEIVE_S = 10.0
"""Longest wait for one message: a failure, not a measurement."""


@dataclass
class RtcClient:
    """One aiortc peer connection with its ``rosbridge`` data channel open."""

    pc: RTCPeerConnection
    channel: RTCDataChannel
    location: str
    inbox: list[str | bytes] = field(default_factory=list)
    arrived: anyio.Event = field(default_factory=anyio.Event)
    closed: anyio.Event = field(default_factory=anyio.Event)
    lossy: RTCDataChannel | None = None
    """The ``rosbridge-lossy`` channel, when asked for (its messages: ``lossy_inbox``)."""
    lossy_inbox: list[str | bytes] = field(default_factory=list)

    def send_lossy(self, op: dict[str, object]) -> None:
        assert self.lossy is not None
        self.lossy.send(msgspec.json.encode(op).decode())

    def send(self, op: dict[str, object], *, cbor: bool = False) -> None:
        self.channel.send(cbor2.dumps(op) if cbor else msgspec.json.encode(op).decode())

    async def receive(self) -> str | bytes:
        with anyio.fail_after(RECEIVE_S):
            while not self.inbox:
                if self.closed.is_set():
                    raise EOFError("the data channel closed")
                self.arrived = anyio.Event()
                await self.arrived.wait()
        return self.inbox.pop(0)

    async def next_op(self, op: str) -> dict[str, object]:
        """The next message whose op is ``op`` (JSON or CBOR), skipping others."""
        while True:
            raw = await self.receive()
            message = cbor2.loads(raw) if isinstance(raw, bytes) else msgspec.json.decode(raw)
            if message.get("op") == op:
                return message  # type: ignore[no-any-return]


def peers_of(server: RosbridgeServer) -> WebRtcPeers:
    """The server's WebRTC peers: those of its ``webrtc`` front end (the registry's)."""
    endpoint = server.endpoints["webrtc"]
    assert isinstance(endpoint, WebRtcSignalling) and isinstance(endpoint.peers, WebRtcPeers)
    return endpoint.peers


async def offer_sdp(pc: RTCPeerConnection) -> str:
    """A complete offer (its candidates gathered) with a ``rosbridge`` channel."""
    await pc.setLocalDescription(await pc.createOffer())
    assert pc.localDescription is not None
    return pc.localDescription.sdp


async def closed_offer(*, channel: bool = True, audio: bool = False) -> str:
    """An offer from a real peer, closed at once (it never connects): with a ``rosbridge``
    channel, an audio section, or both."""
    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    if channel:
        pc.createDataChannel("rosbridge")
    if audio:
        pc.addTransceiver("audio")
    try:
        return await offer_sdp(pc)
    finally:
        await pc.close()


@asynccontextmanager
async def rtc_client(
    base: str,
    headers: dict[str, str] | None = None,
    *,
    lossy: dict[str, object] | None = None,
    ice_servers: list[RTCIceServer] | None = None,
    local_address: str | None = None,
) -> AsyncIterator[RtcClient]:
    """Offer to ``base``/webrtc, open the ``rosbridge`` channel; closed on exit.

    ``lossy``: also open a ``rosbridge-lossy`` channel with these ``createDataChannel``
    options (``{"ordered": False, "maxRetransmits": 0}`` for the server to keep it).
    ``ice_servers``: the STUN and TURN servers a browser page would pass; none by default.
    ``local_address``: the address the offer is posted from (another host: ``127.0.0.2``).
    """
    pc = RTCPeerConnection(RTCConfiguration(iceServers=ice_servers or []))
    channel = pc.createDataChannel("rosbridge")
    opened = anyio.Event()
    channel.on("open", opened.set)
    second = None if lossy is None else pc.createDataChannel("rosbridge-lossy", **lossy)
    lossy_inbox: list[str | bytes] = []
    if second is not None:
        second.on("message", lossy_inbox.append)
    try:
        sdp = await offer_sdp(pc)
        transport = httpx.AsyncHTTPTransport(local_address=local_address)
        async with httpx.AsyncClient(base_url=base, transport=transport) as http:
            reply = await http.post(
                "/webrtc",
                content=sdp,
                headers={"Content-Type": "application/sdp", **(headers or {})},
            )
        assert reply.status_code == 201, reply.text
        await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
        with anyio.fail_after(RECEIVE_S):
            await opened.wait()
        client = RtcClient(
            pc, channel, reply.headers["Location"], lossy=second, lossy_inbox=lossy_inbox
        )

        def on_message(message: str | bytes) -> None:
            client.inbox.append(message)
            client.arrived.set()

        def on_close() -> None:
            client.closed.set()
            client.arrived.set()

        channel.on("message", on_message)
        channel.on("close", on_close)
        yield client
    finally:
        await pc.close()


@dataclass
class Served:
    server: RosbridgeServer
    graph: Graph
    base: str


@asynccontextmanager
async def serving(config: ServerConfig, **kwargs: object) -> AsyncIterator[Served]:
    graph = Graph()
    server = RosbridgeServer(graph, config, **kwargs)  # type: ignore[arg-type]
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield Served(server, graph, url.replace("ws://", "http://"))
        tg.cancel_scope.cancel()
