"""The OpenAPI document of the live graph is valid OpenAPI 3.1 and names what is there."""

from __future__ import annotations

import json

import pytest
from openapi_spec_validator import validate

from rwt_graph.graph import Graph

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
