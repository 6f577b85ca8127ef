"""Topics both ways between real rclpy nodes and rosbridge clients through `rwt serve --ros2`."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import anyio
import pytest

from tests.integration.client_harness import ServerProcess, node_missing_reason
from tests.support.realclients import run_node, run_python

from .support import JsonLines, Peer, peers, roslibpy_prelude, skip_without_rclpy

pytestmark = [pytest.mark.anyio, skip_without_rclpy()]


@pytest.fixture(scope="module")
def server(ros_env: Path) -> Iterator[ServerProcess]:
    """One `rwt serve --ros2` for the module, with its TF republisher (which keeps
    ``/tf_repub_*`` for itself); the other tests' topics are clear of that prefix."""
    process = ServerProcess(ros_env, ("--ros2",))
    try:
        yield process
    finally:
        process.stop()


def _last_json(out: str) -> object:
    return json.loads(out.strip().splitlines()[-1])


SUBSCRIBE = """
got = []
topic = roslibpy.Topic(ros, "{topic}", "{type}")
topic.subscribe(lambda m: got.append(m))
wait_for(lambda: len(got) >= {count})
print(json.dumps(got[:{count}]))
ros.terminate()
"""


async def test_a_ros2_talker_reaches_a_roslibpy_subscriber(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("talk", "/chatter", ros_env):
        script = SUBSCRIBE.format(topic="/chatter", type="std_msgs/msg/String", count=5)
        got = _last_json(await run_python(roslibpy_prelude(server.port) + script))
    assert isinstance(got, list) and len(got) == 5, got
    numbers = [int(m["data"]) for m in got]
    assert numbers == list(range(numbers[0], numbers[0] + 5)), numbers  # in order, none lost


async def test_a_roslibpy_publisher_reaches_a_ros2_listener(
    server: ServerProcess, ros_env: Path
) -> None:
    script = """
topic = roslibpy.Topic(ros, "/from_web", "std_msgs/msg/String")
topic.advertise()
for i in range(100):  # until the listener has heard (the test stops reading then)
    topic.publish(roslibpy.Message({"data": f"web {i}"}))
    time.sleep(0.1)
ros.terminate()
"""
    with Peer("listen", "/from_web", ros_env) as listener:
        async with anyio.create_task_group() as tg:
            tg.start_soon(run_python, roslibpy_prelude(server.port) + script)
            heard = await anyio.to_thread.run_sync(listener.next)
            again = await anyio.to_thread.run_sync(listener.next)
            tg.cancel_scope.cancel()
    assert heard["heard"].startswith("web ")
    assert int(again["heard"].split()[1]) == int(heard["heard"].split()[1]) + 1


async def test_a_transient_local_publisher_reaches_a_late_subscriber(
    server: ServerProcess, ros_env: Path
) -> None:
    with Peer("latched", "/map_like", ros_env):
        # subscribed after the only message was published: only durability delivers it
        script = SUBSCRIBE.format(topic="/map_like", type="std_msgs/msg/String", count=1)
        got = _last_json(await run_python(roslibpy_prelude(server.port) + script))
    assert got == [{"data": "latched"}]


LATE_AFTER_SECOND = """
import json, sys
from websockets.sync.client import connect

def subscriber():
    ws = connect("ws://127.0.0.1:{port}")
    op = {{"op": "subscribe", "topic": "/static_like", "type": "std_msgs/msg/String"}}
    ws.send(json.dumps(op))
    return ws

def heard(ws):
    return json.loads(ws.recv(timeout=20))["msg"]["data"]

early = subscriber()  # stays subscribed, so the link keeps its subscription
print(json.dumps({{"early": heard(early)}}), flush=True)
sys.stdin.readline()  # the test started a second latched publisher
print(json.dumps({{"early": heard(early)}}), flush=True)
late = subscriber()
print(json.dumps({{"late": heard(late)}}), flush=True)
"""


async def test_a_second_latched_publishers_sample_reaches_a_late_subscriber(
    server: ServerProcess, ros_env: Path
) -> None:
    # /tf_static with a second static broadcaster: its sample arrives on the link's
    # transient-local subscription, often before the link's sweep has seen its
    # publisher; whichever comes first, a later subscriber gets the latest sample
    code = LATE_AFTER_SECOND.format(port=server.port)
    with Peer("latched", "/static_like", ros_env, "peer_a"):
        async with await anyio.open_process(["python", "-c", code]) as client:
            assert client.stdout is not None and client.stdin is not None
            lines = JsonLines(client.stdout)
            try:
                with anyio.fail_after(40):
                    assert await lines.next() == {"early": "latched by peer_a"}
                    with Peer("latched", "/static_like", ros_env, "peer_b"):
                        await client.stdin.send(b"\n")
                        assert await lines.next() == {"early": "latched by peer_b"}
                        late = await lines.next()
            finally:
                client.kill()
    assert late == {"late": "latched by peer_b"}


async def test_a_joint_state_arrives_whole(server: ServerProcess, ros_env: Path) -> None:
    with Peer("joints", "/joint_states", ros_env):
        script = SUBSCRIBE.format(topic="/joint_states", type="sensor_msgs/msg/JointState", count=2)
        got = _last_json(await run_python(roslibpy_prelude(server.port) + script))
    assert isinstance(got, list)
    assert [(m["name"], m["position"]) for m in got] == [(["a"], [1.5])] * 2


async def test_garbage_from_a_ros2_node_disturbs_no_other_topic(
    server: ServerProcess, ros_env: Path
) -> None:
    # Discovery of the two peers is independent: the script stays subscribed until the
    # server has met the garbage (its log says so), however late the match comes.
    script = f"""
import pathlib
log = pathlib.Path({str(server.stderr_path)!r})
good, bad = [], []
roslibpy.Topic(ros, "/garbled", "std_msgs/msg/String").subscribe(bad.append)
roslibpy.Topic(ros, "/clean", "std_msgs/msg/String").subscribe(good.append)
wait_for(lambda: len(good) >= 20)
wait_for(lambda: "event=ros2_bad_sample topic=/garbled" in log.read_text("utf-8", "replace"), 30)
print(json.dumps({{"good": len(good) >= 20, "bad": bad}}))
ros.terminate()
"""
    with peers(ros_env, ("garbage", "/garbled"), ("talk", "/clean")):
        got = _last_json(await run_python(roslibpy_prelude(server.port) + script))
    assert got == {"good": True, "bad": []}
    log = server.stderr_text()
    # one line for the episode, not one per sample (docs/limits.md), a warning: data is lost
    [line] = [x for x in log.splitlines() if "event=ros2_bad_sample topic=/garbled" in x]
    assert " WARNING rwt." in line, line


async def test_garbage_inside_a_burst_costs_only_itself(
    server: ServerProcess, ros_env: Path
) -> None:
    # A burst's samples reach the graph as one run (docs/ros2.md, "Latency under
    # rate"): one that is not CDR of its type is dropped alone, the rest go in order.
    script = SUBSCRIBE.format(topic="/mixed", type="std_msgs/msg/String", count=40)
    with Peer("mixed", "/mixed", ros_env):
        messages = _last_json(await run_python(roslibpy_prelude(server.port) + script))
    got = [m["data"] for m in messages]
    first = int(got[0][1:])  # the subscription may match mid-burst
    assert got == [f"g{n}" for n in range(first, first + 40)]
    log = server.stderr_text()
    assert len([x for x in log.splitlines() if "event=ros2_bad_sample topic=/mixed" in x]) == 1


async def test_a_ros2_talker_on_a_topic_the_server_keeps_is_refused_once(
    server: ServerProcess, ros_env: Path
) -> None:
    # The TF republisher keeps /tf_repub_* for itself (docs/limits.md): the ROS 2
    # publisher is not mirrored, and its samples, which then come through the
    # link's relay, are refused with one log line, never delivered.
    script = f"""
import pathlib
log = pathlib.Path({str(server.stderr_path)!r})
forged = []
roslibpy.Topic(ros, "/tf_repub_forged", "std_msgs/msg/String").subscribe(forged.append)
wait_for(lambda: "event=ros2_sample_refused topic=/tf_repub_forged" in log.read_text(), 30)
time.sleep(0.5)  # more samples meet the refusal: still one line for the episode
print(json.dumps(forged))
ros.terminate()
"""
    with Peer("talk", "/tf_repub_forged", ros_env):
        got = _last_json(await run_python(roslibpy_prelude(server.port) + script))
    log = server.stderr_text()
    assert got == []
    lines = [x for x in log.splitlines() if "event=ros2_sample_refused topic=/tf_repub_forged" in x]
    assert len(lines) == 1 and " WARNING rwt." in lines[0], log[-3000:]
    assert "Traceback" not in log, log[-3000:]


@pytest.mark.node
@pytest.mark.skipif(node_missing_reason() is not None, reason=str(node_missing_reason()))
async def test_a_ros2_talker_reaches_roslib_in_node(server: ServerProcess, ros_env: Path) -> None:
    code = f"""
import * as ROSLIB from "roslib";
const ros = new ROSLIB.Ros({{ url: "ws://127.0.0.1:{server.port}" }});
const got = [];
const topic = new ROSLIB.Topic({{
  ros, name: "/node_chatter", messageType: "std_msgs/msg/String",
}});
const timer = setTimeout(() => {{ console.log(JSON.stringify(got)); process.exit(1); }}, 20000);
topic.subscribe((m) => {{
  got.push(m.data);
  if (got.length === 3) {{
    clearTimeout(timer);
    console.log(JSON.stringify(got));
    ros.close();
    process.exit(0);
  }}
}});
"""
    with Peer("talk", "/node_chatter", ros_env):
        got = _last_json(await run_node(code))
    assert isinstance(got, list) and len(got) == 3
    numbers = [int(x) for x in got]
    assert numbers == list(range(numbers[0], numbers[0] + 3))


RESTART = """
got = []
roslibpy.Topic(ros, "/restarting", "std_msgs/msg/String").subscribe(lambda m: got.append(m["data"]))
wait_for(lambda: len(got) >= 3)
print(json.dumps({"before": len(got) >= 3}), flush=True)
input()  # the talker restarts meanwhile
mark = len(got)
wait_for(lambda: len(got) >= mark + 3)
print(json.dumps({"after": got[mark:][:3]}))
ros.terminate()
"""


async def test_a_ros2_node_restarting_mid_stream_keeps_the_subscription(
    server: ServerProcess, ros_env: Path
) -> None:
    talker = Peer("talk", "/restarting", ros_env)
    try:
        async with await anyio.open_process(
            ["python", "-c", roslibpy_prelude(server.port) + RESTART]
        ) as client:
            assert client.stdout is not None and client.stdin is not None
            lines = JsonLines(client.stdout)
            with anyio.fail_after(40):
                assert await lines.next() == {"before": True}
                talker.stop()
                talker = Peer("talk", "/restarting", ros_env)
                await client.stdin.send(b"\n")
                last = await lines.last()
    finally:
        talker.stop()
    # the new talker's messages (what it published before discovery matched it is
    # lost, as with any volatile subscription), in order
    numbers = [int(x) for x in last["after"]]
    assert numbers == list(range(numbers[0], numbers[0] + 3)), numbers


BAD_THEN_GOOD = """
import json
from websockets.sync.client import connect

with connect("ws://127.0.0.1:{port}") as ws:
    ws.send(json.dumps({{"op": "advertise", "topic": "/guarded", "type": "std_msgs/msg/String"}}))
    ws.send(json.dumps({{"op": "publish", "id": "bad", "topic": "/guarded", "msg": {{"data": 5}}}}))
    status = json.loads(ws.recv(timeout=20))
    print(json.dumps(status), flush=True)
    for i in range(200):  # until the listener has heard (the test stops reading then)
        good = {{"op": "publish", "topic": "/guarded", "msg": {{"data": f"ok {{i}}"}}}}
        ws.send(json.dumps(good))
        time.sleep(0.1)
"""


async def test_bad_input_from_a_rosbridge_client_stays_on_its_side(
    server: ServerProcess, ros_env: Path
) -> None:
    code = "import time\n" + BAD_THEN_GOOD.format(port=server.port)
    with Peer("listen", "/guarded", ros_env) as listener:
        async with await anyio.open_process(["python", "-c", code]) as client:
            try:
                assert client.stdout is not None
                with anyio.fail_after(20):
                    status = await JsonLines(client.stdout).next()
                heard = await anyio.to_thread.run_sync(listener.next)
            finally:
                client.kill()
    assert status["op"] == "status" and status["level"] == "error"
    assert status["id"] == "bad"
    assert heard["heard"].startswith("ok ")


BURST = """
import json, sys, time
from websockets.sync.client import connect

with connect("ws://127.0.0.1:{port}") as ws:
    def publish(data):
        ws.send(json.dumps({{"op": "publish", "topic": "/burst", "msg": {{"data": data}}}}))

    def listeners():
        ask = {{"op": "call_service", "service": "/rosapi/subscribers"}}
        ws.send(json.dumps({{**ask, "args": {{"topic": "/burst"}}}}))
        return json.loads(ws.recv(timeout=20))["values"]["subscribers"]

    # the robot's listener is up before the web client publishes: the server knows it
    end = time.monotonic() + 30
    while "/peer_count" not in listeners() and time.monotonic() < end:
        time.sleep(0.1)
    ws.send(json.dumps({{"op": "advertise", "topic": "/burst", "type": "std_msgs/msg/String"}}))
    start = time.monotonic()
    for i in range({count}):  # at once after the advertisement
        publish(str(i))
        if {rate}:
            time.sleep(max(0.0, start + (i + 1) / {rate} - time.monotonic()))
    print(json.dumps({{"sent": {count}}}), flush=True)
    sys.stdin.readline()
"""


def heard_next(listener: Peer, within: float, before: dict) -> dict:
    """The listener's next count line, or ``before`` when none comes ``within`` seconds."""
    try:
        return listener.next(within)
    except AssertionError:
        return before


async def heard_all(listener: Peer, count: int, heard: dict) -> dict:
    """The listener's last count line once it has ``count`` or nothing more comes for 5 s."""
    while heard["count"] < count:
        now = await anyio.to_thread.run_sync(heard_next, listener, 5.0, heard)
        if now == heard:  # nothing more for 5 s: what came is all
            break
        heard = now
    return heard


@pytest.mark.parametrize(("count", "rate"), [(2000, 1000), (1000, 0)], ids=["1kHz", "unpaced"])
async def test_a_stream_right_after_advertise_reaches_a_ros2_listener_whole(
    server: ServerProcess, ros_env: Path, count: int, rate: int
) -> None:
    # The client publishes at once after its advertisement, so the link's publisher
    # is new: its first samples wait until it has matched the listener the server
    # knows, and none is lost to discovery. 1 kHz for 2 s (twice the listener's
    # history), and a burst as deep as the listener's history (1000), which a
    # listener slower than the burst keeps.
    script = BURST.format(port=server.port, count=count, rate=rate)
    with Peer("count", "/burst", ros_env) as listener:
        async with await anyio.open_process(["python", "-c", script]) as client:
            assert client.stdin is not None and client.stdout is not None
            with anyio.fail_after(60):
                assert await JsonLines(client.stdout).next() == {"sent": count}
            heard = await heard_all(listener, count, {"count": 0})
            await client.stdin.send(b"done\n")
    assert heard == {"count": count, "warm": 0, "ordered": True}
