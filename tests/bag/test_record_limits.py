"""``rwt serve --record`` under clients it does not trust (docs/limits.md, Bags).

- ``--record-max-size``: roslibpy publishes 200 messages of 1 KB; the recorder
  stops before 20 000 bytes with one log line, the bag is complete (rosbags reads
  it), and the server goes on serving a bystander. With ``--record-split`` it
  starts new parts there instead and records everything.
- Abandoned topics: five roslibpy clients each advertise 30 fresh topics,
  publish once and leave; rosapi then lists none of them (today's recorder kept
  every one subscribed, so they stayed in the graph and in every lookup).
- A departed client's type: one client publishes ``/claim`` as a String and
  leaves; another then publishes ``/claim`` as an Int32, and the bag holds both.
"""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
from typing import TYPE_CHECKING

import anyio
import pytest
from rosbags.highlevel import AnyReader

import rwt
from rwt_bag import recorder as recorder_module
from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import RECORDER

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = pytest.mark.anyio

#: With ``stops``, the client waits for the recorder to stop (it lets go of /big)
#: before checking that the server still serves it.
PUBLISH = (
    """
    import json, time
    import roslibpy
"""
    + RECORDER
    + """
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    big = roslibpy.Topic(ros, "/big", "std_msgs/String")
    big.advertise()
    recorder(ros, "/big", on=True)
    for i in range(200):
        big.publish(roslibpy.Message({{"data": "%04d" % i + "x" * 996}}))
        time.sleep(0.005)
    if {stops}:
        recorder(ros, "/big", on=False)
    # a bystander: the server still serves after the recorder stopped
    echo = []
    chat = roslibpy.Topic(ros, "/chatter", "std_msgs/String")
    chat.subscribe(lambda m: echo.append(m["data"]))
    for _ in range(100):  # the first ones may come before the subscription is set up
        chat.publish(roslibpy.Message({{"data": "still here"}}))
        time.sleep(0.05)
        if echo:
            break
    print(json.dumps({{"echo": echo[:1]}}))
    ros.terminate()
"""
)


def _bag_messages(paths: list[Path]) -> list[tuple[str, str, int]]:
    """(topic, type, bytes) of every message of the parts, read by rosbags."""
    with AnyReader(paths) as reader:
        return [(c.topic, c.msgtype, len(raw)) for c, _, raw in reader.messages()]


async def test_max_size_stops_recording_and_the_server_goes_on(tmp_path: Path) -> None:
    bag = tmp_path / "capped"
    args = ("--record", str(bag), "--record-topics", "/big", "--record-max-size", "20000")
    server = ServerProcess(tmp_path, args)
    try:
        out = await run_python(PUBLISH.format(port=server.port, stops=True))
    finally:
        assert server.stop() == 0, server.stderr_text()
    assert json.loads(out.strip().splitlines()[-1]) == {"echo": ["still here"]}
    recorded = _bag_messages([bag])
    assert 0 < len(recorded) < 200
    assert sum(size for _, _, size in recorded) <= 20000
    stopped = [ln for ln in server.stderr_text().splitlines() if "record_stopped" in ln]
    assert len(stopped) == 1, stopped
    assert "reason=max_size limit_bytes=20000" in stopped[0]
    assert f"bag={bag}" in stopped[0]


async def test_max_size_with_split_starts_new_parts(tmp_path: Path) -> None:
    bag = tmp_path / "parts"
    args = ("--record", str(bag), "--record-topics", "/big")
    server = ServerProcess(tmp_path, (*args, "--record-max-size", "20000", "--record-split"))
    try:
        await run_python(PUBLISH.format(port=server.port, stops=False))
    finally:
        assert server.stop() == 0, server.stderr_text()
    parts = [bag, *(bag.with_name(f"parts_{i}") for i in range(1, 100))]
    parts = [p for p in parts if p.exists()]
    assert len(parts) >= 5  # 200 KB of messages in parts of about 20 KB
    assert len(_bag_messages(parts)) == 200
    assert "record_stopped" not in server.stderr_text()


CHURN = (
    """
    import json, time
    import roslibpy
"""
    + RECORDER
    + """
    def client():
        ros = roslibpy.Ros("127.0.0.1", {port})
        ros.run(timeout=20)
        return ros
    anchor = client()  # roslibpy's reactor runs as long as this client
    for round in range(5):
        ros = client()
        topics = [roslibpy.Topic(ros, "/churn_%d_%d" % (round, i), "std_msgs/String")
                  for i in range(30)]
        for t in topics:
            t.advertise()
        recorder(ros, topics[-1].name, on=True)  # one look takes all 30
        for t in topics:
            t.publish(roslibpy.Message({{"data": "x"}}))
        ros.get_topics()  # answered after the publishes before it were taken
        ros.close()
    # /claim as a String from a client that leaves...
    ros = client()
    claim = roslibpy.Topic(ros, "/claim", "std_msgs/String")
    claim.advertise()
    recorder(ros, "/claim", on=True)
    claim.publish(roslibpy.Message({{"data": "first"}}))
    ros.get_topics()
    ros.close()
    # ...then as an Int32 from another
    ros = client()
    for _ in range(50):
        listed = ros.get_topics()
        if "/claim" not in listed and not any(t.startswith("/churn") for t in listed):
            break
        time.sleep(0.1)
    claim = roslibpy.Topic(ros, "/claim", "std_msgs/Int32")
    claim.advertise()
    recorder(ros, "/claim", on=True)
    claim.publish(roslibpy.Message({{"data": 42}}))
    ros.get_topics()
    print(json.dumps({{"listed": listed}}))
    ros.close()
    anchor.terminate()
"""
)


async def test_abandoned_topics_and_types_are_let_go(tmp_path: Path) -> None:
    bag = tmp_path / "churn"
    server = ServerProcess(tmp_path, ("--record", str(bag)))
    try:
        out = await run_python(CHURN.format(port=server.port))
    finally:
        # closing a bag of 150 topics renders its metadata as YAML, seconds on a loaded
        # machine: more than ServerProcess.stop waits (a bound on a hang, not a speed)
        server.proc.send_signal(signal.SIGINT)
        with contextlib.suppress(subprocess.TimeoutExpired):
            server.proc.wait(60)
        assert server.stop() == 0, server.stderr_text()
    listed = json.loads(out.strip().splitlines()[-1])["listed"]
    assert [t for t in listed if t.startswith("/churn")] == []
    assert "/claim" not in listed
    recorded = _bag_messages([bag])
    assert sum(1 for topic, _, _ in recorded if topic.startswith("/churn_")) == 150
    claims = [msgtype for topic, msgtype, _ in recorded if topic == "/claim"]
    assert claims == ["std_msgs/msg/String", "std_msgs/msg/Int32"]
    # one log line per topic and type recorded, not one per comeback
    lines = [ln.split("event=")[1] for ln in server.stderr_text().splitlines()]
    recorded_lines = [ln for ln in lines if ln.startswith("record topic=")]
    assert len(recorded_lines) == len(set(recorded_lines))
    assert "record topic=/claim type=std_msgs/msg/Int32" in recorded_lines


async def test_topics_per_recording_are_capped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(recorder_module, "MAX_RECORD_TOPICS", 5)
    graph = rwt.Graph()
    publishers = [graph.create_publisher(f"/many{i}", "std_msgs/msg/String") for i in range(8)]
    async with rwt.bag.Recorder(graph, tmp_path / "capped", discover_s=0.05) as recorder:
        recorder.discover()
        assert recorder.live_topics == 5
        for publisher in publishers:
            publisher.publish({"data": "x"})
        await anyio.sleep(0.1)
    assert recorder.stats.messages == 5
    assert len(recorder.stats.topics) == 5
