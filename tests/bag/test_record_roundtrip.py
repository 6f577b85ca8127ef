"""Round trips: roslibpy publishes into a live `rwt serve --record`; rosbags reads the bag back.

Every field of every message is compared (arrays, nested messages, times and
strings with non-ASCII text), in ROS 2 bags (MCAP and sqlite3) and ROS 1 bags.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import RECORDER, expected, read_bag, sample_messages

pytestmark = pytest.mark.anyio

CASES = [
    pytest.param("mcap", False, "rt", id="ros2-mcap"),
    pytest.param("sqlite3", False, "rt", id="ros2-sqlite3"),
    pytest.param("ros1", True, "rt.bag", id="ros1"),
]


def roslibpy_publisher(port: int, messages: list, repeat: int) -> str:
    """A roslibpy script: advertise, wait for the recorder to subscribe, publish each message."""
    return (
        "\n    import time\n    import roslibpy\n"
        + RECORDER.format()
        + f"""
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    messages = {messages!r}
    topics = {{}}
    for name, type_name, _ in messages:
        topics[name] = roslibpy.Topic(ros, name, type_name)
        topics[name].advertise()
    recorder(ros, name, on=True)  # the last one: the look that took it took all
    for _ in range({repeat}):
        for name, _, msg in messages:
            topics[name].publish(roslibpy.Message(msg))
            time.sleep(0.005)
    ros.get_topics()  # answered once the publishes before it were taken
    ros.terminate()
    print("done")
"""
    )


@pytest.mark.parametrize(("fmt", "ros1", "name"), CASES)
async def test_roslibpy_into_serve_record(tmp_path: Path, fmt: str, ros1: bool, name: str) -> None:
    bag = tmp_path / name
    args = ["--record", str(bag), "--record-topics", "/rt/*", "--record-format", fmt]
    if ros1:
        args += ["--dialect", "ros1"]
    server = ServerProcess(tmp_path, tuple(args))
    try:
        messages = sample_messages(ros1)
        out = await run_python(roslibpy_publisher(server.port, messages, repeat=3))
        assert out.split() == ["done"]
    finally:
        code = server.stop()
    assert code == 0, server.stderr_text()

    recorded = read_bag(bag)
    assert sorted(recorded) == sorted(topic for topic, _, _ in messages)
    for topic, _, msg in messages:
        want = expected(msg)
        got = recorded[topic]
        assert len(got) == 3, topic
        for each in got:
            each.pop("__msgtype__", None)
            _strip_msgtype(each)
            assert each == want, topic


def _strip_msgtype(value: object) -> None:
    if isinstance(value, dict):
        value.pop("__msgtype__", None)
        for v in value.values():
            _strip_msgtype(v)
    elif isinstance(value, list):
        for v in value:
            _strip_msgtype(v)
