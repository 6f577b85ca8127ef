"""Bad bags: a clear error naming the file, topic and type, and nothing published.

Truncated and corrupt bags (ROS 1, ROS 2 sqlite3 and MCAP, written by rosbags),
a bag with a type the graph does not know, a bag whose definition of a
shipped type differs, and a bag with no topic to play (every name invalid, or
none matching ``topics``): the in-process ``Player`` raises ``BagError`` before
any message reaches a subscriber and leaves no publisher behind; ``rwt serve
--play``, ``rwt play`` and ``rwt bag info`` exit 1 with one line.
"""

from __future__ import annotations

from pathlib import Path

import anyio
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from rwt_bag import BagError, Player
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from tests.support.cli import run_rwt

from .bags import write_bag
from .hostile import bad_names

FORMATS = ["mcap", "sqlite3", "ros1"]


def _storage_file(bag: Path) -> Path:
    if bag.is_file():
        return bag
    (found,) = [f for f in bag.iterdir() if f.suffix in (".mcap", ".db3")]
    return found


def truncated(tmp_path: Path, fmt: str) -> Path:
    bag = write_bag(tmp_path / "robot", fmt)
    file = _storage_file(bag)
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])
    return bag


def corrupt(tmp_path: Path, fmt: str) -> Path:
    """The length of the sixth /chatter string made 2^31 - 1: past the message's end."""
    bag = write_bag(tmp_path / "robot", fmt)
    file = _storage_file(bag)
    data = bytearray(file.read_bytes())
    at = data.index("chatter 5 ✓".encode())
    data[at - 4 : at] = b"\xff\xff\xff\x7f"
    file.write_bytes(bytes(data))
    return bag


def graph_for(fmt: str) -> tuple[Graph, list[dict]]:
    graph = Graph(TypeRegistry(Dialect.ROS1 if fmt == "ros1" else Dialect.ROS2))
    received: list[dict] = []
    for topic, type_name in [("/chatter", "std_msgs/String"), ("/tf_static", "tf2_msgs/TFMessage")]:
        graph.create_subscription(topic, received.append, type_name)
    return graph, received


def play(graph: Graph, bag: Path) -> None:
    async def main() -> None:
        with anyio.fail_after(20):
            await Player(graph, bag).run()

    anyio.run(main)


def assert_nothing_published(graph: Graph, received: list[dict]) -> None:
    assert received == []
    for entry in graph.topics.values():
        assert not entry.publishers, f"{entry.name} still has a publisher"
        assert entry.latched is None


@pytest.mark.parametrize("fmt", FORMATS)
def test_truncated_bag(tmp_path: Path, fmt: str) -> None:
    bag = truncated(tmp_path, fmt)
    graph, received = graph_for(fmt)
    with pytest.raises(BagError, match=f"cannot read {bag}"):
        play(graph, bag)
    assert_nothing_published(graph, received)


@pytest.mark.parametrize("fmt", FORMATS)
def test_corrupt_message_found_before_publishing(tmp_path: Path, fmt: str) -> None:
    bag = corrupt(tmp_path, fmt)
    graph, received = graph_for(fmt)
    with pytest.raises(BagError) as caught:
        play(graph, bag)
    text = str(caught.value)
    assert str(bag) in text
    assert "a message of /chatter (type std_msgs/msg/String)" in text
    assert "cannot be decoded" in text
    assert_nothing_published(graph, received)


def _custom_bag(path: Path, topic: str, msgtype: str, text: str) -> Path:
    store = get_typestore(Stores.EMPTY)  # the bag's own definitions, not rosbags' shipped ones
    store.register(get_types_from_msg("int32 data\n", "std_msgs/msg/Int32"))
    store.register(get_types_from_msg(text, msgtype))
    plain = store.types["std_msgs/msg/Int32"]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        ok = writer.add_connection("/ok", "std_msgs/msg/Int32", typestore=store)
        writer.write(ok, 1, store.serialize_cdr(plain(data=1), "std_msgs/msg/Int32"))
        odd = writer.add_connection(topic, msgtype, typestore=store)
        fields = {"data": 3} if "data" in text else {"x": 3}
        writer.write(odd, 2, store.serialize_cdr(store.types[msgtype](**fields), msgtype))
    return path


def test_unknown_type(tmp_path: Path) -> None:
    bag = _custom_bag(tmp_path / "custom", "/thing", "my_pkg/msg/Thing", "int32 x\n")
    graph = Graph()
    with pytest.raises(BagError) as caught:
        Player(graph, bag)
    text = str(caught.value)
    assert "topic /thing (type my_pkg/msg/Thing)" in text
    assert "unknown" in text.lower()
    assert graph.topics == {}


def test_definition_conflicting_with_a_shipped_one(tmp_path: Path) -> None:
    bag = _custom_bag(tmp_path / "conflict", "/words", "std_msgs/msg/String", "int32 data\n")
    graph = Graph()
    with pytest.raises(BagError) as caught:
        Player(graph, bag)
    text = str(caught.value)
    assert "topic /words (type std_msgs/msg/String)" in text
    assert "definition differs" in text
    assert graph.topics == {}


def test_serve_play_refuses_a_corrupt_bag_before_listening(tmp_path: Path) -> None:
    bag = corrupt(tmp_path, "mcap")
    result = run_rwt("serve", "--port", "0", "--play", str(bag), cwd=tmp_path)
    assert result.returncode == 1
    assert "listening" not in result.stdout
    # stderr also has the server's log lines; the error is one line of its own
    (line,) = [ln for ln in result.stderr.splitlines() if ln.startswith("rwt serve: ")]
    assert "/chatter (type std_msgs/msg/String)" in line


def test_play_and_info_refuse_a_truncated_bag(tmp_path: Path) -> None:
    bag = truncated(tmp_path, "ros1")
    for args in (("play", "--port", "0", "--dialect", "ros1", str(bag)), ("bag", "info", str(bag))):
        result = run_rwt(*args, cwd=tmp_path)
        assert result.returncode == 1, result
        assert "listening" not in result.stdout
        (line,) = result.stderr.strip().splitlines()
        assert line.startswith(
            f"rwt {args[0] if args[0] == 'play' else 'bag info'}: cannot read {bag}"
        )


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_bag_with_no_valid_name_to_play_is_refused(tmp_path: Path, fmt: str) -> None:
    graph, received = graph_for(fmt)
    only_bad = bad_names(tmp_path / "bad", fmt, ("a b", "1x"), chatter=False)
    with pytest.raises(BagError, match=f"cannot play {only_bad}: no topic to play has a valid"):
        Player(graph, only_bad)
    mixed = bad_names(tmp_path / "mixed", fmt, ("/x y", "/x.z"))
    with pytest.raises(BagError, match=r"\(2 skipped: '/x y','/x.z'\)"):
        Player(graph, mixed, topics=["/x*"])  # the only topics chosen are invalid
    assert_nothing_published(graph, received)


def test_topics_matching_nothing_are_refused(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    result = run_rwt("play", "--port", "0", "--topics", "/nothing,/x*", str(bag), cwd=tmp_path)
    assert result.returncode == 1, result
    assert "listening" not in result.stdout
    (line,) = result.stderr.strip().splitlines()
    assert line == (
        f"rwt play: cannot play {bag}: none of its 6 topics matches the topics to play "
        "('/nothing','/x*')"
    )
