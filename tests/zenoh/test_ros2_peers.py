"""ROS 2 peers on the same Zenoh network as a linked graph.

No ROS 2 runs on this machine, so two stand-ins check that a ROS 2 node on
rmw_zenoh is just another peer:

- a bare Zenoh session doing exactly what rmw_zenoh's client and service do
  (rmw_client_data.cpp ``send_request``, rmw_service_data.cpp ``take_request``
  and ``send_response``, ros2/rmw_zenoh rolling): a query that targets complete
  queryables only, with the client's sequence number and GID attached; a reply
  that must carry them back, since a ROS 2 client pairs a response with its call
  by that sequence number; the same session plays a ROS 2 action client (the
  tokens it waits for, the ``status`` topic) and a ROS 2 action server;
- zenoh-ros2-sdk (ROBOTIS, on PyPI), an rmw_zenoh-compatible Python library
  written independently of rwt, as a whole peer: topics both ways, a latched
  topic for its late subscriber, services both ways, and each side's graph
  listing the other's nodes.
"""

from __future__ import annotations

import contextlib
import json
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import anyio
import pytest
import zenoh.ext

import zenoh
from rwt_graph.actions import GoalCanceledError
from rwt_graph.async_calls import call_service, send_action_goal
from rwt_graph.graph import Graph
from rwt_graph.rosapi.listing import action_servers, publishers, services, subscribers
from rwt_graph.rosapi.visibility import EVERYTHING
from rwt_graph.types.registry import TypeRegistry
from rwt_protocol.ports import GoalStatus
from rwt_transports.server import running_handlers
from rwt_zenoh.actions import ActionWire
from rwt_zenoh.config import make_config
from rwt_zenoh.link import open_zenoh_link
from rwt_zenoh.payload import decode_sample, encode_sample, named_service_hash
from rwt_zenoh.wire import Attachment, Durability, Entity, EntityKind, Topic, pack_attachment

from .processes import Process, started
from .support import WAIT_S, endpoint, peer, until

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

    from rwt_graph.actions import GoalContext

pytestmark = pytest.mark.anyio

ADD_TYPE = "example_interfaces/srv/AddTwoInts"
# the keys a ROS 2 node derives (hashes pinned in test_payload.py from rosidl's output)
ADD_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
SEND_GOAL_HASH = "RIHS01_d1a57fb2a4afe8c21e34fb10db206f16ce6729b28531141472df92277c55b557"
ADD_KEY = f"0/add/example_interfaces::srv::dds_::AddTwoInts_/{ADD_HASH}"
SEND_GOAL_TYPE = "example_interfaces::action::dds_::Fibonacci_SendGoal_"
SEND_GOAL_KEY = f"0/fib/_action/send_goal/{SEND_GOAL_TYPE}/{SEND_GOAL_HASH}"
FEEDBACK_HASH = "RIHS01_c1de71afd52e49a89c53d8262366884185bc0a02f78ce051c4e46b0a7fe59bb2"
FEEDBACK_KEY = (
    "0/fib/_action/feedback/example_interfaces::action::dds_::Fibonacci_FeedbackMessage_/"
    + FEEDBACK_HASH
)
STATUS_HASH = "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e"
STATUS_KEY = f"0/fib/_action/status/action_msgs::msg::dds_::GoalStatusArray_/{STATUS_HASH}"
CANCEL_HASH = "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a"
CANCEL_KEY = f"0/fib/_action/cancel_goal/action_msgs::srv::dds_::CancelGoal_/{CANCEL_HASH}"
CLIENT_GID = bytes(range(100, 116))
GOAL_STATUS_ARRAY = "action_msgs/msg/GoalStatusArray"
CANCEL_GOAL = "action_msgs/srv/CancelGoal"
FIBONACCI = "example_interfaces/action/Fibonacci"
REGISTRY = TypeRegistry()


@contextlib.contextmanager
def bare_session(connect: str | None = None, listen: str | None = None) -> Any:
    """A plain Zenoh session on loopback, multicast off."""
    session = zenoh.open(make_config(peer(listen=listen, connect=(connect,) if connect else ())))
    try:
        yield session
    finally:
        session.close()


def ros2_call(session: Any, key: str, payload: bytes, sequence: int) -> list[Any]:
    """One request as rmw_zenoh's client sends it; the replies (blocking, on a thread)."""
    replies = session.get(
        key,
        payload=payload,
        attachment=pack_attachment(sequence, time.time_ns(), CLIENT_GID),
        target=zenoh.QueryTarget.ALL_COMPLETE,
        consolidation=zenoh.ConsolidationMode.NONE,
        timeout=3.0,
    )
    return list(replies)


async def ros2_call_until_answered(session: Any, key: str, payload: bytes) -> tuple[Any, int]:
    """Call until a reply comes (the service's route takes a moment); it and its sequence."""
    for sequence in range(41, 41 + int(WAIT_S / 0.2)):
        replies = await anyio.to_thread.run_sync(ros2_call, session, key, payload, sequence)
        if replies:
            assert len(replies) == 1, replies
            return replies[0], sequence
        await anyio.sleep(0.2)
    raise AssertionError(f"no reply to a ROS 2 client's query on {key}")


def adder_graph() -> Graph:
    """A graph whose node ``/adder`` serves ``/add`` (``AddTwoInts``)."""
    graph = Graph()
    graph.create_service("/add", ADD_TYPE, lambda req: {"sum": req["a"] + req["b"]}, node="/adder")
    return graph


@contextlib.asynccontextmanager
async def serving_fib(graph: Graph, handler: Any, node: str, listen: str) -> AsyncIterator[None]:
    """``/fib`` served in ``graph`` by ``handler``, the graph linked, listening on ``listen``."""
    async with running_handlers(graph) as tg, open_zenoh_link(graph, peer(listen=listen)):
        graph.create_action_server("/fib", FIBONACCI, handler, node=node)
        yield
        tg.cancel_scope.cancel()


async def test_a_ros2_client_calls_a_service_and_gets_its_sequence_number_back() -> None:
    first = endpoint()
    graph = adder_graph()
    registry = REGISTRY
    request = encode_sample(registry, f"{ADD_TYPE}_Request", {"a": 2, "b": 40})
    async with open_zenoh_link(graph, peer(listen=first)):
        with bare_session(first) as session:
            reply, sequence = await ros2_call_until_answered(session, ADD_KEY, request)
    assert reply.ok is not None, reply.err.payload.to_string()
    response = decode_sample(registry, f"{ADD_TYPE}_Response", reply.ok.payload.to_bytes())
    assert response == {"sum": 42}
    # what rmw_zenoh's take_response reads to pair the response with the call
    attachment = Attachment.decode(reply.ok.attachment.to_bytes())
    assert attachment.sequence_number == sequence
    assert attachment.source_gid == CLIENT_GID
    assert abs(attachment.source_timestamp - time.time_ns()) < 60e9


async def test_a_ros2_action_client_sends_a_goal_and_takes_its_feedback() -> None:
    first = endpoint()
    graph = Graph()

    async def fibonacci(goal: dict[str, Any], context: GoalContext) -> dict[str, Any]:
        sequence = [0, 1]
        for _ in range(goal["order"] - 1):
            await anyio.sleep(0.05)
            sequence.append(sequence[-1] + sequence[-2])
            context.publish_feedback({"sequence": list(sequence)})
        return {"sequence": sequence}

    wire = ActionWire(graph.registry, graph.registry.action(FIBONACCI))
    samples: list[Any] = []
    async with serving_fib(graph, fibonacci, "/f", first):
        with bare_session(first) as session:
            feedback = session.declare_subscriber(FEEDBACK_KEY, samples.append)
            request = wire.send_goal(bytes(range(16)), {"order": 4})
            reply, sequence = await ros2_call_until_answered(session, SEND_GOAL_KEY, request)
            await until(lambda: len(samples) >= 3, "three feedback samples")
            feedback.undeclare()
    assert reply.ok is not None, reply.err.payload.to_string()
    assert wire.read_accepted(reply.ok.payload.to_bytes()) is True
    attachment = Attachment.decode(reply.ok.attachment.to_bytes())
    assert (attachment.sequence_number, attachment.source_gid) == (sequence, CLIENT_GID)
    # a ROS 2 subscription drops a sample without rmw_zenoh's attachment
    # (rmw_subscription_data.cpp, "Unable to obtain attachment")
    attached = [Attachment.decode(sample.attachment.to_bytes()) for sample in samples]
    assert [a.sequence_number for a in attached] == [1, 2, 3]
    assert len({a.source_gid for a in attached}) == 1
    assert attached[0].source_gid != bytes(16)
    read = [wire.read_feedback(sample.payload.to_bytes()) for sample in samples]
    assert read == [
        (bytes(range(16)), {"sequence": [0, 1, 1]}),
        (bytes(range(16)), {"sequence": [0, 1, 1, 2]}),
        (bytes(range(16)), {"sequence": [0, 1, 1, 2, 3]}),
    ]


async def tokens_of(session: Any) -> list[Entity]:
    """Every ROS 2 entity on the network, from its liveliness token."""

    def get() -> list[Entity]:
        replies = session.liveliness().get("@ros2_lv/0/**", timeout=2.0)
        return [Entity.parse(str(reply.ok.key_expr)) for reply in replies if reply.ok]

    return await anyio.to_thread.run_sync(get)


def status_codes(samples: list[Any], goal_id: bytes) -> list[int]:
    """The successive states of one goal in ``GoalStatusArray`` samples, repeats removed."""
    codes: list[int] = []
    for sample in samples:
        array = decode_sample(REGISTRY, GOAL_STATUS_ARRAY, sample.payload.to_bytes())
        for status in cast("list[Any]", array["status_list"]):
            if status["goal_info"]["goal_id"]["uuid"] == goal_id and (
                not codes or codes[-1] != status["status"]
            ):
                codes.append(status["status"])
    return codes


async def test_a_ros2_action_client_finds_the_server_and_follows_its_goals_status() -> None:
    """What rclpy and rclcpp action clients need of a server besides its services.

    ``wait_for_server`` waits for the three services and a feedback publisher
    (rcl_action action_client.c ``rcl_action_server_is_available``); ``ros2 action
    list`` finds actions by their feedback topics (rcl_action graph.c); a client's
    goal handles follow the ``status`` topic, transient local, keep last 1
    (``rcl_action_qos_profile_status_default``).
    """
    first = endpoint()
    graph = Graph()

    async def patient(goal: dict[str, Any], context: GoalContext) -> dict[str, Any]:
        for _ in range(goal["order"]):  # 50 ms a step, unless canceled
            if context.cancel_requested:
                raise GoalCanceledError
            await anyio.sleep(0.05)
        return {"sequence": [0, 1]}

    registry = graph.registry
    wire = ActionWire(registry, registry.action(FIBONACCI))
    done, stopped = bytes(range(16)), bytes(range(16, 32))
    statuses: list[Any] = []
    async with serving_fib(graph, patient, "/fib_server", first):
        with bare_session(first) as session:
            entities: list[Entity] = []
            with anyio.fail_after(WAIT_S):
                while len([e for e in entities if e.node == "fib_server" and e.topic]) < 5:
                    await anyio.sleep(0.05)
                    entities = await tokens_of(session)
            status_sub = zenoh.ext.declare_advanced_subscriber(
                session,
                STATUS_KEY,
                statuses.append,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
            )
            reply, _ = await ros2_call_until_answered(
                session, SEND_GOAL_KEY, wire.send_goal(done, {"order": 4})
            )
            assert wire.read_accepted(reply.ok.payload.to_bytes())
            await until(lambda: status_codes(statuses, done)[-1:] == [4], "SUCCEEDED")
            reply, _ = await ros2_call_until_answered(
                session, SEND_GOAL_KEY, wire.send_goal(stopped, {"order": 1000})
            )
            await until(lambda: status_codes(statuses, stopped) == [2], "EXECUTING")
            info = {"goal_id": {"uuid": stopped}, "stamp": {"sec": 0, "nanosec": 0}}
            cancel = encode_sample(
                registry, "action_msgs/srv/CancelGoal_Request", {"goal_info": info}
            )
            reply, _ = await ros2_call_until_answered(session, CANCEL_KEY, cancel)
            await until(lambda: status_codes(statuses, stopped)[-1:] == [5], "CANCELED")
            status_sub.undeclare()
            # a late subscriber gets the last status from the publisher's cache
            late: list[Any] = []
            late_sub = zenoh.ext.declare_advanced_subscriber(
                session,
                STATUS_KEY,
                late.append,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
            )
            await until(lambda: bool(late), "the latched status")
            late_sub.undeclare()
    server = {(e.kind, e.topic.name): e for e in entities if e.node == "fib_server" and e.topic}
    assert set(server) == {
        (EntityKind.SERVICE, "/fib/_action/send_goal"),
        (EntityKind.SERVICE, "/fib/_action/get_result"),
        (EntityKind.SERVICE, "/fib/_action/cancel_goal"),
        (EntityKind.PUBLISHER, "/fib/_action/feedback"),
        (EntityKind.PUBLISHER, "/fib/_action/status"),
    }
    feedback = server[(EntityKind.PUBLISHER, "/fib/_action/feedback")].topic
    assert feedback is not None
    assert f"0/fib/_action/feedback/{feedback.dds_type}/{feedback.type_hash}" == FEEDBACK_KEY
    status = server[(EntityKind.PUBLISHER, "/fib/_action/status")]
    assert status.topic is not None
    assert (status.topic.dds_type, status.topic.type_hash) == (
        "action_msgs::msg::dds_::GoalStatusArray_",
        STATUS_HASH,
    )
    assert (status.topic.qos.durability, status.topic.qos.depth) == (Durability.TRANSIENT_LOCAL, 1)
    # the goals' states in order: EXECUTING then SUCCEEDED; EXECUTING, CANCELING, CANCELED
    assert status_codes(statuses, done) == [2, 4]
    assert status_codes(statuses, stopped) == [2, 3, 5]
    attached = [Attachment.decode(sample.attachment.to_bytes()) for sample in statuses]
    assert {a.source_gid for a in attached} == {status.gid()}
    numbers = [a.sequence_number for a in attached]
    assert numbers == sorted(numbers)
    assert status_codes(late[-1:], stopped) == [5]
    accepted_at = decode_sample(REGISTRY, GOAL_STATUS_ARRAY, late[-1].payload.to_bytes())
    stamps = [s["goal_info"]["stamp"]["sec"] for s in cast("list[Any]", accepted_at["status_list"])]
    assert all(abs(stamp - time.time()) < 60 for stamp in stamps)


class Ros2ActionServer:
    """``/fib`` served as rcl_action's server on rmw_zenoh serves it (Zenoh threads).

    Its node's and entities' tokens; complete queryables for ``send_goal``,
    ``get_result`` and ``cancel_goal``, whose replies carry the request's sequence
    number and GID; feedback samples with the publisher's attachment. A goal of
    order n runs n - 1 steps of 50 ms; ``get_result`` is answered when it ends.
    """

    FEEDBACK_GID = bytes(range(200, 216))

    def __init__(self, session: Any, wire: Any) -> None:
        self.wire = wire
        self.asked: list[tuple[str, Attachment]] = []  # (service, the request's attachment)
        self.canceled: set[bytes] = set()
        self.results: dict[bytes, tuple[int, dict[str, Any]]] = {}
        self.waiting: dict[bytes, Any] = {}
        self.lock = threading.Lock()
        registry = wire.registry
        node = Entity(0, "1234abcd", 1, 1, EntityKind.NODE, "/", "ros2_fib")
        hashes = {
            "send_goal": SEND_GOAL_HASH,
            "get_result": named_service_hash(registry, f"{FIBONACCI}_GetResult"),
            "cancel_goal": CANCEL_HASH,
        }
        types = {
            "send_goal": SEND_GOAL_TYPE,
            "get_result": wire.dds_type("GetResult"),
            "cancel_goal": "action_msgs::srv::dds_::CancelGoal_",
        }
        handlers = {
            "send_goal": self.on_send_goal,
            "get_result": self.on_get_result,
            "cancel_goal": self.on_cancel,
        }
        self.handles: list[Any] = [session.liveliness().declare_token(node.token())]
        for eid, name in enumerate(handlers, start=2):
            topic = Topic(f"/fib/_action/{name}", types[name], hashes[name])
            entity = Entity(0, "1234abcd", 1, eid, EntityKind.SERVICE, "/", "ros2_fib", topic=topic)
            key = f"0/fib/_action/{name}/{types[name]}/{hashes[name]}"
            self.handles.append(session.liveliness().declare_token(entity.token()))
            self.handles.append(session.declare_queryable(key, handlers[name], complete=True))
        self.feedback = session.declare_publisher(FEEDBACK_KEY)
        self.handles.append(self.feedback)

    def close(self) -> None:
        for handle in self.handles:
            handle.undeclare()

    def reply(self, query: Any, payload: bytes) -> None:
        asked = Attachment.decode(query.attachment.to_bytes())
        back = pack_attachment(asked.sequence_number, time.time_ns(), asked.source_gid)
        query.reply(query.key_expr, payload, attachment=back)
        query.drop()

    def on_send_goal(self, query: Any) -> None:
        self.asked.append(("send_goal", Attachment.decode(query.attachment.to_bytes())))
        goal_id, goal = self.wire.read_send_goal(query.payload.to_bytes())
        self.reply(query, self.wire.accepted(True, time.time()))
        threading.Thread(target=self.execute, args=(goal_id, goal["order"]), daemon=True).start()

    def execute(self, goal_id: bytes, order: int) -> None:
        sequence, status = [0, 1], 4  # SUCCEEDED
        for step in range(1, order):
            if goal_id in self.canceled:
                status = 5  # CANCELED
                break
            time.sleep(0.05)
            sequence.append(sequence[-1] + sequence[-2])
            attachment = pack_attachment(step, time.time_ns(), self.FEEDBACK_GID)
            payload = self.wire.feedback(goal_id, {"sequence": list(sequence)})
            self.feedback.put(payload, attachment=attachment)
        with self.lock:
            self.results[goal_id] = (status, {"sequence": sequence})
            query = self.waiting.pop(goal_id, None)
        if query is not None:
            self.reply(query, self.wire.result(status, {"sequence": sequence}))

    def on_get_result(self, query: Any) -> None:
        self.asked.append(("get_result", Attachment.decode(query.attachment.to_bytes())))
        goal_id = self.wire.read_get_result(query.payload.to_bytes())
        with self.lock:
            ended = self.results.get(goal_id)
            if ended is None:
                self.waiting[goal_id] = query
                return
        self.reply(query, self.wire.result(*ended))

    def on_cancel(self, query: Any) -> None:
        self.asked.append(("cancel_goal", Attachment.decode(query.attachment.to_bytes())))
        request = decode_sample(REGISTRY, f"{CANCEL_GOAL}_Request", query.payload.to_bytes())
        info: Any = request["goal_info"]
        self.canceled.add(bytes(info["goal_id"]["uuid"]))
        response = {"return_code": 0, "goals_canceling": [info]}
        self.reply(query, encode_sample(REGISTRY, f"{CANCEL_GOAL}_Response", response))


async def test_a_graph_sends_goals_to_a_ros2_action_server_and_cancels_one() -> None:
    """rwt as a ROS 2 action client: goal, feedback, result and cancel, each service
    called through a client entity of its own, as rcl_action's client has three:
    a token the network sees, a GID, and sequence numbers from 1."""
    first = endpoint()
    graph = Graph()
    wire = ActionWire(graph.registry, graph.registry.action(FIBONACCI))
    feedback: list[dict[str, Any]] = []
    with bare_session(listen=first) as session:
        server = Ros2ActionServer(session, wire)
        try:
            async with open_zenoh_link(graph, peer(connect=(first,))):
                await until(lambda: "/fib" in action_servers(graph, EVERYTHING), "the action")
                outcome = await send_action_goal(
                    graph, "/fib", {"order": 5}, on_feedback=feedback.append, timeout_s=WAIT_S
                )
                done: list[tuple[GoalStatus, bool, object]] = []
                handle = graph.port.send_action_goal(
                    graph.port.local_client(),
                    "/fib",
                    {"order": 1000},
                    lambda *ended: done.append(ended),
                )
                await until(lambda: len(server.asked) >= 4, "the second goal's result request")
                handle.request_cancel()
                await until(lambda: bool(done), "the canceled goal's end")
                clients = {
                    e.topic.name: e.gid()
                    for e in await tokens_of(session)
                    if e.kind is EntityKind.CLIENT and e.topic is not None
                }
        finally:
            server.close()
    assert outcome.status is GoalStatus.SUCCEEDED
    assert outcome.result == {"sequence": [0, 1, 1, 2, 3, 5]}
    # feedback in order, each a step towards the result; the first may come before the
    # route to rwt's subscriber is up, the last may trail the result (another route)
    assert feedback
    assert all([0, 1, 1, 2, 3, 5][: len(f["sequence"])] == f["sequence"] for f in feedback)
    assert [len(f["sequence"]) for f in feedback] == sorted({len(f["sequence"]) for f in feedback})
    assert done[0][:2] == (GoalStatus.CANCELED, True)
    called = [name for name, _ in server.asked]
    assert called == ["send_goal", "get_result", "send_goal", "get_result", "cancel_goal"]
    by_service: dict[str, list[Attachment]] = {}
    for name, attachment in server.asked:
        by_service.setdefault(name, []).append(attachment)
    for name, asked in by_service.items():
        # one GID per service, the client token's; numbered from 1 (a repeat is refused)
        assert {a.source_gid for a in asked} == {clients[f"/fib/_action/{name}"]}
        assert [a.sequence_number for a in asked] == list(range(1, len(asked) + 1))
    assert len({asked[0].source_gid for asked in by_service.values()}) == 3


async def test_a_ros2_client_reads_a_node_parameter_and_gets_its_sequence_number_back() -> None:
    first = endpoint()
    graph = Graph()
    graph.params.declare("/camera", {"fps": 30})
    registry = graph.registry
    service = "rcl_interfaces/srv/GetParameters"
    key = "0/camera/get_parameters/rcl_interfaces::srv::dds_::GetParameters_/" + named_service_hash(
        registry, service
    )
    request = encode_sample(registry, f"{service}_Request", {"names": ["fps"]})
    async with open_zenoh_link(graph, peer(listen=first)):
        with bare_session(first) as session:
            reply, sequence = await ros2_call_until_answered(session, key, request)
    assert reply.ok is not None, reply.err.payload.to_string()
    response = decode_sample(registry, f"{service}_Response", reply.ok.payload.to_bytes())
    values: Any = response["values"]
    assert [value["integer_value"] for value in values] == [30]
    attachment = Attachment.decode(reply.ok.attachment.to_bytes())
    assert (attachment.sequence_number, attachment.source_gid) == (sequence, CLIENT_GID)


# rosidl's hashes of the other parameter services (share/rcl_interfaces/srv/*.json, Kilted)
PARAM_HASHES = {
    "describe_parameters": (
        "DescribeParameters",
        "RIHS01_845b484d71eb0673dae682f2e3ba3c4851a65a3dcfb97bddd82c5b57e91e4cff",
    ),
    "get_parameter_types": (
        "GetParameterTypes",
        "RIHS01_da199c878688b3e530bdfe3ca8f74cb9fa0c303101e980a9e8f260e25e1c80ca",
    ),
    "set_parameters_atomically": (
        "SetParametersAtomically",
        "RIHS01_0e192ef259c07fc3c07a13191d27002222e65e00ccec653ca05e856f79285fcd",
    ),
}


async def test_a_ros2_client_describes_types_and_sets_atomically_a_nodes_parameters() -> None:
    first = endpoint()
    graph = Graph()
    graph.params.declare("/camera", {"fps": 30})  # keeps its type
    graph.params.declare("/camera", {"serial": "x1"}, read_only=True)
    graph.params.set("/camera:label", "front")  # dynamic typing, as a client's set_param
    registry = graph.registry

    def key(part: str) -> str:
        name, hash_text = PARAM_HASHES[part]
        return f"0/camera/{part}/rcl_interfaces::srv::dds_::{name}_/{hash_text}"

    async def call(part: str, request: dict[str, Any]) -> Any:
        service = f"rcl_interfaces/srv/{PARAM_HASHES[part][0]}"
        payload = encode_sample(registry, f"{service}_Request", request)
        reply, _ = await ros2_call_until_answered(session, key(part), payload)
        if reply.ok is None:
            return reply.err.payload.to_string()
        return decode_sample(registry, f"{service}_Response", reply.ok.payload.to_bytes())

    def value(kind: int, **field: object) -> dict[str, object]:
        return {
            **REGISTRY.message("rcl_interfaces/msg/ParameterValue").default(),
            "type": kind,
            **field,
        }

    async with open_zenoh_link(graph, peer(listen=first)):
        with bare_session(first) as session:
            described = await call(
                "describe_parameters", {"names": ["fps", "label", "serial", "no"]}
            )
            types = await call("get_parameter_types", {"names": ["fps", "label", "serial", "no"]})
            # the label's change comes first, the refused one last: nothing may change
            refused = await call(
                "set_parameters_atomically",
                {
                    "parameters": [
                        {"name": "label", "value": value(4, string_value="rear")},
                        {"name": "fps", "value": value(4, string_value="fast")},
                    ]
                },
            )
            after_refused = graph.params.get("/camera:label")
            done = await call(
                "set_parameters_atomically",
                {
                    "parameters": [
                        {"name": "label", "value": value(4, string_value="rear")},
                        {"name": "fps", "value": value(2, integer_value=25)},
                    ]
                },
            )
            huge = await call("get_parameter_types", {"names": ["fps"] * 10_001})
            offered = {
                (e.topic.name, e.topic.dds_type, e.topic.type_hash)
                for e in await tokens_of(session)
                if e.kind is EntityKind.SERVICE and e.topic is not None
            }
    for part, (name, hash_text) in PARAM_HASHES.items():
        assert (f"/camera/{part}", f"rcl_interfaces::srv::dds_::{name}_", hash_text) in offered
    rows = [
        (d["name"], d["type"], d["read_only"], d["dynamic_typing"])
        for d in described["descriptors"]
    ]
    assert rows == [
        ("fps", 2, False, False),
        ("label", 4, False, True),
        ("serial", 4, True, False),
        ("no", 0, False, False),
    ]
    assert list(types["types"]) == [2, 4, 4, 0]
    assert refused == {
        "result": {
            "successful": False,
            "reason": "parameter /camera:fps has type integer, not string",
        }
    }
    assert after_refused == "front"
    assert done == {"result": {"successful": True, "reason": ""}}
    assert (graph.params.get("/camera:label"), graph.params.get("/camera:fps")) == ("rear", 25)
    assert "10001 names in one request, more than 10000" in huge


async def test_calls_to_a_ros2_service_carry_each_process_own_client_gid() -> None:
    """A ROS 2 service refuses a second request with the same GID and sequence number."""
    first = endpoint()
    asked: list[Attachment] = []

    registry = TypeRegistry()

    def serve(query: Any) -> None:  # a Zenoh thread: the service as rmw_zenoh answers
        request = Attachment.decode(query.attachment.to_bytes())
        asked.append(request)
        values = decode_sample(registry, f"{ADD_TYPE}_Request", query.payload.to_bytes())
        total = {"sum": sum(values.values())}
        response = encode_sample(registry, f"{ADD_TYPE}_Response", total)
        back = pack_attachment(request.sequence_number, time.time_ns(), request.source_gid)
        query.reply(query.key_expr, response, attachment=back)

    add = Topic("/add", "example_interfaces::srv::dds_::AddTwoInts_", ADD_HASH)
    entity = Entity(0, "1234abcd", 1, 2, EntityKind.SERVICE, "/", "ros2_adder", topic=add)
    a, b = Graph(), Graph()
    with bare_session(listen=first) as session:
        queryable = session.declare_queryable(ADD_KEY, serve, complete=True)
        token = session.liveliness().declare_token(entity.token())
        async with (
            open_zenoh_link(a, peer(connect=(first,))),
            open_zenoh_link(b, peer(connect=(first,))),
        ):
            await until(lambda: "/add" in services(a, EVERYTHING), "A sees the service")
            await until(lambda: "/add" in services(b, EVERYTHING), "B sees the service")
            assert await call_service(a, "/add", {"a": 1, "b": 2}) == {"sum": 3}
            assert await call_service(a, "/add", {"a": 3, "b": 4}) == {"sum": 7}
            assert await call_service(b, "/add", {"a": 5, "b": 6}) == {"sum": 11}
            # each process's caller is a client entity of /add, its token on the network
            clients = [e for e in await tokens_of(session) if e.kind is EntityKind.CLIENT]
        token.undeclare()
        queryable.undeclare()
    assert sorted(e.topic.name for e in clients if e.topic) == ["/add", "/add"]
    gid_a, gid_b = asked[0].source_gid, asked[2].source_gid
    assert [request.source_gid for request in asked] == [gid_a, gid_a, gid_b]
    assert {e.gid() for e in clients} == {gid_a, gid_b}  # two entities, two GIDs
    assert [request.sequence_number for request in asked] == [1, 2, 1]  # per client, from 1


# ---- zenoh-ros2-sdk as a whole peer ------------------------------------------------------

SDK_PEER = Path(__file__).with_name("sdk_peer.py")


class SdkPeer:
    """The SDK peer process and its commands (``sdk_peer.py``)."""

    def __init__(self, process: Process) -> None:
        self.process = process

    async def ask(self, command: str) -> Any:
        stdin = self.process.process.stdin
        assert stdin is not None
        await stdin.send(f"{command}\n".encode())
        return json.loads(await self.process.line())


@contextlib.asynccontextmanager
async def sdk_peer(connect: str) -> AsyncIterator[SdkPeer]:
    pytest.importorskip("zenoh_ros2_sdk", reason="zenoh-ros2-sdk is in the test extra")
    async with started([sys.executable, str(SDK_PEER), connect], "zenoh-ros2-sdk") as process:
        assert (await process.line()).strip() == "ready", process.stderr()
        yield SdkPeer(process)


async def test_zenoh_ros2_sdk_nodes_and_a_linked_graph_share_topics_and_services() -> None:
    first = endpoint()
    graph = Graph()
    heard: list[dict[str, object]] = []
    graph.create_subscription("/from_sdk", heard.append, "std_msgs/msg/String", node="/listener")
    talker = graph.create_publisher("/to_sdk", "std_msgs/msg/String", node="/talker")
    graph.create_service(
        "/rwt/add", ADD_TYPE, lambda req: {"sum": 100 * req["a"] + req["b"]}, node="/adder"
    )
    mapper = graph.create_publisher("/map", "std_msgs/msg/String", latch=True, node="/mapper")
    async with open_zenoh_link(graph, peer(listen=first)), sdk_peer(first) as sdk:
        mapper.publish({"data": "map v1"})
        mapper.publish({"data": "map v2"})
        # the SDK's nodes, from their liveliness tokens, in the graph's rosapi
        await until(lambda: "/sdk/add" in services(graph, EVERYTHING), "the SDK's service")
        await until(lambda: bool(publishers(graph, EVERYTHING, "/from_sdk")), "its publisher")
        await until(lambda: bool(subscribers(graph, EVERYTHING, "/to_sdk")), "its subscriber")
        assert publishers(graph, EVERYTHING, "/from_sdk") == ["/sdk_talker"]
        assert "/sdk_listener" in subscribers(graph, EVERYTHING, "/to_sdk")
        # the SDK publishes, the graph's subscription hears it (once per publish)
        with anyio.fail_after(WAIT_S):
            while not heard:
                await sdk.ask("publish hello from the sdk")
                await anyio.sleep(0.1)
        assert heard[0] == {"data": "hello from the sdk"}
        # the graph publishes, the SDK's subscriber decodes it
        with anyio.fail_after(WAIT_S):
            while not await sdk.ask("received"):
                talker.publish({"data": "hello from rwt"})
                await anyio.sleep(0.1)
        assert set(await sdk.ask("received")) == {"hello from rwt"}
        # services both ways: the graph calls the SDK's; the SDK's client calls the graph's
        assert await call_service(graph, "/sdk/add", {"a": 2, "b": 40}) == {"sum": 42}
        assert await sdk.ask("call /rwt/add 4 5") == 405
        # a late transient-local subscriber of the SDK gets the latched message from the
        # publisher's cache, which it finds by the session id in the publisher's token
        assert await sdk.ask("latched /map") == ["map v2"]
        # the SDK lists the graph's entities with their ROS 2 types
        seen = await sdk.ask("graph")
        assert seen["topics"]["/to_sdk"] == ["std_msgs/msg/String"]
        assert seen["topics"]["/from_sdk"] == ["std_msgs/msg/String"]
        assert seen["services"]["/rwt/add"] == [ADD_TYPE]


async def test_queries_with_forged_attachments_are_answered_and_the_service_carries_on() -> None:
    first = endpoint()
    graph = adder_graph()
    registry = REGISTRY
    request = encode_sample(registry, f"{ADD_TYPE}_Request", {"a": 1, "b": 1})
    forged = [b"", b"\xff" * 33, bytes(1 << 20), (2**63 - 1).to_bytes(8, "little") * 5]

    def call(session: Any, attachment: bytes, payload: bytes) -> list[Any]:
        return list(session.get(ADD_KEY, payload=payload, attachment=attachment, timeout=3.0))

    async with open_zenoh_link(graph, peer(listen=first)):
        with bare_session(first) as session:
            await ros2_call_until_answered(session, ADD_KEY, request)  # the route is up
            for attachment in forged:
                [reply] = await anyio.to_thread.run_sync(call, session, attachment, request)
                back = Attachment.decode(reply.ok.attachment.to_bytes())
                assert (back.sequence_number, back.source_gid) == (0, bytes(16))
            # a payload that is not the request's CDR gets an error reply, not silence
            [bad] = await anyio.to_thread.run_sync(call, session, bytes(16), b"\xff" * 3)
            assert bad.err is not None
            # and a real caller is still served
            reply, sequence = await ros2_call_until_answered(session, ADD_KEY, request)
    assert decode_sample(registry, f"{ADD_TYPE}_Response", reply.ok.payload.to_bytes()) == {
        "sum": 2
    }
    assert Attachment.decode(reply.ok.attachment.to_bytes()).sequence_number == sequence


async def test_forged_goals_and_cancels_are_refused_and_the_status_lists_only_real_goals() -> None:
    """A peer's garbage, a goal id sent twice and cancels of unknown or malformed goals."""
    first = endpoint()
    graph = Graph()
    started: list[int] = []

    async def counting(goal: dict[str, Any], context: GoalContext) -> dict[str, Any]:
        started.append(goal["order"])
        while not context.cancel_requested:
            await anyio.sleep(0.02)
        raise GoalCanceledError

    wire = ActionWire(graph.registry, graph.registry.action(FIBONACCI))
    real = bytes(range(16))
    statuses: list[Any] = []

    def call(session: Any, key: str, payload: bytes) -> list[Any]:
        return ros2_call(session, key, payload, 7)

    async with serving_fib(graph, counting, "/fib_server", first):
        with bare_session(first) as session:
            status_sub = session.declare_subscriber(STATUS_KEY, statuses.append)
            reply, _ = await ros2_call_until_answered(
                session, SEND_GOAL_KEY, wire.send_goal(real, {"order": 1})
            )
            assert wire.read_accepted(reply.ok.payload.to_bytes())
            # the same goal id again: refused, and no second goal starts
            [again] = await anyio.to_thread.run_sync(
                call, session, SEND_GOAL_KEY, wire.send_goal(real, {"order": 2})
            )
            assert wire.read_accepted(again.ok.payload.to_bytes()) is False
            # garbage and a goal that does not fit its type: error replies
            for payload in (b"", b"\xff" * 7, bytes(1 << 20)):
                [bad] = await anyio.to_thread.run_sync(call, session, SEND_GOAL_KEY, payload)
                assert bad.err is not None
            # cancels of an unknown goal and a malformed cancel: the real goal runs on
            stamp = {"sec": 2**31 - 1, "nanosec": 999_999_999}
            unknown = {"goal_id": {"uuid": b"\xff" * 16}, "stamp": stamp}
            request = f"{CANCEL_GOAL}_Request"
            for payload in (encode_sample(REGISTRY, request, {"goal_info": unknown}), b"\x00"):
                await anyio.to_thread.run_sync(call, session, CANCEL_KEY, payload)
            await until(lambda: bool(status_codes(statuses, real)), "the real goal's status")
            assert status_codes(statuses, real) == [2]
            # the real goal is still cancelable, and the status shows only it
            info = {"goal_id": {"uuid": real}, "stamp": {"sec": 0, "nanosec": 0}}
            cancel = encode_sample(REGISTRY, request, {"goal_info": info})
            await anyio.to_thread.run_sync(call, session, CANCEL_KEY, cancel)
            await until(lambda: status_codes(statuses, real)[-1:] == [5], "CANCELED")
            status_sub.undeclare()
    assert started == [1]
    last = decode_sample(REGISTRY, GOAL_STATUS_ARRAY, statuses[-1].payload.to_bytes())
    goals = [s["goal_info"]["goal_id"]["uuid"] for s in cast("list[Any]", last["status_list"])]
    assert goals == [real]
