"""Protocol 2.1.0's ``qos`` on the HTTP API (query parameters named as in the op), with httpx.

An event stream asking transient local gets what the topic keeps first (D63); a bad
policy is a 400 naming it (D62); a publish's ``qos`` fixes the topic's offer while
its request lasts.
"""

from __future__ import annotations

import httpx
import pytest

import rwt
from rwt.types import Durability
from rwt_graph.graph import Graph

from .support import api_server

pytestmark = pytest.mark.anyio

STRING = "std_msgs/msg/String"


async def test_an_event_stream_asking_transient_local_gets_the_kept_messages_first() -> None:
    graph = Graph()
    kept = rwt.QosProfile(durability=Durability.TRANSIENT_LOCAL, depth=3)
    publisher = graph.create_publisher("/map", STRING, qos=kept)
    for n in range(5):
        publisher.publish({"data": f"m{n}"})
    async with api_server(graph) as (_, url), httpx.AsyncClient() as client:
        events = f"{url}/api/topics/map/events?durability=transient_local&depth=2"
        async with client.stream("GET", events) as response:
            assert response.status_code == 200
            lines = response.aiter_lines()
            received = []
            while len(received) < 2:
                line = await anext(lines)
                if line:
                    received.append(line)
        assert received == ['data: {"data":"m3"}', 'data: {"data":"m4"}']


async def test_a_bad_policy_is_a_400_naming_it() -> None:
    graph = Graph()
    graph.create_publisher("/t", STRING)
    async with api_server(graph) as (_, url), httpx.AsyncClient() as client:
        bad = await client.get(f"{url}/api/topics/t/events?durability=forever")
        assert bad.status_code == 400 and bad.json()["error"].startswith("durability: ")
        bad = await client.post(f"{url}/api/topics/t?depth=-1", json={"data": "x"})
        assert bad.status_code == 400 and bad.json()["error"].startswith("depth: ")
        bad = await client.get(f"{url}/api/topics/t/events?lifespan=soon")
        assert bad.status_code == 400 and bad.json()["error"].startswith("lifespan: ")


async def test_the_openapi_document_names_the_qos_parameters() -> None:
    graph = Graph()
    graph.create_publisher("/t", STRING)
    async with api_server(graph) as (_, url), httpx.AsyncClient() as client:
        paths = (await client.get(f"{url}/openapi.json")).json()["paths"]
    policies = ["history", "depth", "reliability", "durability", "deadline", "lifespan"]
    for operation in (paths["/api/topics/t/events"]["get"], paths["/api/topics/t"]["post"]):
        names = [parameter["name"] for parameter in operation["parameters"]]
        assert names[-6:] == policies
