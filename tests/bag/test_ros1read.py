"""The ``ros1-chunk-read`` shortcut reads what rosbags' own reader reads.

Bags written by rosbags' ROS 1 writer (several connections, equal times,
connection records inside chunks, bz2 and lz4 chunks, many chunks) are read
both ways; a record that is not what the index says is refused.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Ros1Writer

from rwt_bag import ros1read
from rwt_bag.errors import BagError
from rwt_bag.reader import BagSource
from rwt_bag.ros1read import chunk_messages
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.shortcuts import ENV_VAR

from .bags import T0, typestore, write_bag

REPO = Path(__file__).resolve().parents[2]
COMPRESSIONS = [None, Ros1Writer.CompressionFormat.BZ2, Ros1Writer.CompressionFormat.LZ4]


@pytest.fixture(autouse=True)
def _shortcut_on(monkeypatch: pytest.MonkeyPatch) -> None:
    """The shortcut on, whatever ``RWT_NO_SHORTCUTS`` says (each test compares both ways)."""
    monkeypatch.setattr(ros1read, "_ENABLED", True)


def _busy_bag(path: Path, compression: Ros1Writer.CompressionFormat | None) -> Path:
    """Three topics, 600 strings in small chunks, some at the same time, one topic late."""
    store = typestore(ros1=True)
    cls = store.types["std_msgs/msg/String"]
    writer = Ros1Writer(path)
    if compression is not None:
        writer.set_compression(compression)
    writer.chunk_threshold = 2048  # many chunks
    with writer:
        conns = [
            writer.add_connection(f"/t{i}", "std_msgs/msg/String", typestore=store)
            for i in range(3)
        ]
        for i in range(600):
            conn = conns[i % 2] if i < 300 else conns[i % 3]
            ns = T0 + (i // 2) * 1000  # pairs at one time
            writer.write(
                conn,
                ns,
                store.serialize_ros1(cls(data=f"m{i} " + "x" * (i % 50)), "std_msgs/msg/String"),
            )
    return path


def _both(
    path: Path, pick: slice = slice(None), start: int | None = None
) -> tuple[list[object], list[object]]:
    with AnyReader([path]) as reader:
        conns = reader.connections[pick]
        ours = chunk_messages(reader, conns, start)
        assert ours is not None
        fast = [(c.id, ns, bytes(raw)) for c, ns, raw in ours]
        general = [
            (c.id, ns, bytes(raw)) for c, ns, raw in reader.messages(connections=conns, start=start)
        ]
    return fast, general


@pytest.mark.parametrize("compression", COMPRESSIONS, ids=["none", "bz2", "lz4"])
def test_reads_what_rosbags_reads(
    tmp_path: Path, compression: Ros1Writer.CompressionFormat | None
) -> None:
    bag = _busy_bag(tmp_path / "busy.bag", compression)
    fast, general = _both(bag)
    assert len(general) == 600
    assert fast == general
    fast, general = _both(bag, slice(1, 3), start=T0 + 100_000)  # some topics, from a time on
    assert fast == general
    assert general


def test_reads_the_replay_bag_as_rosbags(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "std", "ros1")  # the replay tests' bag: six types
    fast, general = _both(bag)
    assert fast == general


def test_not_for_ros2_bags(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "std", "mcap")
    with AnyReader([bag]) as reader:
        assert chunk_messages(reader, reader.connections, None) is None


def test_a_record_unlike_its_index_is_refused(tmp_path: Path) -> None:
    bag = _busy_bag(tmp_path / "busy.bag", None)
    data = bytearray(bag.read_bytes())
    at = data.index(b"op=\x02")  # the first message record's op: now a connection record's
    data[at + 3] = 0x05  # a chunk-info op: not a message
    bag.write_bytes(bytes(data))
    with AnyReader([bag]) as reader, pytest.raises(BagError, match="expected a message record"):
        list(chunk_messages(reader, reader.connections, None) or ())


def test_the_player_reads_the_same_messages_with_the_shortcut_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    bag = write_bag(tmp_path / "std", "ros1")
    registry = TypeRegistry(Dialect.ROS1)
    seen = []
    for on in (True, False):
        monkeypatch.setattr(ros1read, "_ENABLED", on)
        source = BagSource([bag], registry)
        try:
            seen.append([(t.topic, ns, msg, record) for t, ns, msg, record in source.messages()])
        finally:
            source.close()
    assert seen[0] == seen[1]
    assert len(seen[0]) == 37


def test_rwt_no_shortcuts_switches_it_off(tmp_path: Path) -> None:
    bag = _busy_bag(tmp_path / "busy.bag", None)
    probe = (
        "import sys; from pathlib import Path; from rosbags.highlevel import AnyReader; "
        "from rwt_bag.ros1read import chunk_messages; "
        "r = AnyReader([Path(sys.argv[1])]); r.open(); "
        "print(chunk_messages(r, r.connections, None) is None)"
    )
    used = {}
    for value in ("0", "ros1-chunk-read"):
        env = {**os.environ, "PYTHONPATH": str(REPO / "src"), ENV_VAR: value}
        result = subprocess.run(
            [sys.executable, "-c", probe, str(bag)],
            env=env,
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        )
        used[value] = result.stdout.strip()
    assert used == {"0": "False", "ros1-chunk-read": "True"}
