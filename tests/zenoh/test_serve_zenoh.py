"""`rwt serve --zenoh` processes on 127.0.0.1 with real clients: roslibpy on A, roslib (Node) on B.

The servers are subprocesses on random ports, joined by explicit loopback Zenoh
endpoints (multicast off): one pair A-B for the module (``pair``) where the
tests' names keep them apart, servers of a test's own where it kills one or
needs other options. Each test asserts what the clients see: a
message published on A reaches B's subscriber exactly once, a late subscriber on
B gets A's latched message, a service of B answers A's calls (concurrent ones
each their own), a caller on A is answered ``result: false`` when B dies mid-call,
and rosapi on any process lists the whole graph, also on a process that joins late.
"""

from __future__ import annotations

import contextlib
import json
import time
from typing import TYPE_CHECKING

import pytest

from tests.support.realclients import node_missing

from .processes import Process, node_client, python_client, rwt, serving, started
from .support import endpoint

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

pytestmark = [pytest.mark.anyio, pytest.mark.node]

MiB = 1024 * 1024


@pytest.fixture(autouse=True)
def _need_node() -> None:
    reason = node_missing()
    if reason is not None:
        pytest.skip(reason)


ROSLIBPY_PRELUDE = """
import json, sys, time, threading
import roslibpy

def connect(url):
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    ros = roslibpy.Ros(host, int(port))
    ros.run(timeout=10)
    return ros

def until(what, check, timeout=20):
    deadline = time.monotonic() + timeout
    while not check():
        if time.monotonic() > deadline:
            raise SystemExit(f"timed out waiting for {what}")
        time.sleep(0.05)

def say(*parts):
    print(*parts, flush=True)

def ros_subscribers(ros, topic):
    service = roslibpy.Service(ros, "/rosapi/subscribers", "rosapi_msgs/srv/Subscribers")
    return service.call(roslibpy.ServiceRequest({"topic": topic}), timeout=5)["subscribers"]

def stay():
    sys.stdin.read()  # until the test closes stdin or kills us
"""

ROSLIB_PRELUDE = """
import * as ROSLIB from "roslib";
const say = (...parts) => console.log(...parts);
async function connect(url) {
  const ros = new ROSLIB.Ros({});
  const opened = new Promise((resolve, reject) => {
    ros.once("connection", resolve);
    ros.once("error", (e) => reject(new Error(String(e?.message ?? e))));
  });
  await ros.connect(url);
  await opened;
  return ros;
}
const topic = (ros, name, messageType) => new ROSLIB.Topic({ ros, name, messageType });
const service = (ros, name, serviceType) => new ROSLIB.Service({ ros, name, serviceType });
const topics = async (ros) => (await new Promise((ok, no) => ros.getTopics(ok, no))).topics;
const services = async (ros) => await new Promise((ok, no) => ros.getServices(ok, no));
async function until(check) {
  for (let i = 0; i < 400 && !(await check()); i++) await new Promise((r) => setTimeout(r, 50));
}
setTimeout(() => process.exit(3), 60000).unref();
"""


@pytest.fixture(scope="module")
async def pair() -> AsyncIterator[tuple[str, str]]:
    """A, and B connected to it: their ws:// URLs, shared by the tests whose topics,
    services and actions have names of their own (none kills or reconfigures a server)."""
    a_ep = endpoint()
    async with serving("A", listen=a_ep) as (_, a_url), serving("B", connect=(a_ep,)) as (_, b_url):
        yield a_url, b_url


def roslibpy(body: str, url: str) -> str:
    return ROSLIBPY_PRELUDE + f"\nURL = {url!r}\n" + body


def roslib(body: str, url: str) -> str:
    return ROSLIB_PRELUDE + f"\nconst URL = {json.dumps(url)};\n" + body


async def no_line(process: Process, seconds: float) -> None:
    """Assert ``process`` prints nothing more for ``seconds``."""
    with pytest.raises(AssertionError, match="no line"):
        extra = await process.line(within=seconds)
        raise AssertionError(f"unexpected: {extra}")  # pragma: no cover - the failure text


async def test_topics_latched_and_rosapi_across_two_processes(pair: tuple[str, str]) -> None:
    a_url, b_url = pair
    async with (
        node_client(
            roslib(
                """
                const ros = await connect(URL);
                const chatter = topic(ros, "/chatter", "std_msgs/msg/String");
                chatter.subscribe((msg) => say("chatter", JSON.stringify(msg)));
                say("subscribed");
                process.stdin.on("data", () => {});
                process.stdin.on("end", () => process.exit(0));
                """,
                b_url,
            ),
            "roslib-B",
        ) as listener,
    ):
        assert (await listener.line()).strip() == "subscribed"
        async with python_client(
            roslibpy(
                """
ros = connect(URL)
talker = roslibpy.Topic(ros, "/chatter", "std_msgs/msg/String")
talker.advertise()
latched = roslibpy.Topic(ros, "/map", "std_msgs/msg/String", latch=True)
latched.advertise()
# rosapi on A lists B's subscriber once the link has seen it
until("B's subscriber", lambda: len(ros_subscribers(ros, "/chatter")) >= 1)
for text in ("one", "two", "three"):
    talker.publish(roslibpy.Message({"data": text}))
latched.publish(roslibpy.Message({"data": "map v1"}))
latched.publish(roslibpy.Message({"data": "map v2"}))
say("published")
stay()
""",
                a_url,
            ),
            "roslibpy-A",
        ) as talker:
            assert (await talker.line()).strip() == "published"
            got = [(await listener.line()).strip() for _ in range(3)]
            assert got == [
                'chatter {"data":"one"}',
                'chatter {"data":"two"}',
                'chatter {"data":"three"}',
            ]
            await no_line(listener, 0.5)  # exactly once: no echo, no duplicate
            # a late subscriber on B gets the last latched message of A
            async with node_client(
                roslib(
                    """
                    const ros = await connect(URL);
                    const map = topic(ros, "/map", "std_msgs/msg/String");
                    map.subscribe((msg) => say("map", JSON.stringify(msg)));
                    say("topics", JSON.stringify(await topics(ros)));
                    process.stdin.on("data", () => {});
                    """,
                    b_url,
                ),
                "roslib-B-late",
            ) as late:
                lines = {(await late.line()).strip() for _ in range(2)}
                assert 'map {"data":"map v2"}' in lines
                (topics_line,) = [line for line in lines if line.startswith("topics ")]
                # rosapi on B lists A's topics (and its own)
                assert {"/chatter", "/map"} <= set(json.loads(topics_line.removeprefix("topics ")))


async def test_services_across_processes_concurrent_calls_each_get_their_own_reply(
    pair: tuple[str, str],
) -> None:
    a_url, b_url = pair
    async with (
        node_client(
            roslib(
                """
                const ros = await connect(URL);
                const add = service(ros, "/b/add", "example_interfaces/srv/AddTwoInts");
                await add.advertise((request, response) => {
                  response.sum = request.a + request.b;
                  return true;
                });
                say("advertised");
                process.stdin.on("data", () => {});
                """,
                b_url,
            ),
            "roslib-B",
        ) as provider,
    ):
        assert (await provider.line()).strip() == "advertised"
        async with python_client(
            roslibpy(
                """
ros = connect(URL)
until("B's service", lambda: "/b/add" in ros.get_services())
say("type", ros.get_service_type("/b/add"))
add = roslibpy.Service(ros, "/b/add", "example_interfaces/srv/AddTwoInts")
results = {}
done = threading.Event()
def call(n):
    def ok(response):
        results[n] = response["sum"]
        if len(results) == 20:
            done.set()
    add.call(roslibpy.ServiceRequest({"a": n, "b": 1000}), ok, lambda e: say("error", e))
for n in range(20):
    call(n)
done.wait(20)
say("sums", json.dumps(sorted(results.items())))
""",
                a_url,
            ),
            "roslibpy-A",
        ) as caller:
            assert (await caller.line()).strip() == "type example_interfaces/srv/AddTwoInts"
            sums = json.loads((await caller.line()).strip().removeprefix("sums "))
            assert sums == [[n, n + 1000] for n in range(20)]


async def test_a_caller_is_answered_false_when_the_providers_process_dies_mid_call() -> None:
    a_ep = endpoint()
    async with (
        serving("A", listen=a_ep) as (_, a_url),
        serving("B", connect=(a_ep,)) as (b, b_url),
        python_client(
            roslibpy(
                """
ros = connect(URL)
slow = roslibpy.Service(ros, "/b/slow", "std_srvs/srv/Trigger")
def never(request, response):
    say("request")
    threading.Event().wait(60)  # the answer never comes: the process dies first
    return True
slow.advertise(never)
say("advertised")
stay()
""",
                b_url,
            ),
            "roslibpy-B",
        ) as provider,
    ):
        assert (await provider.line()).strip() == "advertised"
        async with python_client(
            roslibpy(
                """
ros = connect(URL)
until("B's service", lambda: "/b/slow" in ros.get_services())
slow = roslibpy.Service(ros, "/b/slow", "std_srvs/srv/Trigger")
start = time.monotonic()
failed = threading.Event()
def errback(error):
    say("failed", round(time.monotonic() - start, 1), error)
    failed.set()
slow.call(roslibpy.ServiceRequest({}), lambda r: say("answered", r), errback)
say("calling")
failed.wait(30)
""",
                a_url,
            ),
            "roslibpy-A",
        ) as caller:
            assert (await caller.line()).strip() == "calling"
            assert (await provider.line()).strip() == "request"
            killed = time.monotonic()
            b.kill()
            outcome = (await caller.line(within=15)).strip()
            assert outcome.startswith("failed"), outcome
            assert time.monotonic() - killed < 15  # well before the 30 s the caller waits


async def test_a_process_joining_late_sees_the_graph_and_three_processes_deliver_once() -> None:
    a_ep = endpoint()
    async with (
        serving("A", listen=a_ep) as (_, a_url),
        python_client(
            roslibpy(
                """
ros = connect(URL)
pub = roslibpy.Topic(ros, "/from_a", "std_msgs/msg/Int32")
pub.advertise()
svc = roslibpy.Service(ros, "/a/trigger", "std_srvs/srv/Trigger")
def answer(request, response):
    response["success"] = True
    response["message"] = "from A"
    return True
svc.advertise(answer)
say("ready")
for line in sys.stdin:  # each line: publish that number
    pub.publish(roslibpy.Message({"data": int(line)}))
""",
                a_url,
            ),
            "roslibpy-A",
        ) as a_client,
    ):
        assert (await a_client.line()).strip() == "ready"
        async with (
            serving("B", connect=(a_ep,)) as (_, b_url),
            serving("C", connect=(a_ep,)) as (_, c_url),
        ):
            subscriber = """
                const ros = await connect(URL);
                await until(async () => (await topics(ros)).includes("/from_a"));
                await until(async () => (await services(ros)).includes("/a/trigger"));
                const trigger = service(ros, "/a/trigger", "std_srvs/srv/Trigger");
                const reply = await new Promise((ok, fail) => trigger.callService({}, ok, fail));
                const t = topic(ros, "/from_a", "std_msgs/msg/Int32");
                t.subscribe((msg) => say("got", msg.data));
                say("ready", reply.message);
                process.stdin.on("data", () => {});
                """
            async with (
                node_client(roslib(subscriber, b_url), "roslib-B") as on_b,
                node_client(roslib(subscriber, c_url), "roslib-C") as on_c,
            ):
                assert (await on_b.line()).strip() == "ready from A"
                assert (await on_c.line()).strip() == "ready from A"
                # wait until A's link has seen both subscribers: then publish
                await _publish_until_both_get(a_client, on_b, on_c)


async def _publish_until_both_get(a_client: Process, on_b: Process, on_c: Process) -> None:
    """Publish 1, 2, 3... on A until B and C both got one; then each number arrives once."""
    stdin = a_client.process.stdin
    assert stdin is not None
    first: dict[str, int] = {}
    number = 0
    deadline = time.monotonic() + 20
    while len(first) < 2 and time.monotonic() < deadline:
        number += 1
        await stdin.send(f"{number}\n".encode())
        for name, process in (("B", on_b), ("C", on_c)):
            if name not in first:
                with contextlib.suppress(AssertionError):
                    first[name] = int((await process.line(within=0.3)).split()[1])
    assert len(first) == 2, "B and C never got A's messages"
    for offset in range(1, 4):
        await stdin.send(f"{number + offset}\n".encode())
    for name, process in (("B", on_b), ("C", on_c)):
        seen = [first[name]]
        while seen[-1] < number + 3:
            seen.append(int((await process.line(within=10)).split()[1]))
        assert seen == list(range(first[name], number + 4)), (name, seen)  # once each, in order
        await no_line(process, 0.3)


async def test_servers_meet_through_rwt_router_as_zenoh_clients() -> None:
    router_ep = endpoint()
    async with started(rwt("router", "--listen", router_ep), "router") as router:
        assert (await router.line()).strip() == f"router listening on {router_ep}"
        client_mode = ("--zenoh-mode", "client")
        async with (
            serving("A", connect=(router_ep,), extra=client_mode) as (_, a_url),
            serving("B", connect=(router_ep,), extra=client_mode) as (_, b_url),
            python_client(
                roslibpy(
                    """
ros = connect(URL)
pub = roslibpy.Topic(ros, "/from_a", "std_msgs/msg/Int32")
pub.advertise()
say("ready")
for line in sys.stdin:
    pub.publish(roslibpy.Message({"data": int(line)}))
""",
                    a_url,
                ),
                "roslibpy-A",
            ) as a_client,
            node_client(
                roslib(
                    """
                    const ros = await connect(URL);
                    const t = topic(ros, "/from_a", "std_msgs/msg/Int32");
                    t.subscribe((msg) => say("got", msg.data));
                    process.stdin.on("data", () => {});
                    """,
                    b_url,
                ),
                "roslib-B",
            ) as on_b,
        ):
            assert (await a_client.line()).strip() == "ready"
            stdin = a_client.process.stdin
            assert stdin is not None
            got = None
            for number in range(1, 60):
                await stdin.send(f"{number}\n".encode())
                try:
                    got = int((await on_b.line(within=0.3)).split()[1])
                    break
                except AssertionError:
                    continue
            assert got is not None, "B never got A's messages through the router"


async def test_an_action_served_by_roslib_on_b_runs_goals_of_roslibpy_on_a(
    pair: tuple[str, str],
) -> None:
    a_url, b_url = pair
    async with (
        node_client(
            roslib(
                """
                const ros = await connect(URL);
                const action = new ROSLIB.Action({
                  ros, name: "/fib", actionType: "example_interfaces/action/Fibonacci",
                });
                action.advertise((goal, id) => {
                  const sequence = [0, 1];
                  for (let i = 1; i < goal.order; i++) {
                    sequence.push(sequence.at(-1) + sequence.at(-2));
                    action.sendFeedback(id, { sequence: [...sequence] });
                  }
                  action.setSucceeded(id, { sequence });
                }, () => {});
                say("advertised");
                process.stdin.on("data", () => {});
                """,
                b_url,
            ),
            "roslib-B",
        ) as server,
    ):
        assert (await server.line()).strip() == "advertised"
        async with python_client(
            roslibpy(
                """
ros = connect(URL)
servers = roslibpy.Service(ros, "/rosapi/action_servers", "rosapi_msgs/srv/GetActionServers")
listed = lambda: servers.call(roslibpy.ServiceRequest({}), timeout=5)["action_servers"]
until("B's action", lambda: "/fib" in listed())
client = roslibpy.ActionClient(ros, "/fib", "example_interfaces/action/Fibonacci")
feedback, results, done = [], [], threading.Event()
def result(value):
    results.append(value["values"])
    done.set()
client.send_goal(roslibpy.Goal({"order": 5}), result, feedback.append,
                 lambda error: (say("error", error), done.set()))
done.wait(20)
# feedback (a topic) and the result (a service's answer) take separate ways through
# Zenoh, as through ROS 2, which orders neither against the other: the last feedback
# may come after the result, but none may be lost (the line says how many came)
deadline = time.monotonic() + 5
while len(feedback) < 4 and time.monotonic() < deadline:
    time.sleep(0.05)
say("result", json.dumps(results[0] if results else None), "feedback", len(feedback))
""",
                a_url,
            ),
            "roslibpy-A",
        ) as caller:
            line = (await caller.line()).strip()
            assert line == 'result {"sequence": [0, 1, 1, 2, 3, 5]} feedback 4', line


async def burst_to_a_slow_subscriber(
    count: int, size: int, pause_s: float, a_extra: tuple[str, ...], b_extra: tuple[str, ...]
) -> list[str]:
    """``count`` String messages of ``size`` characters from roslibpy on A to B.

    B's roslibpy subscriber sleeps ``pause_s`` a message in its callback (its
    socket is not read meanwhile). Returns the sequence numbers B got, in order.
    """
    a_ep = endpoint()
    async with (
        serving("A", listen=a_ep, extra=a_extra) as (_, a_url),
        serving("B", connect=(a_ep,), extra=b_extra) as (_, b_url),
        python_client(
            roslibpy(
                f"""
ros = connect(URL)
got = []
def on_message(msg):
    got.append(msg["data"][:8])
    time.sleep({pause_s})
listener = roslibpy.Topic(ros, "/burst", "std_msgs/msg/String", queue_length=0)
listener.subscribe(on_message)
say("subscribed")
until("the burst", lambda: len(got) >= {count}, timeout=60)
time.sleep(0.5)
say("got", json.dumps(got))
stay()
""",
                b_url,
            ),
            "roslibpy-B",
        ) as listener,
    ):
        assert (await listener.line()).strip() == "subscribed"
        async with python_client(
            roslibpy(
                f"""
ros = connect(URL)
talker = roslibpy.Topic(ros, "/burst", "std_msgs/msg/String")
talker.advertise()
until("B's subscriber", lambda: len(ros_subscribers(ros, "/burst")) >= 1)
time.sleep(0.5)  # the link's route to B is up (discovery is eventual)
for n in range({count}):
    talker.publish(roslibpy.Message({{"data": f"{{n:08d}}" + "x" * {size}}}))
say("published")
stay()
""",
                a_url,
            ),
            "roslibpy-A",
        ) as talker:
            assert (await talker.line()).strip() == "published"
            line = (await listener.line()).strip()
            assert line.startswith("got "), line
            got: list[str] = json.loads(line.removeprefix("got "))
            return got


async def test_a_burst_from_a_reaches_a_slow_subscriber_on_b_whole() -> None:
    # 24 messages of 1 MB at once, more than B's outbox for its subscriber holds
    # (16 MiB): B takes no more from the link while that outbox is congested, within
    # the subscriber's hold budget, as it would hold a publisher connected to it.
    # The subscriber reads slower than the burst comes, faster than the budget.
    got = await burst_to_a_slow_subscriber(24, 1_000_000, 0.03, (), ())
    assert got == [f"{n:08d}" for n in range(24)]


async def test_a_publisher_faster_than_the_link_is_held_back_not_dropped() -> None:
    # Small buffers all the way: A's queue for Zenoh holds 1 MiB, B's inbox 1 MiB
    # and B's outbox for its subscriber 1 MiB. B's subscriber reads slower than
    # the burst (30 MB) comes, so it backs up into A's queue. Past half of it, A
    # stops reading its publisher's socket until the queue is under a quarter
    # (within the hold budget), as it would for a congested local subscriber; B
    # ends each batch from its inbox at the sample that congested the
    # subscriber, so its outbox never passes its limit. Every message arrives, in
    # order. Checked: with ``--hold-budget 0`` on A, A dropped 16 and 29 of the
    # 120; with B's batches ending only at 4 MiB, B dropped 15 of 80.
    a_extra = ("--zenoh-outbox-bytes", str(MiB))
    b_extra = ("--zenoh-queue-bytes", str(MiB), "--send-buffer-limit", str(MiB))
    got = await burst_to_a_slow_subscriber(120, 250_000, 0.02, a_extra, b_extra)
    assert got == [f"{n:08d}" for n in range(120)]
