"""Protocol 2.1.0's ``qos`` on the HTTP API (query parameters named as in the op), with httpx.

An event stream asking transient local gets what the topic keeps first (D63); a bad
policy is a 400 naming it (D62); a publish's ``qos`` outlives its request, so what a
transient-local publish keeps reaches a later roslibpy subscriber (``standing``); a
stream is never sent a message past its lifespan
(its topic's, its own ``lifespan``, or the server's ``--qos-lifespan``): the graph's
clock is moved back while a message is published, so it has waited that long when
its turn comes, without the test waiting.
"""

from __future__ import annotations

import json
import time

import anyio
import httpx
import pytest

import rwt
from rwt.types import Durability
from rwt_graph.graph import Graph
from rwt_http.standing import MAX_STANDING
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import ServerConfig
from tests.support.realclients import run_python

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


class Shifted:
    """The real clocks plus ``offset`` seconds (an ``rwt.Clock``), as the graph's clock."""

    def __init__(self) -> None:
        self.offset = 0.0

    def monotonic(self) -> float:
        return time.monotonic() + self.offset

    def wall(self) -> float:
        return time.time() + self.offset


async def _streamed(graph: Graph, clock: Shifted, query: str = "", **server: object) -> list[str]:
    """The data lines an event stream of ``/scan`` gets of "old" and "fresh".

    "old" is published 30 s ago by the graph's clock (it has waited that long when its
    turn comes, as behind a stalled link), "fresh" now, once the stream subscribed.
    """
    publisher = graph.create_publisher("/scan", STRING)
    async with (
        api_server(graph, **server) as (_, url),
        httpx.AsyncClient() as client,
        client.stream("GET", f"{url}/api/topics/scan/events{query}") as response,
    ):
        assert response.status_code == 200
        with anyio.fail_after(20):
            while not graph.topics["/scan"].subscribers:
                await anyio.sleep(0.01)
            clock.offset = -30.0
            publisher.publish({"data": "old"})
            clock.offset = 0.0
            publisher.publish({"data": "fresh"})
            received = []
            async for line in response.aiter_lines():
                if line.startswith("data: "):
                    received.append(line)
                if line == 'data: {"data":"fresh"}':
                    return received
    raise AssertionError("the stream ended")


async def test_an_event_stream_gets_no_message_past_its_topics_lifespan() -> None:
    clock = Shifted()
    graph = Graph(clock=clock)
    graph.create_publisher("/scan", STRING, qos=rwt.QosProfile(lifespan_s=15.0))
    assert await _streamed(graph, clock) == ['data: {"data":"fresh"}']


async def test_an_event_streams_own_lifespan_and_the_servers_bind_it() -> None:
    clock = Shifted()
    assert await _streamed(Graph(clock=clock), clock, "?lifespan=15") == ['data: {"data":"fresh"}']
    clock = Shifted()
    config = ServerConfig(tf=False, session=SessionConfig(qos_lifespan_s=15.0))
    assert await _streamed(Graph(clock=clock), clock, config=config) == ['data: {"data":"fresh"}']
    clock = Shifted()  # the control: no lifespan anywhere, both arrive
    assert await _streamed(Graph(clock=clock), clock) == [
        'data: {"data":"old"}',
        'data: {"data":"fresh"}',
    ]


LATE_ROSLIBPY = """
import json, threading
import roslibpy

ros = roslibpy.Ros("127.0.0.1", {port})
ros.run(timeout=20)
got, done = [], threading.Event()

def take(msg):
    got.append(msg["data"])
    if len(got) == 5:
        done.set()

roslibpy.Topic(ros, "/map", "std_msgs/String").subscribe(take)
done.wait(20)
print(json.dumps(got), flush=True)
ros.terminate()
"""


async def test_a_transient_local_publish_stays_for_a_late_roslibpy_subscriber() -> None:
    # each POST is a request that ends; the topic keeps its last five all the same
    async with api_server(Graph()) as (server, url), httpx.AsyncClient() as client:
        for n in range(7):
            posted = await client.post(
                f"{url}/api/topics/map?type=std_msgs/String&durability=transient_local&depth=5",
                json={"data": f"m{n}"},
            )
            assert posted.status_code == 200 and "warnings" not in posted.json()
        late = await run_python(LATE_ROSLIBPY.format(port=server.urls["websocket"].rsplit(":")[-1]))
        assert json.loads(late) == ["m2", "m3", "m4", "m5", "m6"]
        # a publish with another qos shares the topic's offer, and is told so
        other = await client.post(f"{url}/api/topics/map?durability=volatile", json={"data": "v"})
        assert other.json()["warnings"] == [
            "/map keeps the QoS of its first registration (keep_last 5, reliable,"
            " transient_local); this one's (keep_last 10, reliable, volatile) is not used"
        ]


async def test_the_api_holds_at_most_max_standing_topics() -> None:
    graph = Graph()
    async with api_server(graph) as (_, url), httpx.AsyncClient() as client:
        for n in range(MAX_STANDING + 1):
            query = "type=std_msgs/String&durability=transient_local&depth=1"
            posted = await client.post(f"{url}/api/topics/t{n}?{query}", json={"data": "x"})
            assert posted.status_code == 200
        # the first topic published went: its offer, and what it kept, with it
        assert graph.port.offered_qos("/t0") is None
        assert graph.port.offered_qos(f"/t{MAX_STANDING}") is not None
