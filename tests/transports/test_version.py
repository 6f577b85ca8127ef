"""``GET /version`` on the WebSocket port (docs/server.md, "Version endpoint"; D49).

A user's ``urllib`` reads it over plain HTTP and over TLS; the answer has
rosbridge_server's fields (docs/reference-behaviour.md §13.4) and rwt's feature list,
taken from the running server's configuration.
"""

from __future__ import annotations

import importlib.metadata
import json
import ssl
import urllib.error
import urllib.request
from dataclasses import replace

import anyio
import anyio.to_thread
import pytest

from rwt import RosbridgeServer, ServerConfig
from rwt.server import FoxgloveOptions, WebSocketOptions
from rwt_protocol.distribution import DISTRIBUTION
from rwt_protocol.server.compat import Compat
from rwt_protocol.server.session import SessionConfig
from rwt_protocol.version import PROTOCOL_VERSION
from rwt_transports.http.version import installed_version
from tests.console.test_http import http_get
from tests.support.clients import Harness, is_op, running_server

pytestmark = pytest.mark.anyio

TIMEOUT_S = 10.0


def fetch(
    url: str,
    method: str = "GET",
    context: ssl.SSLContext | None = None,
    headers: dict[str, str] | None = None,
) -> tuple[int, dict[str, str], bytes]:
    """One request as a user's script makes it (urllib); HTTP errors are answers too."""
    request = urllib.request.Request(url, method=method, headers=headers or {})
    try:
        with urllib.request.urlopen(request, timeout=TIMEOUT_S, context=context) as response:
            return response.status, dict(response.headers), response.read()
    except urllib.error.HTTPError as error:
        with error:
            return error.code, dict(error.headers), error.read()


async def fetch_async(url: str, method: str = "GET", **kw: object) -> tuple[int, dict, bytes]:
    return await anyio.to_thread.run_sync(lambda: fetch(url, method, **kw))  # type: ignore[arg-type]


def version_url(harness: Harness, scheme: str = "http") -> str:
    return f"{scheme}://127.0.0.1:{harness.port('websocket')}/version"


async def test_get_version_answers_the_references_fields_and_rwts_features() -> None:
    async with running_server() as harness:
        status, headers, body = await fetch_async(version_url(harness))
        assert status == 200
        assert headers["Content-Type"] == "application/json"
        answer = json.loads(body)
        major, minor, patch = PROTOCOL_VERSION
        assert answer["protocol"] == {"major": major, "minor": minor, "patch": patch}
        assert answer["protocol"] == {"major": 2, "minor": 1, "patch": 0}
        assert answer["server"] == installed_version()
        features = answer["rwt"]
        assert set(features) == {
            "transports", "encodings", "subprotocols", "webrtc", "mcp", "auth", "safety",
            "frontends",
        }  # fmt: skip
        assert features["safety"] is False  # no --safety (tests/safety: with it)
        # running_server: WebSocket, TCP, UDP and stdio (and WebRTC where aiortc is installed)
        assert features["transports"][:4] == ["ws", "tcp", "udp", "stdio"]
        assert features["webrtc"] is ("webrtc" in harness.server.endpoints)
        assert ("webrtc" in features["transports"]) is features["webrtc"]
        assert features["encodings"] == ["none", "png", "cbor", "cbor-raw"]
        assert "foxglove.websocket.v1" in features["subprotocols"]
        assert features["mcp"] is False
        assert features["auth"] == "none"
        # every front end served, from the one registry: the protocols and the HTTP API too
        frontends = {each.pop("name"): each for each in features["frontends"]}
        assert frontends["rosbridge"] == {
            "subprotocols": [], "labels": ["rosbridge", "rosbridge-lossy"], "paths": [],
            "auth": "none",
        }  # fmt: skip
        assert "foxglove.sdk.v1" in frontends["foxglove"]["subprotocols"]
        assert frontends["http"]["paths"] == ["/api/", "/openapi.json"]
        assert frontends["version"]["paths"] == ["/version"]
        assert ("webrtc" in frontends) is features["webrtc"] and "mcp" not in frontends
        # the WebSocket beside it is unchanged
        ws = await harness.connect("ws")
        await ws.send({"op": "call_service", "service": "/rosapi/get_time", "id": "t"})


def test_the_server_string_is_the_installed_distributions_version() -> None:
    try:
        expected = importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        expected = "0+unknown"
    assert installed_version() == expected


async def test_version_over_tls(tls_harness: Harness) -> None:
    status, headers, body = await fetch_async(
        version_url(tls_harness, "https"), context=tls_harness.ssl_context
    )
    assert status == 200 and headers["Content-Type"] == "application/json"
    answer = json.loads(body)
    assert answer["protocol"]["major"] == 2
    assert answer["rwt"]["transports"][:2] == ["wss", "tcp+tls"]


async def test_methods_other_than_get_and_head() -> None:
    async with running_server() as harness:
        url = version_url(harness)
        status, headers, body = await fetch_async(url, "HEAD")
        assert status == 200 and body == b""
        assert headers["Content-Type"] == "application/json"
        get_length = len((await fetch_async(url))[2])
        assert int(headers["Content-Length"]) == get_length
        status, headers, body = await fetch_async(url, "POST")
        assert status == 405
        assert headers["Allow"] == "GET, HEAD, OPTIONS"
        assert b"GET and HEAD only" in body
        assert (await fetch_async(url, "DELETE"))[0] == 405
        status, headers, _ = await fetch_async(url, "OPTIONS")
        assert status == 204 and headers["Allow"] == "GET, HEAD, OPTIONS"
        # a query does not change the answer; a longer path is not /version
        assert (await fetch_async(url + "?x=1"))[0] == 200
        status, _, _ = await anyio.to_thread.run_sync(
            http_get, f"http://127.0.0.1:{harness.port('websocket')}", "/versions"
        )
        assert status == 404  # the console's answer to a path it does not have


async def test_a_body_is_bounded() -> None:
    async with running_server() as harness:
        url = version_url(harness)
        big = b"x" * 4096
        request = urllib.request.Request(url, data=big, method="GET")

        def send() -> int:
            try:
                with urllib.request.urlopen(request, timeout=TIMEOUT_S) as response:
                    return int(response.status)
            except urllib.error.HTTPError as error:
                error.close()
                return error.code

        assert await anyio.to_thread.run_sync(send) == 413


async def test_auth_mode_and_features_follow_the_configuration() -> None:
    config = ServerConfig(
        websocket=WebSocketOptions(allowed_origins=("https://robot.example",)),
    )
    async with running_server(config, authenticator=lambda op, peer: True) as harness:
        url = version_url(harness)
        # no auth needed to read it (as rosbridge_server's), and no secret in it (D49)
        status, _, body = await fetch_async(url)
        assert status == 200
        assert json.loads(body)["rwt"]["auth"] == "op"
        # how each front end's client proves who it is (AuthMode): the op, a URL token...
        proofs = {each["name"]: each["auth"] for each in json.loads(body)["rwt"]["frontends"]}
        assert proofs["rosbridge"] == "op" and proofs["foxglove"] == "url"
        assert proofs["http"] == "bearer" and proofs["version"] == "none"
        # a browser page from an allowed origin may read it; another origin is refused
        status, headers, _ = await fetch_async(url, headers={"Origin": "https://robot.example"})
        assert status == 200
        assert headers["Access-Control-Allow-Origin"] == "https://robot.example"
        status, _, _ = await fetch_async(url, headers={"Origin": "https://elsewhere.example"})
        assert status == 403


async def test_a_bound_auth_and_no_foxglove() -> None:
    config = ServerConfig(
        port=0,
        session=replace(ServerConfig().session, auth_challenge=True),
        foxglove=FoxgloveOptions(on_rosbridge_port=False),
    )
    server = RosbridgeServer(config=config, authenticator=lambda op, peer: True)
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        status, _, body = await fetch_async(url.replace("ws://", "http://") + "/version")
        tg.cancel_scope.cancel()
    assert status == 200
    features = json.loads(body)["rwt"]
    assert features["auth"] == "op-bound"
    assert features["subprotocols"] == []
    assert features["transports"] == ["ws"]


async def test_the_console_shows_the_versions() -> None:
    async with running_server() as harness:
        url = f"http://127.0.0.1:{harness.port('websocket')}"
        page = (await anyio.to_thread.run_sync(http_get, url, "/"))[2]
        script = (await anyio.to_thread.run_sync(http_get, url, "/console/main.js"))[2]
    assert b'id="server-version"' in page
    assert b"fetch('/version'" in script
    assert b"getElementById('server-version')" in script


async def test_the_optional_qos_of_protocol_2_1_is_accepted() -> None:
    """2.1.0's ``qos`` (docs/reference-behaviour.md §13.2) is read and ignored."""
    qos = {"history": "keep_last", "depth": 1, "reliability": "reliable", "durability": "volatile"}
    async with running_server() as harness:
        ws = await harness.connect("ws")
        with anyio.fail_after(TIMEOUT_S):
            topic, kind = "/qos_chatter", "std_msgs/msg/String"
            await ws.send({"op": "advertise", "topic": topic, "type": kind, "qos": qos})
            await ws.send({"op": "subscribe", "topic": topic, "type": kind, "qos": qos})
            await ws.send({"op": "publish", "topic": topic, "msg": {"data": "hi"}, "qos": qos})
            message = await ws.expect(is_op("publish", topic=topic))
        assert message["msg"] == {"data": "hi"}


async def test_compat_rosbridge_2_1_has_no_version_endpoint() -> None:
    """rosbridge_suite 2.1.0 has no ``/version``: ``--compat rosbridge-2.1`` answers 404 (D49)."""
    compat = ServerConfig(session=SessionConfig(compat=Compat.ROSBRIDGE_2_1))
    async with running_server(compat) as harness:
        url = version_url(harness)
        for method in ("GET", "HEAD", "POST"):
            status, _, body = await fetch_async(url, method)
            assert status == 404, method
        assert b"rosbridge_suite 2.1.0, which has none" in (await fetch_async(url))[2]
    # --compat rosbridge (2.1.0's texts, publish with type advertising) still answers
    rosbridge = ServerConfig(session=SessionConfig(compat=Compat.ROSBRIDGE))
    async with running_server(rosbridge) as harness:
        status, _, body = await fetch_async(version_url(harness))
        assert status == 200 and json.loads(body)["protocol"]["minor"] == 1
