"""Running out of file descriptors never ends the server (docs/limits.md: descriptors).

A real ``rwt serve`` runs with a low RLIMIT_NOFILE (soft = hard = 200, so its
start-up raise of soft to hard changes nothing) and more idle sockets than that
are opened to its WebSocket port, none of which ever starts a handshake. With an
explicit ``--max-connections`` above the limit, ``accept()`` fails with EMFILE:
the server backs off, logs it once per episode and serves again once some close.
With the default ``--max-connections`` (derived from the limit) it never gets
that far: sockets count from ``accept()``, idle ones are closed after
``--handshake-timeout``, and accepting pauses while the budget is spent.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import anyio
import pytest
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from rwt_transports.server import RosbridgeServer, ServerConfig

REPO = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": f"{REPO / 'src'}{os.pathsep}{REPO}", "PYTHONUNBUFFERED": "1"}
FD_LIMIT = 200
IDLE_SOCKETS = 260
WAIT_S = 60.0  # a bound on waiting for the server, not a speed requirement


def limited_rwt(soft: int, hard: int) -> list[str]:
    """``python -m rwt serve ...`` after lowering the child's own limits."""
    code = (
        "import resource, runpy, sys;"
        f"resource.setrlimit(resource.RLIMIT_NOFILE, ({soft}, {hard}));"
        "sys.argv[0] = 'rwt';"
        "runpy.run_module('rwt', run_name='__main__')"
    )
    return [sys.executable, "-c", code, "serve", "--host", "127.0.0.1", "--port", "0"]


SERVE = [*limited_rwt(FD_LIMIT, FD_LIMIT), "--tcp-port", "0", "--no-tf"]


@contextmanager
def rwt_serve(*args: str, log: Path) -> Iterator[tuple[subprocess.Popen[bytes], int, int]]:
    """``rwt serve`` (WebSocket and TCP) under the low limit; its ports once listening."""
    with log.open("wb") as stderr:
        process = subprocess.Popen(
            [*SERVE, *args],
            env=ENV,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=stderr,
        )
    try:
        assert process.stdout is not None
        urls = {}
        while len(urls) < 2:
            line = process.stdout.readline().decode()
            assert line, f"rwt serve ended: {log.read_text()}"
            url = line.strip().removeprefix("listening on ")
            urls[url.split("://")[0]] = int(url.rsplit(":", 1)[1])
        yield process, urls["ws"], urls["tcp"]
    finally:
        process.kill()
        process.wait(10)
        process.stdout.close()  # type: ignore[union-attr]


def idle_sockets(port: int, count: int) -> list[socket.socket]:
    """Connected sockets that never send a byte (the kernel completes the connect)."""
    return [socket.create_connection(("127.0.0.1", port), timeout=WAIT_S) for _ in range(count)]


def ws_served(port: int) -> None:
    """A WebSocket client is served, reconnecting (as clients do) while refused with 503.

    Sockets in their handshake count against ``--max-connections``, so a client
    accepted while idle sockets accepted just before it still hold their slots is
    refused; once their handshake timeout closes them, it is served.
    """
    deadline = time.monotonic() + WAIT_S
    while True:
        try:
            with connect(f"ws://127.0.0.1:{port}", open_timeout=WAIT_S) as ws:
                ws.send(json.dumps({"op": "set_level", "level": "info", "id": "healthy"}))
                reply = json.loads(ws.recv(timeout=WAIT_S))
                assert reply["op"] == "status" and reply["id"] == "healthy"
                return
        except InvalidStatus as refused:
            assert refused.response.status_code == 503
            assert time.monotonic() < deadline, "still refused: too many connections"
            time.sleep(0.2)


def tcp_served(port: int) -> None:
    """A TCP client is served, reconnecting while told "too many connections"."""
    deadline = time.monotonic() + WAIT_S
    while True:
        with socket.create_connection(("127.0.0.1", port), timeout=WAIT_S) as tcp:
            tcp.sendall(b'{"op":"set_level","level":"info","id":"healthy"}')
            reply = json.loads(tcp.makefile("rb").readline())
        if reply.get("msg") == "too many connections":
            assert time.monotonic() < deadline, "still refused: too many connections"
            time.sleep(0.2)
            continue
        assert reply["op"] == "status" and reply["id"] == "healthy"
        return


def wait_for(process: subprocess.Popen[bytes], log: Path, text: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while text not in log.read_text():
        assert process.poll() is None, f"rwt serve ended: {log.read_text()[-3000:]}"
        assert time.monotonic() < deadline, f"no {text!r} in: {log.read_text()[-3000:]}"
        time.sleep(0.05)


def test_emfile_on_accept_backs_off_and_the_server_serves_again(tmp_path: Path) -> None:
    log = tmp_path / "serve.log"
    with rwt_serve("--max-connections", "1000", log=log) as (process, ws_port, tcp_port):
        idle = idle_sockets(ws_port, IDLE_SOCKETS)
        try:
            wait_for(process, log, "event=accept_backoff")
            assert process.poll() is None
            for sock in idle[: IDLE_SOCKETS // 2]:  # some idle peers go away
                sock.close()
            ws_served(ws_port)
            tcp_served(tcp_port)
        finally:
            for sock in idle:
                sock.close()
        assert process.poll() is None
        text = log.read_text()
    # once per episode: each back-off line is followed by a resume before the next
    assert 1 <= text.count("event=accept_backoff") <= text.count("event=accept_resumed") + 1


def test_the_default_max_connections_keeps_accept_within_the_descriptors(
    tmp_path: Path,
) -> None:
    log = tmp_path / "serve.log"
    with rwt_serve("--handshake-timeout", "1", log=log) as (process, ws_port, tcp_port):
        idle = idle_sockets(ws_port, IDLE_SOCKETS)
        try:
            ws_served(ws_port)  # once idle sockets ahead of it were closed for their silence
            tcp_served(tcp_port)
            assert process.poll() is None
        finally:
            for sock in idle:
                sock.close()
        text = log.read_text()
    assert "event=handshake_timeout" in text
    assert "event=accept_backoff" not in text  # never ran out of descriptors
    soft = FD_LIMIT
    assert f"event=max_connections limit={soft - min(128, soft // 2) - 16}" in text


@pytest.mark.anyio
@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_sockets_in_their_handshake_count_against_max_connections(
    anyio_backend: str,
) -> None:
    config = ServerConfig(port=0, tcp_port=0, max_connections=2, handshake_timeout_s=30)
    server = RosbridgeServer(config=config)
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        ws_port = int(url.rsplit(":", 1)[1])
        tcp_port = int(server.urls["tcp"].rsplit(":", 1)[1])
        with anyio.fail_after(30):
            idle = [await anyio.connect_tcp("127.0.0.1", ws_port) for _ in range(2)]
            # (the backlog is first in, first out: they are accepted before the next one)
            with pytest.raises(InvalidStatus) as refused:
                await ws_connect(url)
            assert refused.value.response.status_code == 503
            async with await anyio.connect_tcp("127.0.0.1", tcp_port) as tcp:
                assert b"too many connections" in await tcp.receive()
            for sock in idle:
                await sock.aclose()
            async with ws_connect(url) as ws:  # their descriptors are free again
                await ws.send(json.dumps({"op": "set_level", "level": "info", "id": "ok"}))
                assert json.loads(await ws.recv())["id"] == "ok"
        tg.cancel_scope.cancel()


@pytest.mark.parametrize(("raise_limit", "limit"), [(True, 256), (False, 84)])  # minus reserves
def test_the_soft_limit_is_raised_to_the_hard_one_unless_told_not_to(
    tmp_path: Path, raise_limit: bool, limit: int
) -> None:
    log = tmp_path / "serve.log"
    option = "--raise-fd-limit" if raise_limit else "--no-raise-fd-limit"
    with log.open("wb") as stderr:
        process = subprocess.Popen(
            [*limited_rwt(200, 400), "--no-tf", option],
            env=ENV,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=stderr,
        )
    try:
        assert process.stdout is not None
        assert process.stdout.readline().startswith(b"listening on ")
        text = log.read_text()
        assert f"event=max_connections limit={limit}" in text
        assert ("event=fd_limit soft=400 hard=400 raised_from=200" in text) is raise_limit
    finally:
        process.kill()
        process.wait(10)
        process.stdout.close()  # type: ignore[union-attr]
