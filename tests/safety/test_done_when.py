"""``rwt serve --safety FILE --mcp`` with the example file, as a user runs it, end to end.

Every client is a real one against the command line's server: roslibpy publishes
``linear.x`` 2.0 and ``angular.z`` -5.0 and a WebSocket subscriber gets 0.5 and -1.0,
then the dead-man's stop once roslibpy is quiet; ``/arm/joint_cmd`` 9.0 is an error
status naming ``data``, its bound and the value, and nothing is delivered, then 1.0
arrives; ``POST /api/topics/cmd_vel`` (httpx) with ``linear.x`` 3.0 arrives as 0.5;
the official MCP client on 2026-07-28 whose person declines publishes nothing, and one
whose person accepts publishes ``linear.x`` 0.2 (docs/safety.md).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import anyio
import httpx
import pytest
from websockets.asyncio.client import ClientConnection, connect

pytest.importorskip("mcp", reason="the MCP SDK is not installed (the mcp or test extra)")

from mcp import Client

from tests.safety.example import HANG_S, STOP, example_file, twist
from tests.safety.test_approval import DRIVE, MODERN, Person
from tests.support.cli import rwt_serve
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio

Message = dict[str, Any]


async def _next(ws: ClientConnection, op: str, **fields: object) -> Message:
    with anyio.fail_after(HANG_S):
        while True:
            message = json.loads(await ws.recv())
            if message.get("op") == op and all(message.get(k) == v for k, v in fields.items()):
                return message  # type: ignore[no-any-return]


async def _twist(ws: ClientConnection) -> tuple[float, float]:
    msg = (await _next(ws, "publish", topic="/cmd_vel"))["msg"]
    return msg["linear"]["x"], msg["angular"]["z"]


async def test_the_example_file_on_every_front_end(tmp_path: Path) -> None:
    rules = example_file(tmp_path)
    async with rwt_serve("--port", "0", "--safety", str(rules), "--mcp") as (_, urls):
        url = urls["ws"]
        async with connect(url, ping_interval=None) as watch:
            for topic in ("/cmd_vel", "/arm/joint_cmd"):
                await watch.send(json.dumps({"op": "subscribe", "topic": topic}))
            await watch.send(json.dumps({"op": "call_service", "service": "/rosapi/get_time"}))
            await _next(watch, "service_response")  # subscribed

            port = int(url.rsplit(":", 1)[1])
            await run_python(
                f"""
                import time, roslibpy
                ros = roslibpy.Ros("127.0.0.1", {port})
                ros.run(timeout=10)
                topic = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/Twist")
                topic.advertise()
                for _ in range(5):
                    topic.publish(roslibpy.Message({json.dumps(twist(2.0, -5.0))}))
                    time.sleep(0.1)
                time.sleep(1.0)  # quiet while connected: the stop comes
                ros.terminate()
                """
            )
            assert [await _twist(watch) for _ in range(6)] == [(0.5, -1.0)] * 5 + [(0.0, 0.0)]

            async with connect(url, ping_interval=None) as arm:
                publish = {"op": "publish", "topic": "/arm/joint_cmd", "type": "std_msgs/Float64"}
                await arm.send(json.dumps({**publish, "id": "far", "msg": {"data": 9.0}}))
                error = await _next(arm, "status", level="error")
                assert "data 9 is outside [0, 3.14]" in error["msg"]
                await arm.send(json.dumps({**publish, "msg": {"data": 1.0}}))
                joint = await _next(watch, "publish", topic="/arm/joint_cmd")
                assert joint["msg"] == {"data": 1.0}  # 9.0 never came

            http_url = url.replace("ws://", "http://")
            async with httpx.AsyncClient(base_url=http_url, timeout=HANG_S) as http:
                answer = await http.post("/api/topics/cmd_vel", json={"linear": {"x": 3.0}})
            assert answer.status_code == 200
            assert await _twist(watch) == (0.5, 0.0)
            assert await _twist(watch) == (0.0, 0.0)  # the request's command stood, then stopped

            mcp_url = http_url + "/mcp"
            for answer_of_person in ("decline", "accept"):
                person = Person(answer_of_person)
                with anyio.fail_after(60):
                    async with Client(mcp_url, mode=MODERN, elicitation_callback=person) as c:
                        result = await c.call_tool("publish", DRIVE)
                assert result.is_error == (answer_of_person == "decline")
            assert await _twist(watch) == (0.2, 0.0)  # the accepted one, the declined never came
            assert (await _next(watch, "publish", topic="/cmd_vel"))["msg"] == STOP
