"""WebRTC signalling on the WebSocket port: refusals, CORS, deadlines, bursts (docs/webrtc.md)."""

from __future__ import annotations

import json

import anyio
import httpx
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from websockets.asyncio.client import connect

from rwt_transports.server import ServerConfig
from rwt_transports.webrtc.peers import MAX_CONNECTING
from rwt_transports.webrtc.signalling import MAX_OFFER_BYTES, WebRtcOptions
from rwt_transports.websocket import WebSocketOptions
from tests.webrtc.peer import Served, closed_offer, peers_of, rtc_client, serving

pytestmark = pytest.mark.anyio

SDP = {"Content-Type": "application/sdp"}


@pytest.mark.parametrize(
    ("body", "headers", "status", "text"),
    [
        ("v=0\r\n", {"Content-Type": "text/plain"}, 400, "Content-Type: application/sdp"),
        ("", SDP, 400, "the offer is empty"),
        ("not sdp at all", SDP, 400, "not a usable SDP offer"),
    ],
)
async def test_a_bad_offer_gets_400_with_a_reason(
    served_on: Served, body: str, headers: dict[str, str], status: int, text: str
) -> None:
    async with httpx.AsyncClient(base_url=served_on.base) as http:
        reply = await http.post("/webrtc", content=body, headers=headers)
    assert reply.status_code == status and text in reply.text
    assert not served_on.server.slots_taken  # a refused offer holds no slot, no session


async def test_an_offer_without_a_data_channel_gets_400(served_on: Served) -> None:
    sdp = await closed_offer(channel=False, audio=True)
    async with httpx.AsyncClient(base_url=served_on.base) as http:
        reply = await http.post("/webrtc", content=sdp, headers=SDP)
    assert reply.status_code == 400 and "no data channel" in reply.text


async def test_an_oversized_offer_gets_413(served: Served) -> None:
    async with httpx.AsyncClient(base_url=served.base) as http:
        reply = await http.post("/webrtc", content="a" * (MAX_OFFER_BYTES + 1), headers=SDP)
    assert reply.status_code == 413


async def test_unknown_sessions_and_paths_get_404(served: Served) -> None:
    async with httpx.AsyncClient(base_url=served.base) as http:
        assert (await http.delete("/webrtc/nosuchsession")).status_code == 404
        assert (await http.post("/webrtc/x", content="v=0", headers=SDP)).status_code == 404


async def test_cors_preflight_and_answer_headers(served: Served) -> None:
    origin = {"Origin": "https://app.example"}
    async with httpx.AsyncClient(base_url=served.base) as http:
        preflight = await http.options(
            "/webrtc",
            headers={
                **origin,
                "Access-Control-Request-Method": "POST",
                "Access-Control-Request-Headers": "content-type, authorization",
            },
        )
        assert preflight.status_code == 204
        assert preflight.headers["Access-Control-Allow-Origin"] == "https://app.example"
        assert "POST" in preflight.headers["Access-Control-Allow-Methods"]
        assert "Authorization" in preflight.headers["Access-Control-Allow-Headers"]
        reply = await http.post("/webrtc", content="nonsense", headers={**SDP, **origin})
        assert reply.headers["Access-Control-Allow-Origin"] == "https://app.example"
    async with rtc_client(served.base, headers=origin) as client:
        assert client.location.startswith("/webrtc/")


async def test_allowed_origins_apply_to_signalling(stack: str) -> None:
    config = ServerConfig(
        port=0,
        websocket=WebSocketOptions(allowed_origins=("https://ok.example",)),
        webrtc=WebRtcOptions(stack=stack),
    )
    async with serving(config) as running, httpx.AsyncClient(base_url=running.base) as http:
        bad = await http.post(
            "/webrtc", content="v=0", headers={**SDP, "Origin": "https://evil.example"}
        )
        assert bad.status_code == 403 and "not allowed" in bad.text


async def test_a_peer_that_never_connects_is_freed_after_the_deadline(served_on: Served) -> None:
    async with httpx.AsyncClient(base_url=served_on.base) as http:
        reply = await http.post("/webrtc", content=await closed_offer(), headers=SDP)
        assert reply.status_code == 201 and reply.headers["Content-Type"] == "application/sdp"
        assert "a=candidate" in reply.text  # gathered: no trickle
        # admitted as it was answered: its ticket holds a slot, no session before a channel
        assert served_on.server.slots_taken == 1 and not served_on.server.sessions
        with anyio.fail_after(15):  # connect_timeout_s is 2 here
            while served_on.server.slots_taken:
                await anyio.sleep(0.05)
        assert not peers_of(served_on.server).peers
        assert (await http.delete(reply.headers["Location"])).status_code == 404


async def test_max_connections_refuses_an_offer_with_503(stack: str) -> None:
    config = ServerConfig(port=0, max_connections=1, webrtc=WebRtcOptions(stack=stack))
    async with serving(config) as running, rtc_client(running.base):
        async with httpx.AsyncClient(base_url=running.base) as http:
            reply = await http.post("/webrtc", content=await closed_offer(), headers=SDP)
        assert reply.status_code == 503 and "too many connections" in reply.text
        assert len(running.server.sessions) == 1


async def test_a_burst_of_offers_is_bounded_and_a_websocket_bystander_is_served(
    served_on: Served,
) -> None:
    sdp = await closed_offer()
    statuses: list[int] = []

    async def post(http: httpx.AsyncClient) -> None:
        statuses.append((await http.post("/webrtc", content=sdp, headers=SDP)).status_code)

    limits = httpx.Limits(max_connections=MAX_CONNECTING * 3)
    http = httpx.AsyncClient(base_url=served_on.base, limits=limits, timeout=30)
    async with http, anyio.create_task_group() as tg:
        for _ in range(MAX_CONNECTING * 2):
            tg.start_soon(post, http)
        async with connect(served_on.base.replace("http://", "ws://")) as bystander:
            await bystander.send(
                json.dumps({"op": "call_service", "service": "/rosapi/nodes", "id": "b"})
            )
            with anyio.fail_after(10):
                reply = json.loads(await bystander.recv())
            assert reply["id"] == "b" and reply["result"] is True
    assert sorted(set(statuses)) == [201, 503]
    assert statuses.count(201) <= MAX_CONNECTING
    assert len(peers_of(served_on.server).peers) <= MAX_CONNECTING


async def test_the_roslib_transport_is_served_as_javascript_with_cors(served: Served) -> None:
    page = "http://page.example:8000"
    async with httpx.AsyncClient(base_url=served.base) as http:
        reply = await http.get("/webrtc/roslib-transport.js", headers={"Origin": page})
        missing = await http.get("/webrtc/nothing.js")
        websocket = await http.get("/")  # not signalling's: the console's
    assert reply.status_code == 200
    assert reply.headers["Content-Type"] == "text/javascript; charset=utf-8"
    assert reply.headers["Access-Control-Allow-Origin"] == page  # importable from a page elsewhere
    assert "export function webrtcTransportFactory(AbstractTransport" in reply.text
    assert '"rosbridge-lossy"' in reply.text
    assert missing.status_code == 404 and "/webrtc/roslib-transport.js" in missing.text
    assert websocket.status_code == 200  # the console's page, as before
    assert websocket.headers["Content-Type"].startswith("text/html")


async def test_the_roslib_transport_obeys_allowed_origins() -> None:
    config = ServerConfig(
        port=0,
        webrtc=WebRtcOptions(),
        websocket=WebSocketOptions(allowed_origins=("http://good.example",)),
    )
    async with serving(config) as served, httpx.AsyncClient(base_url=served.base) as http:
        bad = await http.get(
            "/webrtc/roslib-transport.js", headers={"Origin": "http://evil.example"}
        )
        good = await http.get(
            "/webrtc/roslib-transport.js", headers={"Origin": "http://good.example"}
        )
    assert bad.status_code == 403
    assert good.status_code == 200


async def test_the_stack_answers_data_only_offers_and_aiortc_media_without_tracks(
    served_on: Served, stack: str
) -> None:
    """``--webrtc-stack`` (D51): an offer with an audio or video section and no ``?video=``
    stays on aiortc (one asking for tracks: test_video_native.py)."""
    with_media = await closed_offer(audio=True)
    async with httpx.AsyncClient(base_url=served_on.base) as http:
        data_only = await http.post("/webrtc", content=await closed_offer(), headers=SDP)
        mixed = await http.post("/webrtc", content=with_media, headers=SDP)
    assert data_only.status_code == 201 and mixed.status_code == 201
    libdatachannel = "o=rtc "  # its answers' origin line; aiortc's is "o=- "
    assert (libdatachannel in data_only.text) is (stack == "native")
    assert libdatachannel not in mixed.text
    assert "m=audio " in mixed.text  # aiortc answered its audio section too
