"""Playback options as `ros2 bag play` names them: --remap, --delay, --playback-duration,
--playback-until-sec (docs/record-replay.md), in process and through `rwt play` to roslibpy."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import anyio
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

import rwt
from rwt_bag.errors import BagError
from tests.integration.client_harness import REPO
from tests.support.cli import RWT, run_rwt
from tests.support.realclients import run_python

from .hostile import bad_names

START_NS = 1_000_000_000
SPACING_NS = 2_000_000  # a message every 2 ms of bag time
COUNT = 300


def write_chatter(path: Path) -> Path:
    """A bag written by rosbags (MCAP): /chatter m0..m299, 2 ms apart from 1 s."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    String = store.types["std_msgs/msg/String"]
    with Ros2Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        for i in range(COUNT):
            data = store.serialize_cdr(String(data=f"m{i}"), "std_msgs/msg/String")
            writer.write(conn, START_NS + i * SPACING_NS, data)
    return path


async def play(bag: Path, topic: str, **options: object) -> tuple[list[str], float]:
    """What a subscriber of ``topic`` got, and when the first came (s after the start)."""
    graph = rwt.Graph()
    got: list[str] = []
    first: list[float] = []

    def on(msg: dict[str, str]) -> None:
        got.append(msg["data"])
        if not first:
            first.append(time.monotonic())

    graph.create_subscription(topic, on, "std_msgs/String")
    player = rwt.bag.Player(graph, bag, rate=4.0, check=False, **options)  # type: ignore[arg-type]
    started = time.monotonic()
    with anyio.fail_after(60):
        await player.run()
    return got, (first[0] - started) if first else float("nan")


@pytest.mark.anyio
async def test_remap_publishes_the_bag_topic_under_its_new_name_only(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    got, _ = await play(bag, "/talk", remap={"/chatter": "/talk"})
    assert got == [f"m{i}" for i in range(COUNT)]
    untouched, _ = await play(bag, "/chatter", remap={"/chatter": "/talk"})
    assert untouched == []


@pytest.mark.anyio
async def test_playback_duration_and_until_end_the_playback(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    got, _ = await play(bag, "/chatter", duration=0.2)  # bag time: m0..m100
    assert got == [f"m{i}" for i in range(101)]
    got, _ = await play(bag, "/chatter", until_ns=START_NS + 50 * SPACING_NS)
    assert got == [f"m{i}" for i in range(51)]
    # from a start offset, the duration counts from there
    got, _ = await play(bag, "/chatter", start_offset=0.1, duration=0.1)
    assert got == [f"m{i}" for i in range(50, 101)]


@pytest.mark.anyio
async def test_delay_holds_the_first_message(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    got, first_s = await play(bag, "/chatter", delay=0.5)
    assert len(got) == COUNT
    assert first_s >= 0.5


def test_bad_values_are_refused_with_one_line(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    with pytest.raises(BagError, match="the delay must be a finite number of seconds"):
        rwt.bag.Player(rwt.Graph(), bag, delay=float("nan"))
    with pytest.raises(BagError, match="the duration must be a finite number of seconds"):
        rwt.bag.Player(rwt.Graph(), bag, duration=-1.0)
    with pytest.raises(BagError, match="cannot play /chatter as bad name: invalid name"):
        rwt.bag.Player(rwt.Graph(), bag, remap={"/chatter": "bad name"})


def test_rwt_play_refuses_a_remap_that_is_no_rule_or_no_name(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    result = run_rwt("play", str(bag), "--port", "0", "--remap", "/chatter", cwd=tmp_path)
    assert result.returncode == 2
    assert "'/chatter' is not OLD:=NEW" in result.stderr
    result = run_rwt("play", str(bag), "--port", "0", "--remap", "/chatter:=bad name", cwd=tmp_path)
    assert result.returncode == 1
    assert "cannot play /chatter as bad name" in result.stderr


LISTEN = """
got = []
roslibpy.Topic(ros, "/talk", "std_msgs/msg/String").subscribe(lambda m: got.append(m["data"]))
# the server takes a connection's ops in order: the subscription is in before resume
resume = roslibpy.Service(ros, "/rwt/player/resume", "std_srvs/srv/Trigger")
resume.call(roslibpy.ServiceRequest({}), timeout=20)
wait_for(lambda: len(got) >= 101)
time.sleep(0.5)  # nothing more comes: the playback ended at 0.2 s of bag time
print(json.dumps(got))
ros.terminate()
"""


@pytest.mark.anyio
async def test_rwt_play_remaps_and_ends_for_a_roslibpy_subscriber(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    # started paused, so a slow client misses nothing; it resumes once subscribed
    args = ["--remap", "/chatter:=/talk", "--delay", "0.5", "--playback-duration", "0.2"]
    args.append("--start-paused")
    command = [*RWT, "play", str(bag), "--port", "0", *args]
    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}
    rwt_play = subprocess.Popen(  # noqa: ASYNC220 - its output is read in the test's thread
        command, stdout=subprocess.PIPE, text=True, cwd=tmp_path, env=env
    )
    with rwt_play:
        assert rwt_play.stdout is not None
        line = rwt_play.stdout.readline()
        assert line.startswith("listening on ws://127.0.0.1:"), line
        port = int(line.rsplit(":", 1)[1])
        prelude = f"""
import json, time
import roslibpy
ros = roslibpy.Ros("127.0.0.1", {port})
ros.run(timeout=20)

def wait_for(predicate, within=20.0):
    end = time.monotonic() + within
    while not predicate() and time.monotonic() < end:
        time.sleep(0.05)
"""
        got = json.loads((await run_python(prelude + LISTEN)).strip().splitlines()[-1])
        assert rwt_play.wait(timeout=30) == 0
    assert got == [f"m{i}" for i in range(101)]


@pytest.mark.anyio
async def test_prefix_puts_every_topic_under_a_namespace_after_the_remap(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    got, _ = await play(bag, "/sim/chatter", prefix="sim/")
    assert got == [f"m{i}" for i in range(COUNT)]
    got, _ = await play(bag, "/sim/talk", prefix="/sim", remap={"/chatter": "/talk"})
    assert len(got) == COUNT
    got, _ = await play(bag, "/sim/talk", prefix="/sim", remap={"/chatter": "talk"})
    assert len(got) == COUNT
    relative = bad_names(tmp_path / "relative", "mcap", ("relative",), chatter=False)
    got, _ = await play(relative, "/sim/relative", prefix="/sim")  # not /simrelative
    assert got == ["hostile"]
    with pytest.raises(BagError, match="the prefix '/a b' is not a namespace"):
        rwt.bag.Player(rwt.Graph(), bag, prefix="/a b")


@pytest.mark.anyio
async def test_waiting_for_subscribers_gives_up_at_its_timeout(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    bag = write_chatter(tmp_path / "bag")
    player = rwt.bag.Player(
        rwt.Graph(), bag, rate=4.0, check=False, wait_for_subscribers=True, wait_timeout=0.2
    )
    with anyio.fail_after(60):
        await player.run()
    assert player.stats.messages == COUNT  # played anyway, into no subscriber
    (line,) = [r.getMessage() for r in caplog.records if "play_wait_timeout" in r.getMessage()]
    assert "topics=/chatter" in line


LATE = """
import json, time
import roslibpy
ros = roslibpy.Ros("127.0.0.1", {port})
ros.run(timeout=20)
time.sleep(1.0)  # the bag (0.6 s) would have played by now without the wait
got = []
roslibpy.Topic(ros, "/sim/chatter", "std_msgs/msg/String").subscribe(
    lambda m: got.append(m["data"])
)
end = time.monotonic() + 30
while len(got) < {count} and time.monotonic() < end:
    time.sleep(0.05)
print(json.dumps(got))
ros.terminate()
"""


@pytest.mark.anyio
async def test_rwt_play_waits_for_a_late_roslibpy_subscriber(tmp_path: Path) -> None:
    bag = write_chatter(tmp_path / "bag")
    args = ["--prefix", "/sim", "--wait-for-subscribers"]
    command = [*RWT, "play", str(bag), "--port", "0", *args]
    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}
    rwt_play = subprocess.Popen(  # noqa: ASYNC220 - its output is read in the test's thread
        command, stdout=subprocess.PIPE, text=True, cwd=tmp_path, env=env
    )
    with rwt_play:
        assert rwt_play.stdout is not None
        line = rwt_play.stdout.readline()
        assert line.startswith("listening on ws://127.0.0.1:"), line
        port = int(line.rsplit(":", 1)[1])
        out = await run_python(LATE.format(port=port, count=COUNT))
        assert rwt_play.wait(timeout=30) == 0
    assert json.loads(out.strip().splitlines()[-1]) == [f"m{i}" for i in range(COUNT)]
