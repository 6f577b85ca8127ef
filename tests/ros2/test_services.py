"""Services both ways between real rclpy nodes and rosbridge clients through `rwt serve --ros2`."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import anyio
import pytest

from rwt_ros2.node import MAX_WAITING
from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import JsonLines, Peer, roslibpy_prelude, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]

CALL = """
service = roslibpy.Service(ros, "{name}", "std_srvs/srv/SetBool")
wait_for(lambda: "{name}" in ros.get_services())
try:
    response = service.call(roslibpy.ServiceRequest({{"data": True}}), timeout=20)
    print(json.dumps({{"response": dict(response)}}))
except Exception as exc:
    print(json.dumps({{"error": str(exc)}}))
ros.terminate()
"""


def _last_json(out: str) -> dict[str, object]:
    return json.loads(out.strip().splitlines()[-1])


async def test_roslibpy_calls_a_ros2_service(server: ServerProcess, ros_env: Path) -> None:
    with Peer("serve", "/ros2_switch", ros_env):
        out = await run_python(roslibpy_prelude(server.port) + CALL.format(name="/ros2_switch"))
    assert _last_json(out) == {"response": {"success": True, "message": "ros2 got True"}}


async def test_a_call_to_a_ros2_server_that_went_fails(
    server: ServerProcess, ros_env: Path
) -> None:
    script = """
service = roslibpy.Service(ros, "/short_lived", "std_srvs/srv/SetBool")
print(json.dumps({"listed": wait_for(lambda: "/short_lived" in ros.get_services())}), flush=True)
input()  # the server is stopped meanwhile
wait_for(lambda: "/short_lived" not in ros.get_services())
try:
    response = service.call(roslibpy.ServiceRequest({"data": True}), timeout=20)
    print(json.dumps({"response": dict(response)}))
except Exception as exc:
    print(json.dumps({"error": str(exc)}))
ros.terminate()
"""
    peer = Peer("serve", "/short_lived", ros_env)
    try:
        async with await anyio.open_process(
            ["python", "-c", roslibpy_prelude(server.port) + script]
        ) as client:
            assert client.stdout is not None and client.stdin is not None
            lines = JsonLines(client.stdout)
            with anyio.fail_after(30):
                assert await lines.next() == {"listed": True}
                peer.stop()
                await client.stdin.send(b"\n")
                answer = await lines.last()
    finally:
        peer.stop()
    assert "error" in answer, answer
    assert "/short_lived" in str(answer["error"])


ADVERTISE = """
def handler(request, response):
    response["success"] = request["data"]
    response["message"] = "web answered"
    return True

service = roslibpy.Service(ros, "/web_switch", "std_srvs/srv/SetBool")
service.advertise(handler)
print(json.dumps({"advertised": True}), flush=True)
time.sleep(25)
ros.terminate()
"""


async def test_a_ros2_client_calls_a_service_a_rosbridge_client_advertised(
    server: ServerProcess, ros_env: Path
) -> None:
    async with await anyio.open_process(
        ["python", "-c", roslibpy_prelude(server.port) + ADVERTISE]
    ) as provider:
        try:
            assert provider.stdout is not None
            with anyio.fail_after(20):
                assert await JsonLines(provider.stdout).next() == {"advertised": True}
            with Peer("call", "/web_switch", ros_env) as caller:
                answer = await anyio.to_thread.run_sync(caller.next)
        finally:
            with contextlib.suppress(ProcessLookupError):  # it may have exited already
                provider.kill()
    assert answer == {"response": {"success": True, "message": "web answered"}}


HANGING = """
import os, threading
def handler(request, response):
    print(json.dumps({"called": True}), flush=True)
    # the provider vanishes mid-call, after 3 s: the link's answer then goes out once the
    # server's response writer has matched the caller's reader (DDS discovery is not
    # symmetric; sent sooner under load, the answer was lost and the caller heard nothing)
    threading.Timer(3.0, lambda: os._exit(0)).start()
    time.sleep(30)
    return True

service = roslibpy.Service(ros, "/vanishing", "std_srvs/srv/SetBool")
service.advertise(handler)
print(json.dumps({"advertised": True}), flush=True)
time.sleep(25)
"""


async def test_a_pending_ros2_call_fails_cleanly_when_its_provider_disconnects(
    server: ServerProcess, ros_env: Path
) -> None:
    async with await anyio.open_process(
        ["python", "-c", roslibpy_prelude(server.port) + HANGING]
    ) as provider:
        try:
            assert provider.stdout is not None
            with anyio.fail_after(20):
                assert await JsonLines(provider.stdout).next() == {"advertised": True}
            with Peer("call", "/vanishing", ros_env) as caller:
                answer = await anyio.to_thread.run_sync(caller.next)
        finally:
            with contextlib.suppress(ProcessLookupError):  # it may have exited already
                provider.kill()
    # the ROS 2 caller is answered at once (rclpy services cannot answer an error: the
    # default response), not left waiting for the link's call timeout
    assert answer == {"response": {"success": False, "message": ""}}
    assert "event=ros2_call_failed service=/vanishing" in server.stderr_text()


STUCK = """
def handler(request, response):
    print(json.dumps({"called": True}), flush=True)
    time.sleep(60)  # never answers while the test runs
    return True

service = roslibpy.Service(ros, "/stuck", "std_srvs/srv/SetBool")
service.advertise(handler)
print(json.dumps({"advertised": True}), flush=True)
time.sleep(60)
"""

FLOWING = """
got = []
roslibpy.Topic(ros, "/still_flowing", "std_msgs/msg/String").subscribe(got.append)
wait_for(lambda: len(got) >= 1)
mark = len(got)
print(json.dumps({"flowing": True}), flush=True)
input()  # the calls are stuck meanwhile
wait_for(lambda: len(got) >= mark + 10)
print(json.dumps({"during": len(got) - mark >= 10}))
ros.terminate()
"""


async def test_calls_from_ros2_stuck_in_the_graph_leave_the_topics_flowing(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("talk", "/still_flowing", ros_env):
        async with (
            await anyio.open_process(
                ["python", "-c", roslibpy_prelude(server.port) + STUCK]
            ) as provider,
            await anyio.open_process(
                ["python", "-c", roslibpy_prelude(server.port) + FLOWING]
            ) as listener,
        ):
            try:
                assert provider.stdout is not None and listener.stdout is not None
                assert listener.stdin is not None
                with anyio.fail_after(30):
                    assert await JsonLines(provider.stdout).next() == {"advertised": True}
                    heard = JsonLines(listener.stdout)
                    assert await heard.next() == {"flowing": True}
                calls = MAX_WAITING + 4
                with Peer("call_many", "/stuck", ros_env, str(calls)) as callers:
                    # the calls beyond the waiting ones are answered at once
                    first = {"answered": 0}
                    while first["answered"] < calls - MAX_WAITING:
                        first = await anyio.to_thread.run_sync(callers.next)
                    await listener.stdin.send(b"\n")
                    with anyio.fail_after(30):
                        during = await heard.next()
                    provider.kill()  # the provider goes: the waiting calls fail (D15)
                    lines = [first]
                    try:
                        while "responses" not in lines[-1]:
                            lines.append(await anyio.to_thread.run_sync(callers.next))
                    except AssertionError as exc:  # what the server saw, to tell why
                        raise AssertionError(f"{exc}\n{server.stderr_text()[-4000:]}") from exc
            finally:
                for process in (provider, listener):
                    with contextlib.suppress(ProcessLookupError):
                        process.kill()
    assert during == {"during": True}
    assert lines[-1]["responses"] == [[False, ""]] * calls


CALL_AT_START = """
import json, sys
from websockets.sync.client import connect

with connect("ws://127.0.0.1:{port}") as ws:
    print(json.dumps({{"connected": True}}), flush=True)
    sys.stdin.readline()  # the ROS 2 server has just started
    call = {{"op": "call_service", "id": "c1", "service": "{name}", "args": {{"data": True}}}}
    ws.send(json.dumps({{**call, **{timeout}}}))
    while True:
        reply = json.loads(ws.recv(timeout=30))
        if reply["op"] == "service_response":
            print(json.dumps(reply), flush=True)
            break
"""


async def test_a_call_issued_as_the_ros2_server_starts_waits_for_it(
    server: ServerProcess, ros_env: Path
) -> None:
    # The call comes as soon as the node has made its service, before the link has
    # discovered it: it waits for the discovery (up to its own timeout, 20 s) and is
    # answered by the node, not refused as a service that does not exist.
    code = CALL_AT_START.format(port=server.port, name="/starting_switch", timeout={"timeout": 20})
    async with await anyio.open_process(["python", "-c", code]) as client:
        assert client.stdout is not None and client.stdin is not None
        lines = JsonLines(client.stdout)
        with anyio.fail_after(40):
            assert await lines.next() == {"connected": True}
            with Peer("serve", "/starting_switch", ros_env):
                await client.stdin.send(b"\n")
                reply = await lines.next()
    assert reply["id"] == "c1"
    assert reply["result"] is True, reply
    assert reply["values"] == {"success": True, "message": "ros2 got True"}


async def test_a_call_to_a_service_nobody_offers_fails_after_the_discovery_wait(
    server: ServerProcess, ros_env: Path
) -> None:
    # no timeout of its own: it waits DISCOVERY_WAIT_S for the service, then fails
    code = CALL_AT_START.format(port=server.port, name="/nobody_offers", timeout={})
    async with await anyio.open_process(["python", "-c", code]) as client:
        assert client.stdout is not None and client.stdin is not None
        lines = JsonLines(client.stdout)
        with anyio.fail_after(40):
            assert await lines.next() == {"connected": True}
            await client.stdin.send(b"\n")
            reply = await lines.next()
    assert reply["result"] is False
    assert reply["values"] == "service /nobody_offers does not exist"
