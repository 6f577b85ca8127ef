"""`rwt serve` as a user runs it: every listener from one command, stdio, signals, --help."""

from __future__ import annotations

import json
import signal

import anyio
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from tests.support.cli import ENV, SERVE, port, rwt_serve
from tests.support.clients import validate_udp
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio


async def test_help_documents_every_option() -> None:
    result = await anyio.run_process([*SERVE[:-2], "--help"], env={**ENV, "COLUMNS": "200"})
    text = result.stdout.decode()
    for option in (
        "--port",
        "--tcp-port",
        "--udp-port",
        "--stdio",
        "--certfile",
        "--keyfile",
        "--auth-secret-file",
        "--topics-glob",
        "--services-glob",
        "--params-glob",
        "--actions-glob",
        "--allowed-origins",
        "--url-path",
        "--max-connections",
        "--max-message-size",
        "--send-buffer-limit",
        "--send-timeout",
        "--websocket-ping-interval",
        "--websocket-ping-timeout",
        "--log-level",
        "--uvloop",
        "--webrtc",
        "--mcp",
        "--mcp-read-only",
    ):
        assert option in text, option


async def test_uvloop_server_relays_a_message() -> None:
    pytest.importorskip("uvloop")
    async with rwt_serve("--port", "0", "--uvloop") as (_, urls):
        url = urls["ws"]
        async with connect(url) as sub, connect(url) as pub:
            await sub.send('{"op":"subscribe","topic":"/u","type":"std_msgs/String"}')
            await sub.send('{"op":"call_service","service":"/rosapi/get_time","id":"sync"}')
            with anyio.fail_after(10):
                assert '"id":"sync"' in await sub.recv()
                await pub.send('{"op":"publish","topic":"/u","msg":{"data":"hi"}}')
                reply = json.loads(await sub.recv())
        assert reply == {"op": "publish", "topic": "/u", "msg": {"data": "hi"}}


async def test_one_command_serves_every_transport_on_one_graph() -> None:
    async with rwt_serve("--port", "0", "--tcp-port", "0", "--udp-port", "0", listeners=3) as (
        _,
        urls,
    ):
        assert list(urls) == ["ws", "tcp", "udp"]  # the WebSocket line comes first
        tcp = await anyio.connect_tcp("127.0.0.1", port(urls["tcp"]))
        await tcp.send(b'{"op":"advertise","topic":"/from_tcp","type":"std_msgs/String"}')
        udp = await anyio.create_connected_udp_socket("127.0.0.1", port(urls["udp"]))
        token = await validate_udp(udp)
        await udp.send(token + b'{"op":"subscribe","topic":"/from_tcp","type":"std_msgs/String"}')
        await udp.send(token + b'{"op":"set_level","level":"info","id":"b"}')
        with anyio.fail_after(10):
            while json.loads(await udp.receive()).get("id") != "b":
                pass
        # roslibpy (WebSocket) subscribes; the raw TCP client publishes once it is in.
        subscriber = run_python(
            f"""
            import threading, roslibpy
            ros = roslibpy.Ros("127.0.0.1", {port(urls["ws"])})
            ros.run(timeout=20)
            got = threading.Event()
            topic = roslibpy.Topic(ros, "/from_tcp", "std_msgs/String")
            topic.subscribe(lambda m: (print(m["data"], flush=True), got.set()))
            print("subscribed", flush=True)
            assert got.wait(20)
            ros.terminate()
            """
        )
        async with anyio.create_task_group() as tg:
            outputs: list[str] = []

            async def run_subscriber() -> None:
                outputs.append(await subscriber)

            tg.start_soon(run_subscriber)
            with anyio.fail_after(30):
                while not outputs:
                    await tcp.send(b'{"op":"publish","topic":"/from_tcp","msg":{"data":"hi"}}\n')
                    await anyio.sleep(0.2)
        assert "hi" in outputs[0].split()
        await tcp.aclose()
        await udp.aclose()


async def test_stdio_session_driven_by_a_parent_process() -> None:
    ops = [
        {"op": "set_level", "level": "info"},
        {"op": "advertise", "topic": "/loop", "type": "std_msgs/String"},
        {"op": "subscribe", "topic": "/loop"},
        {"op": "publish", "topic": "/loop", "msg": {"data": "round trip"}},
    ]
    text = "".join(json.dumps(op) + "\n" for op in ops) + "this is not json\n"
    with anyio.fail_after(30):
        result = await anyio.run_process(
            [*SERVE, "--stdio", "--no-websocket"], input=text.encode(), env=ENV, check=False
        )
    assert result.returncode == 0, result.stderr.decode()
    lines = [json.loads(line) for line in result.stdout.decode().splitlines()]  # JSON only
    assert {"op": "publish", "topic": "/loop", "msg": {"data": "round trip"}} in lines
    assert lines[-1]["level"] == "error" and "invalid JSON" in lines[-1]["msg"]
    assert "event=connect client=stdio" in result.stderr.decode()


async def test_sigterm_answers_pending_callers_and_closes_with_1001() -> None:
    async with rwt_serve("--port", "0") as (process, urls):
        async with (
            connect(urls["ws"]) as provider,
            connect(urls["ws"]) as caller,
        ):
            await provider.send(
                json.dumps(
                    {"op": "advertise_service", "service": "/slow", "type": "std_srvs/Empty"}
                )
            )
            await caller.send(json.dumps({"op": "call_service", "service": "/slow", "id": "c"}))
            with anyio.fail_after(10):
                request = json.loads(await provider.recv())  # the call is now pending
                assert request["op"] == "call_service"
                process.send_signal(signal.SIGTERM)
                reply = json.loads(await caller.recv())
                with pytest.raises(ConnectionClosed) as closed:
                    await caller.recv()
                assert await process.wait() == 0
        assert reply["op"] == "service_response" and reply["result"] is False
        assert reply["id"] == "c" and "shutting down" in reply["values"]
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1001


async def test_bad_tls_files_fail_at_start_with_a_message(tmp_path: object) -> None:
    result = await anyio.run_process(
        [*SERVE, "--port", "0", "--certfile", "/nonexistent.pem"], env=ENV, check=False
    )
    assert result.returncode == 2  # a usage error (tests/cli/test_cli_usage.py)
    assert result.stderr.decode() == "rwt serve: --certfile: no such file: /nonexistent.pem\n"
