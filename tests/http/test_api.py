"""The HTTP API with real clients (curl, httpx): topics, events, services, actions, rules."""

from __future__ import annotations

import json

import anyio
import httpx
import pytest

from rwt_graph.graph import Graph
from rwt_http import HttpApiOptions
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig

from .support import api_server, curl

pytestmark = pytest.mark.anyio


async def test_topics_are_listed_published_to_and_read_with_curl() -> None:
    graph = Graph()
    got: list[dict[str, object]] = []
    graph.create_subscription("/robot/say", got.append, "std_msgs/msg/String")
    latched = graph.create_publisher("/robot/mode", "std_msgs/msg/String", latch=True)
    latched.publish({"data": "auto"})
    async with api_server(graph) as (_, url):
        status, body = await curl(f"{url}/api/topics")
        assert status == 200
        listing = json.loads(body)
        assert "/robot/say" in listing["topics"]
        index = listing["topics"].index("/robot/mode")
        assert listing["types"][index] == "std_msgs/msg/String"

        status, body = await curl("-d", '{"data": "hello"}', f"{url}/api/topics/robot/say")
        assert (status, json.loads(body)) == (
            200,
            {"topic": "/robot/say", "type": "std_msgs/msg/String"},
        )
        assert got == [{"data": "hello"}]

        status, body = await curl(f"{url}/api/topics/robot/mode")
        assert (status, json.loads(body)) == (200, {"data": "auto"})


async def test_publishing_needs_a_type_for_a_new_topic_and_a_message_object() -> None:
    graph = Graph()
    got: list[dict[str, object]] = []
    async with api_server(graph) as (_, url):
        status, body = await curl("-d", '{"data": 1}', f"{url}/api/topics/fresh")
        assert status == 404 and "type" in json.loads(body)["error"]
        status, _ = await curl("-d", "[1, 2]", f"{url}/api/topics/fresh?type=std_msgs/msg/Int32")
        assert status == 400
        graph.create_subscription("/fresh", got.append, "std_msgs/msg/Int32")
        status, _ = await curl("-d", '{"data": 7}', f"{url}/api/topics/fresh?type=std_msgs/Int32")
        assert status == 200
        status, body = await curl("-d", '{"data": "x"}', f"{url}/api/topics/fresh")
        assert status == 400 and "data" in json.loads(body)["error"]
    assert got == [{"data": 7}]


async def test_the_latest_message_is_waited_for_a_bounded_time() -> None:
    graph = Graph()
    publisher = graph.create_publisher("/beat", "std_msgs/msg/String")
    config = ServerConfig(tf=False, http_options={"http": HttpApiOptions(latest_wait_s=0.3)})
    async with api_server(graph, config) as (_, url), httpx.AsyncClient() as client:
        status, body = await curl(f"{url}/api/topics/beat")
        assert status == 504 and "0.3 s" in json.loads(body)["error"]

        async def beat() -> None:
            await anyio.sleep(0.1)
            publisher.publish({"data": "now"})

        async with anyio.create_task_group() as tg:
            tg.start_soon(beat)
            answer = await client.get(f"{url}/api/topics/beat")
        assert (answer.status_code, answer.json()) == (200, {"data": "now"})
        assert (await client.get(f"{url}/api/topics/nowhere")).status_code == 404


async def test_an_event_stream_carries_each_message_as_one_data_line() -> None:
    graph = Graph()
    publisher = graph.create_publisher("/robot/odom", "std_msgs/msg/String")
    async with api_server(graph) as (server, url), httpx.AsyncClient() as client:
        events = f"{url}/api/topics/robot/odom/events"
        async with client.stream("GET", events) as response:
            assert response.status_code == 200
            assert response.headers["content-type"] == "text/event-stream"
            lines = response.aiter_lines()
            for n in range(3):
                publisher.publish({"data": f"m{n}"})
            received = []
            while len(received) < 3:
                line = await anext(lines)
                if line:
                    received.append(line)
        assert received == [f'data: {{"data":"m{n}"}}' for n in range(3)]
        with anyio.fail_after(10):  # the client left: its session goes
            while any(each.protocol == "http" for each in server.sessions.values()):
                await anyio.sleep(0.02)


async def test_throttle_rate_and_queue_length_keep_rosbridges_names() -> None:
    graph = Graph()
    publisher = graph.create_publisher("/fast", "std_msgs/msg/String")
    async with api_server(graph) as (_, url), httpx.AsyncClient() as client:
        events = f"{url}/api/topics/fast/events?throttle_rate=60000&queue_length=5"
        async with client.stream("GET", events) as response:
            lines = response.aiter_lines()
            for n in range(10):
                publisher.publish({"data": f"m{n}"})
            first = await anext(lines)
        assert first == 'data: {"data":"m0"}'  # the rest came within the minute
        bad = await client.get(f"{url}/api/topics/fast/events?queue_length=-1")
        assert bad.status_code == 400 and "queue_length" in bad.json()["error"]


async def test_a_service_is_called_with_json_arguments() -> None:
    graph = Graph()

    def set_bool(request: dict[str, object]) -> dict[str, object]:
        return {"success": bool(request["data"]), "message": "set"}

    graph.create_service("/robot/enable", "std_srvs/srv/SetBool", set_bool)
    graph.create_service("/robot/fail", "std_srvs/srv/Trigger", lambda request: 1 / 0)
    async with api_server(graph) as (_, url):
        status, body = await curl("-d", '{"data": true}', f"{url}/api/services/robot/enable")
        assert (status, json.loads(body)) == (200, {"success": True, "message": "set"})
        status, body = await curl("-X", "POST", f"{url}/api/services/robot/nothing")
        assert status == 404
        status, body = await curl("-X", "POST", f"{url}/api/services/robot/fail")
        assert status == 502 and json.loads(body)["error"]
        status, _ = await curl(f"{url}/api/services/robot/enable")  # a GET
        assert status == 405


async def test_an_action_goal_streams_its_feedback_and_result() -> None:
    graph = Graph()

    async def fibonacci(goal: dict[str, object], context: object) -> dict[str, object]:
        sequence = [0, 1]
        for _ in range(int(goal["order"]) - 1):  # type: ignore[call-overload]
            sequence.append(sequence[-1] + sequence[-2])
            context.publish_feedback({"sequence": sequence})  # type: ignore[attr-defined]
        return {"sequence": sequence}

    graph.create_action_server("/fib", "example_interfaces/action/Fibonacci", fibonacci)
    async with api_server(graph) as (_, url):
        status, body = await curl("-N", "-d", '{"order": 3}', f"{url}/api/actions/fib")
    assert status == 200
    events = [block.splitlines() for block in body.strip().split("\n\n")]
    assert [lines[0] for lines in events] == ["event: feedback"] * 2 + ["event: result"]
    result = json.loads(events[-1][1].removeprefix("data: "))
    assert result["result"] is True and result["values"] == {"sequence": [0, 1, 1, 2]}


async def test_access_rules_refuse_and_hide_as_for_every_protocol() -> None:
    graph = Graph()
    graph.create_publisher("/public/a", "std_msgs/msg/String")
    graph.create_publisher("/secret/b", "std_msgs/msg/String")
    access = AccessPolicy(topics=("/public/*",), services=("/rosapi/*",))
    config = ServerConfig(tf=False, session=SessionConfig(access=access))
    async with api_server(graph, config) as (_, url):
        status, body = await curl(f"{url}/api/topics")
        assert "/public/a" in json.loads(body)["topics"]
        assert "/secret/b" not in json.loads(body)["topics"]
        status, body = await curl("-d", '{"data": "x"}', f"{url}/api/topics/secret/b")
        assert status == 403 and "not allowed" in json.loads(body)["error"]
        status, _ = await curl(f"{url}/api/topics/secret/b/events")
        assert status == 403
        status, body = await curl(f"{url}/openapi.json")
        assert "/api/topics/public/a" in json.loads(body)["paths"]
        assert "/api/topics/secret/b" not in json.loads(body)["paths"]


async def test_with_an_authenticator_each_request_needs_a_bearer_token() -> None:
    config = ServerConfig(tf=False, bearer_token=lambda token: token == "good")
    async with api_server(None, config, authenticator=lambda op, peer: False) as (_, url):
        status, _ = await curl(f"{url}/api/topics")
        assert status == 401
        status, _ = await curl("-H", "Authorization: Bearer bad", f"{url}/api/topics")
        assert status == 401
        status, _ = await curl("-H", "Authorization: Bearer good", f"{url}/api/topics")
        assert status == 200


async def test_no_http_api_leaves_the_paths_to_the_websocket() -> None:
    config = ServerConfig(tf=False, http_options={"http": None})
    async with api_server(None, config) as (_, url):
        status, _ = await curl(f"{url}/api/topics")
        assert status != 200
        status, _ = await curl(f"{url}/openapi.json")
        assert status != 200


async def test_an_event_stream_that_is_not_read_is_cut_as_a_slow_consumer() -> None:
    graph = Graph()
    publisher = graph.create_publisher("/big", "std_msgs/msg/String")
    session = SessionConfig(send_buffer_limit=256 * 1024, send_timeout_s=0.2)
    config = ServerConfig(tf=False, session=session)
    async with api_server(graph, config) as (server, url):
        port = int(url.rsplit(":", 1)[1])
        stream = await anyio.connect_tcp("127.0.0.1", port)
        await stream.send(b"GET /api/topics/big/events HTTP/1.1\r\nHost: x\r\n\r\n")
        with anyio.fail_after(30):
            while not any(each.protocol == "http" for each in server.sessions.values()):
                await anyio.sleep(0.01)
            # never read: the socket's buffers fill, then the send buffer, then the cut
            while any(each.protocol == "http" for each in server.sessions.values()):
                publisher.publish({"data": "x" * 65536})
                await anyio.sleep(0.001)
        await stream.aclose()
        # the server goes on for everyone else
        status, _ = await curl(f"{url}/api/topics")
        assert status == 200


async def test_a_body_that_is_not_json_is_a_400() -> None:
    async with api_server(Graph()) as (_, url):
        status, body = await curl("-d", "{not json", f"{url}/api/topics/x?type=std_msgs/String")
    assert status == 400 and json.loads(body)["error"]


@pytest.mark.parametrize(
    "path",
    ["a%20b", "1x", "%00", "a%E2%80%AEb", "n" * 5000, "a%0Ab/events", "%FF%FE"],
)
async def test_a_name_that_is_not_a_ros_name_is_a_400_quoted_escaped_and_cut(path: str) -> None:
    """As a rosbridge op's name (docs/limits.md): refused, never echoed raw or whole."""
    async with api_server(Graph()) as (_, url):
        status, body = await curl(f"{url}/api/topics/{path}")
        error = json.loads(body)["error"]
        assert status == 400, body
        assert error.startswith(("invalid name", "name longer than")), error
        assert error.isascii() and error.isprintable() and len(error) < 300, error
