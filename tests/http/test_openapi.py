"""The OpenAPI document of the live graph is valid OpenAPI 3.1 and names what is there."""

from __future__ import annotations

import json

import httpx
import pytest
from openapi_spec_validator import validate

from rwt_graph.graph import Graph
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig

from .support import api_server, curl

pytestmark = pytest.mark.anyio


async def test_the_document_validates_and_follows_the_graph() -> None:
    graph = Graph()
    graph.create_publisher("/robot/odom", "nav_msgs/msg/Odometry")
    graph.create_service("/robot/enable", "std_srvs/srv/SetBool", lambda request: {})
    graph.create_action_server(
        "/fib", "example_interfaces/action/Fibonacci", lambda goal, context: {}
    )
    async with api_server(graph) as (_, url):
        status, body = await curl(f"{url}/openapi.json")
        assert status == 200
        document = json.loads(body)
        validate(document)  # OpenAPI 3.1, its schemas JSON Schema 2020-12
        paths = document["paths"]
        odom = paths["/api/topics/robot/odom"]
        assert odom["get"]["responses"]["200"]["content"]["application/json"]["schema"] == {
            "$ref": "#/components/schemas/nav_msgs.Odometry"
        }
        assert "text/event-stream" in str(paths["/api/topics/robot/odom/events"])
        assert "/api/services/robot/enable" in paths and "/api/actions/fib" in paths
        schemas = document["components"]["schemas"]
        pose = schemas["nav_msgs.Odometry"]["properties"]["pose"]
        assert pose == {"$ref": "#/components/schemas/geometry_msgs.PoseWithCovariance"}
        assert "geometry_msgs.Point" in schemas

        graph.create_publisher("/late", "std_msgs/msg/String")
        status, body = await curl(f"{url}/openapi.json")
        assert "/api/topics/late" in json.loads(body)["paths"]


async def test_the_document_is_kept_with_an_etag_until_what_it_lists_changes() -> None:
    graph = Graph()
    graph.create_publisher("/robot/odom", "nav_msgs/msg/Odometry")
    async with api_server(graph) as (_, url), httpx.AsyncClient() as client:
        first = await client.get(f"{url}/openapi.json")
        assert first.status_code == 200
        tag = first.headers["etag"]
        assert tag.startswith('"') and tag.endswith('"')
        again = await client.get(f"{url}/openapi.json")
        assert (again.headers["etag"], again.content) == (tag, first.content)

        same = await client.get(f"{url}/openapi.json", headers={"If-None-Match": tag})
        assert same.status_code == 304
        assert (same.headers["etag"], same.content) == (tag, b"")
        weak = await client.get(f"{url}/openapi.json", headers={"If-None-Match": f'"x", W/{tag}'})
        assert weak.status_code == 304
        head = await client.head(f"{url}/openapi.json")
        assert head.status_code == 200 and head.content == b""
        assert int(head.headers["content-length"]) == len(first.content)

        # a new subscriber of a listed topic changes the graph, not the document
        graph.create_subscription("/robot/odom", lambda msg: None, "nav_msgs/msg/Odometry")
        same = await client.get(f"{url}/openapi.json", headers={"If-None-Match": tag})
        assert same.status_code == 304

        graph.create_publisher("/robot/late", "std_msgs/msg/String")
        changed = await client.get(f"{url}/openapi.json", headers={"If-None-Match": tag})
        assert changed.status_code == 200
        assert changed.headers["etag"] != tag
        assert "/api/topics/robot/late" in changed.json()["paths"]
        assert "/api/topics/robot/late" not in first.json()["paths"]


async def test_the_document_offers_only_what_the_split_globs_allow() -> None:
    graph = Graph()
    graph.create_subscription("/cmd/vel", lambda msg: None, "geometry_msgs/msg/Twist")
    graph.create_publisher("/state/odom", "nav_msgs/msg/Odometry", latch=True).publish({})
    graph.create_publisher("/hidden", "std_msgs/msg/String")
    access = AccessPolicy(topics_pub=("/cmd/*",), topics_sub=("/state/*",))
    config = ServerConfig(tf=False, session=SessionConfig(access=access))
    async with api_server(graph, config) as (_, url), httpx.AsyncClient() as client:
        document = (await client.get(f"{url}/openapi.json")).json()
        validate(document)
        paths = document["paths"]
        assert set(paths["/api/topics/cmd/vel"]) == {"post"}  # publish-only: no GET
        assert "/api/topics/cmd/vel/events" not in paths
        assert set(paths["/api/topics/state/odom"]) == {"get"}  # subscribe-only: no POST
        assert "/api/topics/state/odom/events" in paths
        assert not any(path.startswith("/api/topics/hidden") for path in paths)
        # what it offers is served; what it leaves out is what the server refuses
        assert (await client.post(f"{url}/api/topics/cmd/vel", json={})).status_code == 200
        assert (await client.get(f"{url}/api/topics/state/odom")).status_code == 200
        assert (await client.get(f"{url}/api/topics/cmd/vel")).status_code == 403
        assert (await client.post(f"{url}/api/topics/state/odom", json={})).status_code == 403


async def test_a_topic_named_events_leaves_its_path_to_the_stream_before_it() -> None:
    """``/api/topics/a/events`` is ``/a``'s stream (routes.py): the document says so once."""
    graph = Graph()
    graph.create_publisher("/a", "std_msgs/msg/String")
    graph.create_publisher("/a/events", "std_msgs/msg/Int32")
    async with api_server(graph) as (_, url), httpx.AsyncClient() as client:
        answer = await client.get(f"{url}/openapi.json")
        assert answer.content.count(b'"/api/topics/a/events":') == 1
        document = answer.json()
        validate(document)
        paths = document["paths"]
        assert set(paths["/api/topics/a"]) == {"get", "post"}
        stream = paths["/api/topics/a/events"]["get"]["responses"]["200"]["content"]
        assert stream["text/event-stream"]["x-rwt-data"] == {
            "$ref": "#/components/schemas/std_msgs.String"
        }
        assert "/api/topics/a/events/events" in paths
