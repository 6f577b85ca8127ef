"""A Foxglove client sees the robot, not rwt's own helpers (docs/foxglove.md, "What a client sees").

rwt's plumbing, the entities of the server's own nodes (rosapi's services,
``/client_count`` and ``/connected_clients``, the TF republisher's action,
service and topics), and so those nodes in the connection graph, show only with
``show_plumbing`` (``rwt serve --foxglove-show-plumbing``); other connections'
entities and nodes always do (D47; with the real clients: test_robot_graph.py).
rosbridge clients keep seeing all of it through rosapi, as rosbridge_suite shows it.
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt_graph.graph import Graph
from rwt_graph.nodes import SERVER_NODES
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.conftest import Peer
from tests.foxglove.sansio import Client
from tests.foxglove.test_cli import serving

STRING = "std_msgs/msg/String"
TRIGGER = "std_srvs/srv/Trigger"
PLUMBING_TOPICS = {"/client_count", "/connected_clients"}
PLUMBING_SERVICES = {"/rosapi/topics", "/rosapi/nodes", "/republish_tfs"}


def served_robot() -> Graph:
    """A robot's topic and service on a graph with every helper a server installs."""
    graph = Graph()
    RosbridgeServer(graph, ServerConfig(port=0))  # rosapi, the client counts, the TF republisher
    graph.create_publisher("/odom", STRING, node="/robot")
    graph.create_subscription("/tf", lambda msg: None, node="/robot")
    graph.create_service("/reset", TRIGGER, lambda request: {}, node="/robot")
    return graph


def channels(client: Client) -> set[str]:
    return {str(c["topic"]) for op in client.take_ops("advertise") for c in op["channels"]}  # type: ignore[attr-defined]


def services(client: Client) -> set[str]:
    ops = client.take_ops("advertiseServices")
    return {str(s["name"]) for op in ops for s in op["services"]}  # type: ignore[attr-defined]


def graph_ids(client: Client) -> dict[str, set[str]]:
    """Every name of the client's whole connection graph -> the node ids listed for it."""
    client.send({"op": "subscribeConnectionGraph"})
    (update,) = client.take_ops("connectionGraphUpdate")
    ids: dict[str, set[str]] = {}
    for key, field in (
        ("publishedTopics", "publisherIds"),
        ("subscribedTopics", "subscriberIds"),
        ("advertisedServices", "providerIds"),
    ):
        for entry in update[key]:  # type: ignore[attr-defined]
            ids.setdefault(entry["name"], set()).update(entry[field])
    return ids


def test_by_default_a_client_sees_the_robots_topics_services_and_nodes_only() -> None:
    graph = served_robot()
    client = Client(graph)
    assert channels(client) == {"/odom"}
    assert services(client) == {"/reset"}
    # the TF republisher's subscription to /tf is its own: /tf shows the robot's node only
    assert graph_ids(client) == {"/odom": {"/robot"}, "/tf": {"/robot"}, "/reset": {"/robot"}}


def test_show_plumbing_shows_rwts_helpers_and_their_nodes() -> None:
    graph = served_robot()
    client = Client(graph, show_plumbing=True)
    assert channels(client) >= {"/odom"} | PLUMBING_TOPICS
    assert services(client) >= {"/reset"} | PLUMBING_SERVICES
    ids = graph_ids(client)
    assert ids["/tf"] == {"/robot", "/tf2_web_republisher"}
    assert set().union(*ids.values()) == {"/robot"} | SERVER_NODES


def test_a_helper_added_later_stays_out_of_the_clients_view() -> None:
    graph = Graph()
    client = Client(graph)
    client.send({"op": "subscribeConnectionGraph"})
    client.take_ops("connectionGraphUpdate")
    RosbridgeServer(graph, ServerConfig(port=0))
    graph.create_publisher("/odom", STRING, node="/robot")
    client.sync()
    assert channels(client) == {"/odom"}
    assert services(client) == set()
    (update,) = client.take_ops("connectionGraphUpdate")
    assert update["publishedTopics"] == [{"name": "/odom", "publisherIds": ["/robot"]}]
    assert update["subscribedTopics"] == update["advertisedServices"] == []


def test_rosbridge_clients_still_see_the_helpers_through_rosapi() -> None:
    graph = served_robot()
    Client(graph)  # a Foxglove client's view does not change rosapi's
    peer = Peer(graph, "rb")
    peer.send(op="call_service", service="/rosapi/topics", id="t")
    peer.send(op="call_service", service="/rosapi/services", id="s")
    answers = {str(m["id"]): m["values"] for m in peer.received() if m["op"] == "service_response"}
    assert set(answers["t"]["topics"]) >= {"/odom"} | PLUMBING_TOPICS  # type: ignore[index]
    assert set(answers["s"]["services"]) >= {"/reset"} | PLUMBING_SERVICES  # type: ignore[index]


@pytest.mark.parametrize("show", [False, True])
def test_other_connections_nodes_show_with_or_without_show_plumbing(show: bool) -> None:
    graph = served_robot()
    graph.nodes.attach("foxglove:test#1")  # the server gives each connection its node
    own = graph.nodes.name_of("foxglove:test#1")
    client = Client(graph, show_plumbing=show)
    channels(client)
    peer = Peer(graph, "rb")
    peer.send(op="advertise", topic="/from_web", type=STRING)
    peer.send(op="subscribe", topic="/odom", type=STRING)
    peer.send(op="advertise_service", service="/robot_reset", type=TRIGGER)
    web = graph.nodes.name_of("rb")
    client.sync()
    # what a web page or a robot's rosbridge program holds is the robot's all the same
    assert "/from_web" in channels(client)
    odom = next(c for c in client.session._channels.values() if c.topic == "/odom")
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": odom.id}]})
    ids = graph_ids(client)
    assert ids["/odom"] == {"/robot", web, own}
    assert ids["/from_web"] == ids["/robot_reset"] == {web}
    assert ("/rosapi/topics" in ids) is show


# ---- through a real server ------------------------------------------------------------


@asynccontextmanager
async def foxglove(url: str) -> AsyncIterator[ClientConnection]:
    async with connect(url, subprotocols=["foxglove.sdk.v1"]) as ws:  # type: ignore[list-item]
        yield ws


async def first_op(ws: ClientConnection, op: str) -> dict[str, object]:
    while True:
        frame = await ws.recv()
        if isinstance(frame, str) and (message := json.loads(frame))["op"] == op:
            return message  # type: ignore[no-any-return]


@pytest.mark.anyio
@pytest.mark.parametrize("flags", [(), ("--foxglove-show-plumbing",)])
async def test_rwt_serve_shows_its_helpers_only_when_asked(flags: tuple[str, ...]) -> None:
    async with serving("--tf", *flags) as (url,), connect(url) as web:
        # a web page gives the robot a topic and a service over rosbridge
        await web.send(json.dumps({"op": "advertise", "topic": "/odom", "type": STRING}))
        offer = {"op": "advertise_service", "service": "/reset", "type": TRIGGER}
        await web.send(json.dumps(offer))
        await web.send(json.dumps({"op": "set_level", "level": "info", "id": "done"}))
        while json.loads(await web.recv()).get("id") != "done":
            pass
        with anyio.fail_after(30):
            async with foxglove(url) as ws:
                # the whole graph comes in the first frames of each kind
                advertised = await first_op(ws, "advertise")
                offered = await first_op(ws, "advertiseServices")
                await ws.send(json.dumps({"op": "subscribeConnectionGraph"}))
                update = await first_op(ws, "connectionGraphUpdate")
    topics = {str(c["topic"]) for c in advertised["channels"]}  # type: ignore[attr-defined]
    names = {str(s["name"]) for s in offered["services"]}  # type: ignore[attr-defined]
    nodes = {
        node
        for key in ("publishedTopics", "subscribedTopics", "advertisedServices")
        for entry in update[key]  # type: ignore[attr-defined]
        for ids in (v for k, v in entry.items() if k.endswith("Ids"))
        for node in ids
    }
    if flags:
        assert topics >= {"/odom"} | PLUMBING_TOPICS and names >= {"/reset"} | PLUMBING_SERVICES
        assert nodes >= SERVER_NODES and any(n.startswith("/rwt_client_") for n in nodes)
    else:
        assert topics == {"/odom"} and names == {"/reset"}
        [web] = nodes  # the web page's connection, which holds /odom and /reset (D47)
        assert web.startswith("/rwt_client_")
