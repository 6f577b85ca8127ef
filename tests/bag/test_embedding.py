"""The embedding API: ``rwt.bag.Recorder`` and ``rwt.bag.Player`` on an in-process graph."""

from __future__ import annotations

import time
from pathlib import Path

import anyio
import pytest
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability

import rwt
from rwt_bag import BagError, BagFormat, SplitPolicy
from rwt_graph.types import Dialect, TypeRegistry

from .bags import CHATTER, write_bag
from .support import read_bag

pytestmark = pytest.mark.anyio


async def _publish(pub: object, count: int, text: str = "m", gap_s: float = 0.0) -> None:
    for i in range(count):
        pub.publish({"data": f"{text}{i}"})  # type: ignore[attr-defined]
        await anyio.sleep(gap_s)


async def test_recorder_patterns_late_topics_and_latching(tmp_path: Path) -> None:
    graph = rwt.Graph()
    chatter = graph.create_publisher("/robot/chatter", "std_msgs/String")
    other = graph.create_publisher("/other", "std_msgs/String")
    static = graph.create_publisher("/robot/static", "std_msgs/String", latch=True)
    static.publish({"data": "latched before the recorder started"})
    async with rwt.bag.Recorder(graph, tmp_path / "bag", topics=["/robot/*"], discover_s=0.05):
        await _publish(chatter, 3)
        await _publish(other, 3)
        late = graph.create_publisher("/robot/late", "std_msgs/String")
        await anyio.sleep(0.2)  # a new topic is found within discover_s
        await _publish(late, 2, "late")
    got = read_bag(tmp_path / "bag")
    assert sorted(got) == ["/robot/chatter", "/robot/late", "/robot/static"]
    assert [m["data"] for m in got["/robot/chatter"]] == ["m0", "m1", "m2"]
    assert [m["data"] for m in got["/robot/late"]] == ["late0", "late1"]
    assert [m["data"] for m in got["/robot/static"]] == ["latched before the recorder started"]
    with AnyReader([tmp_path / "bag"]) as reader:
        durability = {c.topic: c.ext.offered_qos_profiles[0].durability for c in reader.connections}
    assert durability["/robot/static"] == QosDurability.TRANSIENT_LOCAL
    assert durability["/robot/chatter"] == QosDurability.VOLATILE


async def test_recorder_ros1_bag_keeps_latching(tmp_path: Path) -> None:
    graph = rwt.Graph(TypeRegistry(Dialect.ROS1))
    static = graph.create_publisher("/static", "std_msgs/String", latch=True)
    chatter = graph.create_publisher("/chatter", "std_msgs/String")
    async with rwt.bag.Recorder(graph, tmp_path / "run.bag", fmt="ros1"):
        static.publish({"data": "s"})
        await _publish(chatter, 2)
    with AnyReader([tmp_path / "run.bag"]) as reader:
        latching = {c.topic: c.ext.latching for c in reader.connections}
        definitions = {c.topic: c.msgdef.data for c in reader.connections}
    assert latching == {"/static": 1, "/chatter": 0}
    assert definitions["/chatter"].strip() == "string data"


async def test_recorder_splits_by_size(tmp_path: Path) -> None:
    graph = rwt.Graph()
    pub = graph.create_publisher("/big", "std_msgs/String")
    split = SplitPolicy(max_bytes=3000)
    recorder = rwt.bag.Recorder(graph, tmp_path / "part", split=split)
    async with recorder:
        for i in range(10):
            pub.publish({"data": f"{i:04d}" + "x" * 996})
            await anyio.sleep(0.01)
    paths = recorder.paths
    assert paths[0] == tmp_path / "part"
    assert paths[1] == tmp_path / "part_1"
    assert len(paths) >= 3
    numbers = [int(m["data"][:4]) for p in paths for m in read_bag(p)["/big"]]
    assert numbers == list(range(10))
    assert all(len(read_bag(p)["/big"]) <= 4 for p in paths)


async def test_recorder_refuses_a_format_of_the_other_dialect(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="ros1 bag needs a ROS 1 graph"):
        rwt.bag.Recorder(rwt.Graph(), tmp_path / "x.bag", fmt=BagFormat.ROS1)


async def test_recorder_refuses_an_existing_bag(tmp_path: Path) -> None:
    (tmp_path / "taken").mkdir()
    with pytest.raises(BagError, match="cannot create the bag"):
        async with rwt.bag.Recorder(rwt.Graph(), tmp_path / "taken"):
            pass


def _listen(graph: rwt.Graph, topic: str = "/chatter") -> list[tuple[float, str]]:
    got: list[tuple[float, str]] = []
    graph.create_subscription(
        topic, lambda m: got.append((time.monotonic(), m["data"])), "std_msgs/String"
    )
    return got


async def test_player_loop_offset_topics_and_rate(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    graph = rwt.Graph()
    got = _listen(graph)
    tf: list[object] = []
    graph.create_subscription("/tf", tf.append, "tf2_msgs/TFMessage")
    player = rwt.bag.Player(graph, bag, rate=4.0, start_offset=0.5, topics=["/chatter"], loop=True)
    async with player:
        with anyio.fail_after(10):
            while player.stats.loops < 2:
                await anyio.sleep(0.01)
    words = [w for _, w in got]
    once = [f"chatter {i} ✓" for i in range(8, CHATTER)]  # from 0.5 s on
    assert words[: 2 * len(once)] == once + once
    assert tf == []  # not among --topics
    assert graph.topics["/chatter"].publishers == {}  # the player's publishers are gone
    with pytest.raises(BagError, match="rate"):
        rwt.bag.Player(graph, bag, rate=0)


async def test_player_pause_resume_seek(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "sqlite3")
    graph = rwt.Graph()
    got = _listen(graph)
    async with rwt.bag.Player(graph, bag, paused=True, linger=True) as player:
        await anyio.sleep(0.2)
        assert got == [] and player.paused and player.position_s == 0.0
        player.seek(0.9)  # chatter 16 is at 0.9 s
        player.resume()
        with anyio.fail_after(10):
            while len(got) < CHATTER - 16:
                await anyio.sleep(0.01)
        player.seek(0.0)
        with anyio.fail_after(10):
            while len(got) < CHATTER - 16 + 1:
                await anyio.sleep(0.01)
        player.pause()
        paused_at = len(got)
        await anyio.sleep(0.2)
        assert len(got) == paused_at
    words = [w for _, w in got]
    assert words[: CHATTER - 16] == [f"chatter {i} ✓" for i in range(16, CHATTER)]
    assert words[CHATTER - 16] == "chatter 0 ✓"


async def test_player_refuses_a_topic_of_another_type_publishing_nothing(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    graph = rwt.Graph()
    got = _listen(graph)
    graph.create_subscription("/camera", got.append, "std_msgs/String")  # not an Image
    with pytest.raises(BagError, match="cannot play /camera"):
        await rwt.bag.Player(graph, bag).run()
    assert got == []
    assert all(not entry.publishers for entry in graph.topics.values())


async def test_recorded_then_played_in_process(tmp_path: Path) -> None:
    graph = rwt.Graph(TypeRegistry(Dialect.ROS1))
    pub = graph.create_publisher("/chatter", "std_msgs/String")
    async with rwt.bag.Recorder(graph, tmp_path / "r.bag", fmt="ros1"):
        await _publish(pub, 5, gap_s=0.02)
    pub.close()
    replay = rwt.Graph(TypeRegistry(Dialect.ROS1))
    got = _listen(replay)
    await rwt.bag.Player(replay, tmp_path / "r.bag").run()
    assert [w for _, w in got] == [f"m{i}" for i in range(5)]


async def test_recorder_splits_by_duration(tmp_path: Path) -> None:
    graph = rwt.Graph()
    pub = graph.create_publisher("/tick", "std_msgs/String")
    recorder = rwt.bag.Recorder(graph, tmp_path / "t", split=SplitPolicy(max_seconds=0.2))
    async with recorder:
        await _publish(pub, 12, gap_s=0.05)  # about 0.6 s of messages
    assert len(recorder.paths) >= 3
    words = [m["data"] for p in recorder.paths for m in read_bag(p)["/tick"]]
    assert words == [f"m{i}" for i in range(12)]
    for path in recorder.paths:
        with AnyReader([path]) as reader:
            assert reader.duration < 0.2e9 + 1


@pytest.mark.parametrize("fmt", ["mcap", "ros1"])
async def test_each_split_part_repeats_the_latched_topics(tmp_path: Path, fmt: str) -> None:
    """--repeat-latched (the default): a part played alone has its /tf_static."""
    ros1 = fmt == "ros1"
    graph = rwt.Graph(TypeRegistry(Dialect.ROS1)) if ros1 else rwt.Graph()
    static = graph.create_publisher("/static", "std_msgs/String", latch=True)
    pub = graph.create_publisher("/big", "std_msgs/String")
    path = tmp_path / ("part.bag" if ros1 else "part")
    recorder = rwt.bag.Recorder(
        graph, path, fmt="ros1" if ros1 else "mcap", split=SplitPolicy(max_bytes=3000)
    )
    async with recorder:
        static.publish({"data": "map"})
        await anyio.sleep(0.05)
        for i in range(10):
            pub.publish({"data": f"{i:04d}" + "x" * 996})
            await anyio.sleep(0.01)
    assert len(recorder.paths) >= 3
    for part in recorder.paths:
        assert [m["data"] for m in read_bag(part)["/static"]] == ["map"], part
    numbers = [int(m["data"][:4]) for p in recorder.paths for m in read_bag(p)["/big"]]
    assert numbers == list(range(10))  # the other topics are not repeated
