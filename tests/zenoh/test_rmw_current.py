"""A peer writing tokens as a current rmw_zenoh_cpp does (docs/zenoh.md, "Which rmw_zenoh").

Since March 2025 an empty durability field in a token is volatile, and a transient
local publisher writes ``1`` there. The bare session below plays such a node: its
tokens carry that QoS text (one of them spelling a default out, as a peer may), and
each sample's attachment carries the GID that node derives from the token it
declared. Latching must come out right both ways, and with ``--zenoh-rmw-compat
pre-2025`` the same link speaks the older form.
"""

from __future__ import annotations

import contextlib
import time
from typing import TYPE_CHECKING, Any

import anyio
import pytest

from rwt_graph.graph import Graph
from rwt_zenoh.config import ZenohOptions
from rwt_zenoh.link import open_zenoh_link
from rwt_zenoh.payload import decode_sample, encode_sample, type_hash
from rwt_zenoh.wire import (
    Attachment,
    Durability,
    Entity,
    EntityKind,
    RmwCompat,
    dds_type_name,
    gid_of,
    pack_attachment,
)

from .support import checked, endpoint
from .test_ros2_peers import bare_session, until

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

pytestmark = pytest.mark.anyio

ZID = "77aa"
STRING = "std_msgs/msg/String"
# the QoS text of each token, as rmw_zenoh_cpp writes it since the change
VOLATILE_TEXT = "::,10:,:,:,,"  # rclcpp's default profile: reliable, volatile, keep last 10
LATCHED_TEXT = "1:1:1,1:,:,:,,"  # transient local, keep last 1; reliability and history spelled out


def options(listen: str, compat: RmwCompat = RmwCompat.CURRENT) -> ZenohOptions:
    return checked(ZenohOptions(listen=(listen,), connect=(), domain_id=0, rmw_compat=compat))


class CurrentNode:
    """A node of a current rmw_zenoh_cpp: its tokens, and samples with its GIDs."""

    def __init__(self, session: Any, graph: Graph) -> None:
        self.session = session
        string_hash = type_hash(graph.registry, STRING)
        self.prefix = f"@ros2_lv/0/{ZID}/1"
        self.string_key = f"{dds_type_name(STRING)}/{string_hash}"
        self.handles = [session.liveliness().declare_token(f"{self.prefix}/1/NN/%/%/talker")]
        self.registry = graph.registry

    def publisher(self, eid: int, topic: str, qos_text: str) -> tuple[Any, bytes]:
        """Declare a publisher's token; its Zenoh publisher and the GID it attaches."""
        token = f"{self.prefix}/{eid}/MP/%/%/talker/%{topic[1:]}/{self.string_key}/{qos_text}"
        self.handles.append(self.session.liveliness().declare_token(token))
        key = f"0/{topic[1:]}/{self.string_key}"
        publisher = self.session.declare_publisher(key)
        self.handles.append(publisher)
        return publisher, gid_of(token)

    def put(self, publisher: Any, gid: bytes, sequence: int, text: str) -> None:
        payload = encode_sample(self.registry, STRING, {"data": text})
        publisher.put(payload, attachment=pack_attachment(sequence, time.time_ns(), gid))

    def close(self) -> None:
        for handle in reversed(self.handles):
            handle.undeclare()


@contextlib.asynccontextmanager
async def linked_graph(
    compat: RmwCompat = RmwCompat.CURRENT,
) -> AsyncIterator[tuple[Graph, Any, CurrentNode]]:
    graph = Graph()
    listen = endpoint()
    async with open_zenoh_link(graph, options(listen, compat)):
        with bare_session(connect=listen) as session:
            node = CurrentNode(session, graph)
            try:
                yield graph, session, node
            finally:
                node.close()


async def published_and_late(graph: Graph, node: CurrentNode, topic: str, qos: str) -> list[str]:
    """An early subscriber takes one sample; what a late subscriber then gets."""
    early: list[str] = []
    graph.create_subscription(topic, lambda msg: early.append(msg["data"]), STRING)
    publisher, gid = node.publisher(2 if topic == "/chatter" else 3, topic, qos)
    await until(lambda: topic in dict(graph.topic_names_and_types()), "the publisher mirrored")
    # the link's subscription may be declared a moment after the token: resend until heard
    for sequence in range(1, 200):
        node.put(publisher, gid, sequence, f"hello {sequence}")
        with anyio.move_on_after(0.1):
            while not early:
                await anyio.sleep(0.01)
        if early:
            break
    assert early, f"no sample of {topic} reached the graph"
    late: list[str] = []
    graph.create_subscription(topic, lambda msg: late.append(msg["data"]), STRING)
    await anyio.sleep(0.5)  # a latched message is delivered at once; give a stale one time
    return late


async def test_a_current_volatile_publisher_is_not_replayed_to_a_late_subscriber() -> None:
    async with linked_graph() as (graph, _, node):
        late = await published_and_late(graph, node, "/chatter", VOLATILE_TEXT)
        assert late == []


async def test_a_current_transient_local_publisher_is_replayed_to_a_late_subscriber() -> None:
    # also pins the GID: the token spells defaults out, so only the GID of the token
    # as declared matches the attachment, and only a matched sample is latched
    async with linked_graph() as (graph, _, node):
        late = await published_and_late(graph, node, "/map_like", LATCHED_TEXT)
        assert len(late) == 1
        assert late[0].startswith("hello ")


async def token_texts(session: Any, *parts: str) -> list[str]:
    """The tokens on the network holding each of ``parts``, once all are there."""

    def get() -> set[str]:
        replies = session.liveliness().get("@ros2_lv/**", timeout=2.0)
        return {str(reply.ok.key_expr) for reply in replies if reply.ok}

    with anyio.fail_after(10):
        while True:
            texts = await anyio.to_thread.run_sync(get)
            found = [next((t for t in texts if part in t), None) for part in parts]
            if all(found):
                return [t for t in found if t is not None]
            await anyio.sleep(0.1)


@pytest.mark.parametrize(
    ("compat", "latched_text", "volatile_text"),
    [
        (RmwCompat.CURRENT, ":1:,1:,:,:,,", "::,10:,:,:,,"),
        (RmwCompat.PRE_2025, "::,1:,:,:,,", ":2:,10:,:,:,,"),
    ],
)
async def test_rwt_writes_durability_as_the_chosen_rmw_zenoh_reads_it(
    compat: RmwCompat, latched_text: str, volatile_text: str
) -> None:
    async with linked_graph(compat) as (graph, session, _):
        graph.create_publisher("/latched", STRING, latch=True).publish({"data": "kept"})
        graph.create_publisher("/plain", STRING).publish({"data": "gone"})
        latched, plain = await token_texts(session, "%latched/", "%plain/")
        assert latched.endswith("/" + latched_text)
        assert plain.endswith("/" + volatile_text)
        # and a peer of the same release reads them back as meant
        assert Entity.parse(latched, compat).topic.qos.durability is Durability.TRANSIENT_LOCAL  # type: ignore[union-attr]
        assert Entity.parse(plain, compat).topic.qos.durability is Durability.VOLATILE  # type: ignore[union-attr]
        assert Entity.parse(latched, compat).kind is EntityKind.PUBLISHER


async def test_a_plain_zenoh_sample_and_query_without_attachment_are_taken() -> None:
    # docs/zenoh.md: unlike a ROS 2 node, rwt takes what plain Zenoh programs send
    async with linked_graph() as (graph, session, node):
        heard: list[str] = []
        graph.create_subscription("/plain", lambda msg: heard.append(msg["data"]), STRING)
        graph.create_service(
            "/add", "example_interfaces/srv/AddTwoInts", lambda r: {"sum": r["a"] + r["b"]}
        )
        key = f"0/plain/{node.string_key}"
        payload = encode_sample(graph.registry, STRING, {"data": "no attachment"})
        with anyio.fail_after(10):
            while not heard:
                session.put(key, payload)  # no attachment
                await anyio.sleep(0.1)
        assert heard[0] == "no attachment"
        add = "0/add/example_interfaces::srv::dds_::AddTwoInts_/*"
        request = encode_sample(
            graph.registry, "example_interfaces/srv/AddTwoInts_Request", {"a": 2, "b": 3}
        )

        def call() -> list[Any]:
            return [r for r in session.get(add, payload=request, timeout=2.0) if r.ok]

        with anyio.fail_after(10):
            replies: list[Any] = []
            while not replies:
                replies = await anyio.to_thread.run_sync(call)
        reply = replies[0].ok
        response = decode_sample(
            graph.registry,
            "example_interfaces/srv/AddTwoInts_Response",
            reply.payload.to_bytes(),
        )
        assert response["sum"] == 5
        back = Attachment.decode(reply.attachment.to_bytes())
        assert (back.sequence_number, back.source_gid) == (0, bytes(16))


async def client_tokens(session: Any) -> list[str]:
    def get() -> list[str]:
        replies = session.liveliness().get("@ros2_lv/**", timeout=2.0)
        return [str(r.ok.key_expr) for r in replies if r.ok and "/SC/" in str(r.ok.key_expr)]

    return await anyio.to_thread.run_sync(get)


async def test_a_callers_client_entity_is_withdrawn_when_its_node_leaves() -> None:
    # rmw_zenoh has one client entity per client; rwt declares one per caller's node
    # and service at its first call, and withdraws it with the node (docs/zenoh.md)
    server, caller = Graph(), Graph()
    server.create_service(
        "/add", "example_interfaces/srv/AddTwoInts", lambda r: {"sum": r["a"] + r["b"]}
    )
    listen = endpoint()
    connect = checked(ZenohOptions(listen=(), connect=(listen,), domain_id=0))
    async with open_zenoh_link(server, options(listen)), open_zenoh_link(caller, connect):
        with bare_session(connect=listen) as session:
            await until(lambda: "/add" in caller.services.entries, "the remote service")
            answers: list[object] = []
            participant = caller.port.local_client()
            caller.nodes.bind(participant, "/web_page")
            caller.port.call_service(
                participant,
                "/add",
                {"a": 1, "b": 2},
                lambda ok, value: answers.append(value),
            )
            await until(lambda: bool(answers), "the answer")
            assert answers == [{"sum": 3}]
            with anyio.fail_after(10):
                while not (tokens := await client_tokens(session)):
                    await anyio.sleep(0.1)
            assert len(tokens) == 1
            assert "/web_page/%add/example_interfaces::srv::dds_::AddTwoInts_/" in tokens[0]
            caller.nodes.forget(participant)  # the caller leaves
            with anyio.fail_after(10):
                while await client_tokens(session):
                    await anyio.sleep(0.1)
