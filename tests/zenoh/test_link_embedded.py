"""Two graphs in one process, linked over Zenoh on loopback: the embedding API across processes.

Each graph has its own Zenoh session (so each is "remote" to the other, as two
processes are); what one graph's code publishes, provides or lists, the other's
code sees as if the graphs were one.
"""

from __future__ import annotations

import contextlib
import sys
import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import anyio
import pytest

import zenoh
from rwt_graph.actions import GoalCanceledError, GoalContext
from rwt_graph.async_calls import ServiceCallError, call_service, send_action_goal
from rwt_graph.graph import Graph
from rwt_graph.rosapi.listing import (
    action_servers,
    node_names,
    publishers,
    service_node,
    services,
    subscribers,
    topics,
)
from rwt_graph.rosapi.visibility import EVERYTHING
from rwt_protocol.errors import FieldError, RwtError
from rwt_protocol.ports import GoalStatus
from rwt_transports.server import running_handlers
from rwt_zenoh.actions import GET_RESULT_SUFFIX
from rwt_zenoh.config import make_config
from rwt_zenoh.link import ZenohLink, open_zenoh_link
from rwt_zenoh.link_actions import MAX_RESULT_WAITERS
from tests.support.gates import CongestedGate

from .processes import REPO
from .support import WAIT_S, endpoint, peer, until

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

pytestmark = pytest.mark.anyio


@contextlib.asynccontextmanager
async def linked(count: int) -> AsyncIterator[list[tuple[Graph, ZenohLink]]]:
    """``count`` graphs, each linked by its own session; all connect to the first."""
    first = endpoint()
    async with contextlib.AsyncExitStack() as stack:
        pairs = []
        for index in range(count):
            graph = Graph()
            options = peer(listen=first) if index == 0 else peer(connect=(first,))
            link = await stack.enter_async_context(open_zenoh_link(graph, options))
            pairs.append((graph, link))
        yield pairs


async def test_a_message_published_on_one_graph_reaches_the_other_once() -> None:
    async with linked(2) as [(a, _), (b, _)]:
        got_b: list[dict[str, object]] = []
        got_a: list[dict[str, object]] = []
        b.create_subscription("/chatter", got_b.append, "std_msgs/msg/String", node="/listener")
        a.create_subscription("/chatter", got_a.append, "std_msgs/msg/String")
        talker = a.create_publisher("/chatter", "std_msgs/msg/String", node="/talker")
        # B's rosapi lists A's publisher once B's link has seen its token
        await until(lambda: "/talker" in publishers(b, EVERYTHING, "/chatter"), "publisher")
        await until(lambda: "/listener" in subscribers(a, EVERYTHING, "/chatter"), "subscriber")
        talker.publish({"data": "hello"})
        await until(lambda: len(got_b) == 1, "delivery")
        await anyio.sleep(0.3)  # anything extra (an echo) would arrive meanwhile
        assert got_b == [{"data": "hello"}]
        assert got_a == [{"data": "hello"}]  # the local subscriber, once: no echo from B


async def test_three_graphs_deliver_each_message_once_without_loops() -> None:
    async with linked(3) as pairs:
        received: list[list[dict[str, object]]] = []
        for index, (graph, _) in enumerate(pairs):
            inbox: list[dict[str, object]] = []
            received.append(inbox)
            graph.create_subscription("/n", inbox.append, "std_msgs/msg/Int32", node=f"/s{index}")
        a = pairs[0][0]
        pub = a.create_publisher("/n", "std_msgs/msg/Int32", node="/talker")
        for graph, _ in pairs[1:]:
            await until(lambda g=graph: "/talker" in publishers(g, EVERYTHING, "/n"), "publisher")
        await until(lambda: {"/s1", "/s2"} <= set(subscribers(a, EVERYTHING, "/n")), "subs")
        for number in range(5):
            pub.publish({"data": number})
        await until(lambda: all(len(inbox) == 5 for inbox in received), "delivery")
        await anyio.sleep(0.3)
        for inbox in received:
            assert [msg["data"] for msg in inbox] == [0, 1, 2, 3, 4]


async def test_a_late_subscriber_gets_the_last_latched_message() -> None:
    async with linked(2) as [(a, _), (b, _)]:
        latched = a.create_publisher("/map", "std_msgs/msg/String", latch=True, node="/mapper")
        latched.publish({"data": "old"})
        latched.publish({"data": "map v2"})
        await until(lambda: "/mapper" in publishers(b, EVERYTHING, "/map"), "publisher")
        got: list[dict[str, object]] = []
        b.create_subscription("/map", got.append, "std_msgs/msg/String")
        await until(lambda: len(got) == 1, "latched message")
        second: list[dict[str, object]] = []
        b.create_subscription("/map", second.append, node="/other")  # a later one, locally
        assert got == [{"data": "map v2"}]
        assert second == [{"data": "map v2"}]


async def test_rosapi_lists_topics_of_both_graphs_and_forgets_them() -> None:
    async with linked(2) as [(a, _), (b, _)]:
        pub = b.create_publisher("/only_on_b", "std_msgs/msg/Bool", node="/b_node")
        await until(lambda: "/only_on_b" in topics(a, EVERYTHING)[0], "listing")
        names, types = topics(a, EVERYTHING)
        assert types[names.index("/only_on_b")] == "std_msgs/msg/Bool"
        assert "/b_node" in a.nodes.names()
        pub.close()
        await until(lambda: "/only_on_b" not in topics(a, EVERYTHING)[0], "forgetting")
        await until(lambda: "/b_node" not in a.nodes.names(), "node gone")


async def test_types_are_checked_on_both_sides() -> None:
    async with linked(2) as [(a, _), (b, _)]:
        got: list[dict[str, object]] = []
        b.create_subscription("/x", got.append, "std_msgs/msg/Int32", node="/b")
        pub = a.create_publisher("/x", "std_msgs/msg/String", node="/a")
        await anyio.sleep(0.5)
        pub.publish({"data": "text"})  # another type: the keys differ, nothing arrives
        await anyio.sleep(0.3)
        assert got == []
        assert "/a" not in publishers(b, EVERYTHING, "/x")  # refused by B's graph


async def test_a_service_of_one_graph_is_called_from_the_other() -> None:
    async with linked(2) as [(a, _), (b, _)]:

        def add(request: dict[str, Any]) -> dict[str, Any]:
            return {"sum": request["a"] + request["b"]}

        def refuse(request: dict[str, Any]) -> dict[str, Any]:
            raise RwtError("refused by B")

        b.create_service("/b/add", "example_interfaces/srv/AddTwoInts", add, node="/adder")
        b.create_service("/b/refuse", "std_srvs/srv/Trigger", refuse, node="/adder")
        await until(lambda: {"/b/add", "/b/refuse"} <= set(services(a, EVERYTHING)), "services")
        assert service_node(a, EVERYTHING, "/b/add") == "/adder"
        assert await call_service(a, "/b/add", {"a": 2, "b": 40}) == {"sum": 42}
        with pytest.raises(ServiceCallError, match="refused by B"):
            await call_service(a, "/b/refuse")
        with pytest.raises(FieldError):  # checked against the type on the caller's side
            await call_service(a, "/b/add", {"a": "two"})


async def test_callers_fail_at_once_when_the_providing_graph_leaves() -> None:
    first = endpoint()
    a, b = Graph(), Graph()
    started = anyio.Event()

    async def never(request: dict[str, Any]) -> dict[str, Any]:
        started.set()
        await anyio.sleep_forever()
        raise AssertionError  # pragma: no cover

    async with open_zenoh_link(a, peer(listen=first)), running_handlers(b) as tg:
        b.create_service("/b/slow", "std_srvs/srv/Trigger", never, node="/slow")
        outcome: list[BaseException] = []

        async def caller(timeout_s: float) -> None:
            try:
                await call_service(a, "/b/slow", timeout_s=timeout_s)
            except ServiceCallError as exc:
                outcome.append(exc)

        async with open_zenoh_link(b, peer(connect=(first,))):
            await until(lambda: "/b/slow" in a.services.entries, "service")
            await caller(0.3)  # a timeout on the caller's side
            assert "timed out" in str(outcome.pop())
            tg.start_soon(caller, WAIT_S)
            with anyio.fail_after(WAIT_S):
                await started.wait()
        # B left: the caller is answered false at once, and the service goes with B's
        # tokens (B's closing may answer the call before A sees the tokens go)
        await until(lambda: bool(outcome), "the failed call")
        await until(lambda: "/b/slow" not in a.services.entries, "the service gone")
        tg.cancel_scope.cancel()


async def test_an_action_of_one_graph_runs_goals_from_the_other() -> None:
    first = endpoint()
    a, b = Graph(), Graph()

    async def fibonacci(goal: dict[str, Any], context: GoalContext) -> dict[str, Any]:
        sequence = [0, 1]
        for _ in range(goal["order"] - 1):
            if context.cancel_requested:
                raise GoalCanceledError
            sequence.append(sequence[-1] + sequence[-2])
            context.publish_feedback({"sequence": list(sequence)})
            await anyio.sleep(0.05 if goal["order"] < 50 else 0.2)
        return {"sequence": sequence}

    async with (
        running_handlers(b) as tg,
        open_zenoh_link(a, peer(listen=first)),
        open_zenoh_link(b, peer(connect=(first,))),
    ):
        b.create_action_server("/fib", "example_interfaces/action/Fibonacci", fibonacci, node="/f")
        await until(lambda: "/fib" in action_servers(a, EVERYTHING), "action")
        feedback: list[dict[str, Any]] = []
        outcome = await send_action_goal(
            a, "/fib", {"order": 5}, on_feedback=feedback.append, timeout_s=WAIT_S
        )
        assert outcome.status is GoalStatus.SUCCEEDED
        assert outcome.result == {"sequence": [0, 1, 1, 2, 3, 5]}
        assert feedback == [{"sequence": [0, 1, 1, 2, 3, 5][: n + 3]} for n in range(4)]
        # a cancel from A reaches B's goal
        done: list[tuple[GoalStatus, bool, object]] = []
        handle = a.port.send_action_goal(
            a.port.local_client(),
            "/fib",
            {"order": 100},
            lambda *outcome: done.append(outcome),
            feedback.append,
        )
        await until(lambda: len(feedback) > 5, "the long goal's feedback")
        handle.request_cancel()
        await until(lambda: bool(done), "the canceled goal")
        assert done[0][0] is GoalStatus.CANCELED
        tg.cancel_scope.cancel()


async def test_the_first_goal_gets_instant_feedback_and_a_gone_action_is_unsubscribed() -> None:
    """Feedback published the moment a goal starts still reaches the first caller.

    The caller's link subscribes to an action's feedback when the action appears
    (as an rclpy ActionClient does from its creation), not with the first goal: a
    subscription declared with the goal can reach the server after it. When the
    action goes, so does the subscription.
    """

    async def at_once(goal: dict[str, Any], context: GoalContext) -> dict[str, Any]:
        sequence = [0, 1]
        for _ in range(goal["order"] - 1):
            sequence.append(sequence[-1] + sequence[-2])
            context.publish_feedback({"sequence": list(sequence)})
        return {"sequence": sequence}

    async with linked(2) as [(a, a_link), (b, _)], running_handlers(b) as tg:
        server = b.create_action_server(
            "/fib", "example_interfaces/action/Fibonacci", at_once, node="/f"
        )
        await until(lambda: "/fib" in action_servers(a, EVERYTHING), "action")
        feedback: list[dict[str, Any]] = []
        outcome = await send_action_goal(
            a, "/fib", {"order": 5}, on_feedback=feedback.append, timeout_s=WAIT_S
        )
        assert outcome.result == {"sequence": [0, 1, 1, 2, 3, 5]}
        assert feedback == [{"sequence": [0, 1, 1, 2, 3, 5][: n + 3]} for n in range(4)]
        server.close()
        await until(lambda: "/fib" not in action_servers(a, EVERYTHING), "the action gone")
        await until(lambda: not a_link._actions._feedback_subs, "the subscription withdrawn")
        tg.cancel_scope.cancel()


async def test_parameters_of_a_node_of_one_graph_are_read_and_set_from_the_other() -> None:
    async with linked(2) as [(a, _), (b, _)]:
        b.params.declare("/camera", {"fps": 30, "name": "front", "gains": [1.5, 2.0]})
        # a node shows in rosapi with its parameters, read through its parameter services
        await until(lambda: a.params.get("/camera:name", None) == "front", "replica")
        assert a.params.get("/camera:fps") == 30
        assert a.params.get("/camera:gains") == (1.5, 2.0)
        assert "/camera" in node_names(a)
        # set on A (what rosapi set_param does): it reaches the node on B
        a.params.set("/camera:fps", 15)
        await until(lambda: b.params.get("/camera:fps") == 15, "set on B")
        # changed on B: A's copy follows
        b.params.set("/camera:name", "rear")
        await until(lambda: a.params.get("/camera:name", None) == "rear", "refreshed")
        b.params.delete("/camera:gains")
        await until(lambda: not a.params.has("/camera:gains"), "deleted")


async def test_graphs_of_another_domain_stay_apart() -> None:
    first = endpoint()
    a, same, other = Graph(), Graph(), Graph()
    other_domain = replace(peer(connect=(first,)), domain_id=7)
    async with (
        open_zenoh_link(a, peer(listen=first)),
        open_zenoh_link(same, peer(connect=(first,))),
        open_zenoh_link(other, other_domain),
    ):
        a.create_publisher("/in_domain_0", "std_msgs/msg/Empty", node="/talker")
        other.create_publisher("/in_domain_7", "std_msgs/msg/Empty", node="/other")
        await until(lambda: "/in_domain_0" in topics(same, EVERYTHING)[0], "same domain")
        await anyio.sleep(0.5)  # the other domain's tokens had as long to arrive
        assert "/in_domain_0" not in topics(other, EVERYTHING)[0]
        assert "/in_domain_7" not in topics(a, EVERYTHING)[0]
        assert "/in_domain_7" not in topics(same, EVERYTHING)[0]


async def test_a_flood_arrives_whole_and_in_order() -> None:
    """More samples than the link hands the graph in one turn: every one, in order."""
    count = 1200
    async with linked(2) as [(a, _), (b, _)]:
        got: list[dict[str, object]] = []
        b.create_subscription("/flood", got.append, "std_msgs/msg/Int32", node="/listener")
        pub = a.create_publisher("/flood", "std_msgs/msg/Int32", node="/talker")
        await until(lambda: "/listener" in subscribers(a, EVERYTHING, "/flood"), "subscriber")
        await until(lambda: "/talker" in publishers(b, EVERYTHING, "/flood"), "publisher")
        # Liveliness tokens and Zenoh's routes travel separately: probe until the route
        # is up (B gets a probe), then drop the probes
        with anyio.fail_after(WAIT_S):
            while not got:
                pub.publish({"data": -1})
                await anyio.sleep(0.1)
        await anyio.sleep(0.2)  # the probes still in flight arrive
        del got[:]
        for number in range(count):
            pub.publish({"data": number})
            if number % 100 == 99:
                await anyio.sleep(0.005)  # bursts, so Zenoh's congestion control keeps all
        await until(lambda: len(got) == count, "every message")
        assert [msg["data"] for msg in got] == list(range(count))


async def test_a_burst_of_200_images_from_another_process_arrives_whole() -> None:
    """200 images of 1 MB published at once by a linked graph in another process: none lost.

    The receiving graph is slow (5 ms an image) and its inbox holds 8 MiB, so the
    burst outruns it. The rule of docs/zenoh.md, "Reliability": a full inbox holds
    a reliable sample's peer back rather than drop it, and the sending link's
    publisher blocks (on its outbox thread, not its event loop) rather than drop.
    """
    count = 200
    got: list[object] = []
    probed = anyio.Event()

    def on_image(msg: dict[str, Any]) -> None:
        if msg["header"]["frame_id"] == "probe":
            probed.set()
            return
        time.sleep(0.005)  # a consumer slower than the network: the inbox fills
        got.append(msg["header"]["frame_id"])

    listen = endpoint()
    options = replace(peer(listen=listen), queue_bytes=8 * 1024 * 1024)
    graph = Graph()
    sender = [sys.executable, "-m", "benchmarks.zenoh_link", "send", listen, "1000000", str(count)]
    async with open_zenoh_link(graph, options) as link:
        graph.create_subscription("/tp", on_image, "sensor_msgs/msg/Image", node="/viewer")
        async with await anyio.open_process(sender, cwd=REPO) as process:
            assert process.stdin is not None
            with anyio.fail_after(WAIT_S):
                await probed.wait()
            await process.stdin.send(b"go\n")
            await until(lambda: len(got) >= count, "every image")
            await anyio.sleep(0.5)  # nothing more comes
            await process.stdin.send(b"\n")
        assert len(got) == count
        assert link._inbox.dropped == 0


async def test_a_peer_repeating_get_result_for_a_running_goal_is_refused_past_a_bound() -> None:
    # Any Zenoh peer may query a served goal's result; each query waits for the goal
    # to end, so a peer repeating it must not grow the server's memory without bound.
    first = endpoint()
    a, b = Graph(), Graph()

    async def slow(goal: dict[str, Any], context: GoalContext) -> dict[str, Any]:
        while not context.cancel_requested:
            await anyio.sleep(0.02)
        raise GoalCanceledError

    async with (
        running_handlers(b) as tg,
        open_zenoh_link(a, peer(listen=first)),
        open_zenoh_link(b, peer(connect=(first,))) as b_link,
    ):
        fib = "example_interfaces/action/Fibonacci"
        b.create_action_server("/fib", fib, slow, node="/f")
        await until(lambda: "/fib" in action_servers(a, EVERYTHING), "action")
        done: list[tuple[GoalStatus, bool, object]] = []
        handle = a.port.send_action_goal(
            a.port.local_client(), "/fib", {"order": 3}, lambda *o: done.append(o), print
        )
        actions = b_link._actions
        await until(lambda: bool(actions._served), "the goal served on B")
        [uuid] = actions._served
        # A's own query waits first; queries past the bound could crowd out a caller's
        # as a cancel from any peer could end its goal (link_actions.MAX_RESULT_WAITERS)
        await until(lambda: bool(actions._served[uuid].waiting), "A's own get_result")
        wire = actions.wire(fib)
        key = actions._key("/fib" + GET_RESULT_SUFFIX, wire, "GetResult")
        errors: list[str] = []

        repeater = zenoh.open(make_config(peer(connect=(first,))))
        try:
            # its queries go once it reaches B's queryable (sent before, they reach
            # nobody): B answers a goal it does not know at once
            probes: list[str] = []

            def probe() -> bool:
                repeater.get(
                    key,
                    lambda reply: probes.append(reply.err.payload.to_string() if reply.err else ""),
                    payload=wire.get_result(bytes(16)),
                    timeout=1,
                )
                return any("unknown goal" in p for p in probes)

            await until(probe, "B's get_result queryable")
            for _ in range(MAX_RESULT_WAITERS + 40):
                repeater.get(
                    key,
                    lambda reply: (
                        errors.append(reply.err.payload.to_string()) if reply.err else None
                    ),
                    payload=wire.get_result(uuid),
                    timeout=120,  # the waiting ones must not time out on a loaded machine
                )
            await until(lambda: len(errors) >= 40, "the refusals")
            waiting = actions._served[uuid].waiting
            assert len(waiting) <= MAX_RESULT_WAITERS
            assert all("get_result queries wait for this goal" in e for e in errors), errors
            handle.request_cancel()  # the goal ends: A's caller still gets its outcome
            await until(lambda: bool(done), "the canceled goal")
            assert done[0][0] is GoalStatus.CANCELED
        finally:
            repeater.close()
        tg.cancel_scope.cancel()


async def test_a_goals_feedback_reaches_it_before_its_result_while_subscribers_congest() -> None:
    # A topic whose deliveries congest a subscriber is held back while replies go on
    # (TopicHolds); an action's feedback must not be: the goal's result, a reply, would
    # pass it and end the goal, and the feedback behind would be lost.
    first = endpoint()
    a, b = Graph(), Graph()

    async def fibonacci(goal: dict[str, Any], context: GoalContext) -> dict[str, Any]:
        sequence = [0, 1]
        for _ in range(goal["order"] - 1):
            sequence.append(sequence[-1] + sequence[-2])
            context.publish_feedback({"sequence": list(sequence)})
        return {"sequence": sequence}

    async with (
        running_handlers(b) as tg,
        open_zenoh_link(a, peer(listen=first)),
        open_zenoh_link(b, peer(connect=(first,))),
    ):
        b.create_action_server("/fib", "example_interfaces/action/Fibonacci", fibonacci, node="/f")
        await until(lambda: "/fib" in action_servers(a, EVERYTHING), "action")
        a.port.inflow = CongestedGate()  # type: ignore[misc]
        feedback: list[dict[str, Any]] = []
        outcome = await send_action_goal(
            a, "/fib", {"order": 5}, on_feedback=feedback.append, timeout_s=WAIT_S
        )
        assert outcome.result == {"sequence": [0, 1, 1, 2, 3, 5]}
        assert feedback == [{"sequence": [0, 1, 1, 2, 3, 5][: n + 3]} for n in range(4)]
        tg.cancel_scope.cancel()


async def test_a_message_no_graph_on_zenoh_subscribes_to_is_not_put_on_zenoh() -> None:
    """A put no subscriber matches goes nowhere: the link skips its encoding and put (D57)."""
    async with linked(2) as [(a, link_a), (b, _)]:
        puts: list[str] = []
        outbox = link_a._outbox
        put = outbox.put
        outbox.put = lambda key, *rest: (puts.append(key), put(key, *rest))[1]  # type: ignore[method-assign]
        here: list[dict[str, object]] = []
        a.create_subscription("/quiet", here.append, "std_msgs/msg/Int32", node="/local")
        talker = a.create_publisher("/quiet", "std_msgs/msg/Int32", node="/talker")
        await until(lambda: "/talker" in publishers(b, EVERYTHING, "/quiet"), "publisher")
        for number in range(10):
            talker.publish({"data": number})
        assert len(here) == 10  # the local subscriber got them all
        assert puts == []
        there: list[dict[str, object]] = []
        b.create_subscription("/quiet", there.append, "std_msgs/msg/Int32", node="/remote")
        await until(lambda: "/remote" in subscribers(a, EVERYTHING, "/quiet"), "subscriber")
        with anyio.fail_after(WAIT_S):
            while not there:  # Zenoh's routing knows B's subscriber a moment after the token
                talker.publish({"data": 99})
                await anyio.sleep(0.05)
        assert len(puts) >= len(there) and len(set(puts)) == 1  # /quiet's, once B subscribed
        assert {msg["data"] for msg in there} == {99}
