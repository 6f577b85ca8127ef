"""`rwt serve` answers plain HTTP GETs with the console beside the WebSocket (docs/console.md)."""

from __future__ import annotations

import json
import socket
import ssl
import subprocess
from collections.abc import Iterator
from pathlib import Path

import anyio
import pytest
import trustme
from websockets.asyncio.client import connect

from tests.integration.client_harness import ServerProcess
from tests.support.cli import RWT

TIMEOUT_S = 10.0


def http_get(
    url: str, target: str, method: str = "GET", tls: ssl.SSLContext | None = None
) -> tuple[int, dict[str, str], bytes]:
    """One raw HTTP/1.1 request (the target is sent exactly as given, unnormalised)."""
    host, port = url.split("://", 1)[1].split("/", 1)[0].rsplit(":", 1)
    raw = socket.create_connection((host, int(port)), timeout=TIMEOUT_S)
    with raw if tls is None else tls.wrap_socket(raw, server_hostname=host) as sock:
        sock.sendall(f"{method} {target} HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
        data = b""
        try:
            while chunk := sock.recv(65536):
                data += chunk
        except ssl.SSLEOFError:  # the server closes without close_notify: the reply is whole
            pass
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    fields = dict(line.split(": ", 1) for line in lines[1:])
    return int(lines[0].split()[1]), fields, body


@pytest.fixture
def serve(tmp_path: Path) -> Iterator:
    servers: list[ServerProcess] = []

    def start(*args: str) -> ServerProcess:
        server = ServerProcess(tmp_path, args)
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.stop()


async def rosapi_topics(url: str) -> list[str]:
    async with connect(url, open_timeout=TIMEOUT_S) as ws:
        await ws.send(json.dumps({"op": "call_service", "id": "1", "service": "/rosapi/topics"}))
        with anyio.fail_after(TIMEOUT_S):
            reply = json.loads(await ws.recv())
    return reply["values"]["topics"]


def test_the_console_and_the_websocket_share_the_port(serve) -> None:
    server = serve()
    status, fields, body = http_get(server.url, "/")
    assert status == 200
    assert fields["Content-Type"] == "text/html; charset=utf-8"
    assert b'<script type="module" src="/console/main.js">' in body
    status, fields, body = http_get(server.url, "/console/config.json")
    config = json.loads(body)
    assert config["websocket"] == {"port": None, "path": "/", "tls": False}
    assert config["video"] is None
    assert config["auth"] is False
    assert config["foxglove"] is True  # the page shows Foxglove's URL (docs/foxglove.md)
    assert config["limits"]["--max-message-size"] == 10 * 1024 * 1024  # rwt serve's default
    for target in ("/console/../../../etc/passwd", "/console/%2e%2e/site.py", "/nothing"):
        status, _, body = http_get(server.url, target)
        assert status == 404, target
        assert b"root:" not in body
    assert http_get(server.url, "/", "POST")[0] in (400, 405)
    assert "/client_count" in anyio.run(rosapi_topics, server.url)  # the WebSocket, as before


def test_url_path_moves_the_websocket_not_the_console(serve) -> None:
    server = serve("--url-path", "/rosbridge", "--max-subscriptions", "7")
    assert http_get(server.url, "/")[0] == 200
    config = json.loads(http_get(server.url, "/console/config.json")[2])
    assert config["websocket"]["path"] == "/rosbridge"
    assert config["limits"]["--max-subscriptions"] == 7
    assert anyio.run(rosapi_topics, server.url + "/rosbridge")


@pytest.mark.parametrize(
    ("args", "served"),
    [
        (("--no-console",), False),
        (("--allowed-origins", "https://robot.example"), False),
        (("--allowed-origins", "http://127.0.0.1:*", "--console"), True),
    ],
)
def test_when_the_console_is_off(serve, args: tuple[str, ...], served: bool) -> None:
    server = serve(*args)
    status, _, body = http_get(server.url, "/")
    assert (status == 200) is served
    if not served:
        assert b"<html" not in body


def test_auth_is_announced_to_the_page(serve, tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("1234567890abcdef\n")
    server = serve("--auth-secret-file", str(secret))
    assert json.loads(http_get(server.url, "/console/config.json")[2])["auth"] is True


def test_without_foxglove_the_page_offers_no_foxglove_url(serve) -> None:
    server = serve("--no-foxglove")
    assert json.loads(http_get(server.url, "/console/config.json")[2])["foxglove"] is False


def test_the_video_port_serves_the_console_too(serve) -> None:
    server = serve("--video", "--video-port", "0")
    line = server.next_stdout_line()
    assert line is not None and line.startswith("video on "), line
    video_url = line.removeprefix("video on ")
    ws_port = int(server.url.rsplit(":", 1)[1])
    video_port = int(video_url.rsplit(":", 1)[1])
    assert json.loads(http_get(server.url, "/console/config.json")[2])["video"] == {
        "port": video_port,
        "token": False,  # no --auth-secret-file: the streams are open
    }
    config = json.loads(http_get(video_url, "/console/config.json")[2])
    assert config["video"] == {"port": video_port, "token": False}  # its images show too
    assert config["websocket"] == {"port": ws_port, "path": "/", "tls": False}
    status, _, body = http_get(video_url, "/console/")
    assert status == 200 and b"rwt console" in body
    size = len(http_get(video_url, "/console/main.js")[2])
    for url in (server.url, video_url):
        status, fields, body = http_get(url, "/console/main.js", "HEAD")
        assert (status, fields["Content-Length"], body) == (200, str(size), b"")
    status, _, body = http_get(video_url, "/")  # web_video_server's topic list stays
    assert status == 200 and b"Available ROS Image Topics" in body


def test_over_tls_the_page_is_https_and_connects_with_wss(tmp_path: Path) -> None:
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1")
    certfile, keyfile = tmp_path / "cert.pem", tmp_path / "key.pem"
    cert.cert_chain_pems[0].write_to_path(certfile)
    cert.private_key_pem.write_to_path(keyfile)
    args = ("--port", "0", "--certfile", str(certfile), "--keyfile", str(keyfile))
    command = [*RWT, "serve", "--host", "127.0.0.1", *args]
    server = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        assert server.stdout is not None
        line = server.stdout.readline().decode()  # the server prints it at once, or exits
        assert line.startswith("listening on wss://"), line
        url = line.removeprefix("listening on ").strip()
        context = ssl.create_default_context()
        ca.configure_trust(context)
        status, _, body = http_get(url, "/", tls=context)
        assert status == 200 and b"rwt console" in body
        config = json.loads(http_get(url, "/console/config.json", tls=context)[2])
        assert config["websocket"]["tls"] is True
    finally:
        server.terminate()
        server.wait(10)
        server.stdout.close()
