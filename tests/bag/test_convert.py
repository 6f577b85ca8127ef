"""``rwt bag convert`` and ``rwt bag filter`` (docs/record-replay.md, Converting and filtering).

A bag written by rosbags (MCAP: a String topic, a PointStamped topic, a latched
topic) goes MCAP -> sqlite3 -> ROS 1 -> MCAP through ``rwt bag convert``; rosbags
reads every step back, and Debian's real ``rosbag`` (python3-rosbag) reads the
ROS 1 bag: the same values, the header seq 0, the latched topic with
``latching=1``. ``rwt bag filter`` keeps topics by glob, regular expression and
exclusion, and a time range. Bad input is refused with one line, and nothing is
left at OUT.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
from rosbags.convert.converter import LATCH
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from tests.integration.client_harness import REPO
from tests.support.cli import RWT, invoke_rwt

START_NS = 1_000_000_000
STEP_NS = 100_000_000
COUNT = 20
ROSBAG_PYTHON = "/usr/bin/python3"


def write_source(path: Path) -> Path:
    """An MCAP bag by rosbags: /chatter and /point every 0.1 s from 1 s, /latched once."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    string, stamped = types["std_msgs/msg/String"], types["geometry_msgs/msg/PointStamped"]
    header, time, point = (
        types["std_msgs/msg/Header"],
        types["builtin_interfaces/msg/Time"],
        types["geometry_msgs/msg/Point"],
    )
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        chatter = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        points = writer.add_connection("/point", "geometry_msgs/msg/PointStamped", typestore=store)
        latched = writer.add_connection(
            "/latched", "std_msgs/msg/String", typestore=store, offered_qos_profiles=LATCH
        )
        writer.write(
            latched, START_NS, store.serialize_cdr(string(data="once"), "std_msgs/msg/String")
        )
        for i in range(COUNT):
            ns = START_NS + i * STEP_NS
            text = string(data=f"m{i}")
            writer.write(chatter, ns, store.serialize_cdr(text, "std_msgs/msg/String"))
            msg = stamped(
                header=header(stamp=time(sec=i, nanosec=5), frame_id="map"),
                point=point(x=float(i), y=2.0, z=3.0),
            )
            writer.write(points, ns, store.serialize_cdr(msg, "geometry_msgs/msg/PointStamped"))
    return path


def contents(bag: Path) -> list[tuple[str, int, Any]]:
    """(topic, time, the message's values) of every message, read by rosbags."""
    out = []
    with AnyReader([bag]) as reader:
        for conn, ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            value = (
                (msg.header.stamp.sec, msg.header.frame_id, msg.point.x)  # type: ignore[attr-defined]
                if conn.topic == "/point"
                else msg.data  # type: ignore[attr-defined]
            )
            out.append((conn.topic, ns, value))
    return sorted(out, key=lambda item: (item[1], item[0]))


def rwt(*args: str) -> tuple[int, str]:
    """``rwt ARGS`` in-process: its exit code and output."""
    result = invoke_rwt(*args)
    return result.exit_code, result.output


ROSBAG_READ = """
import json, sys
import rosbag
with rosbag.Bag(sys.argv[1]) as bag:
    latching = {c.topic: c.header.get("latching", b"").decode() for c in bag._get_connections()}
    out = []
    for topic, msg, t in bag.read_messages():
        if topic == "/point":
            value = [msg.header.stamp.secs, msg.header.frame_id, msg.point.x, msg.header.seq]
        else:
            value = msg.data
        out.append([topic, t.to_nsec(), value])
print(json.dumps({"latching": latching, "messages": out}))
"""


def test_convert_mcap_sqlite3_ros1_and_back(tmp_path: Path) -> None:
    source = write_source(tmp_path / "source")
    want = contents(source)
    assert len(want) == 2 * COUNT + 1
    assert rwt("bag", "convert", str(source), str(tmp_path / "sq"), "--format", "sqlite3") == (
        0,
        f"wrote {len(want)} messages on 3 topics -> {tmp_path / 'sq'}\n",
    )
    assert list((tmp_path / "sq").glob("*.db3"))
    assert contents(tmp_path / "sq") == want
    ros1 = tmp_path / "run.bag"
    # as a user runs it: the module's command line, this checkout's code
    done = subprocess.run(
        [*RWT, "bag", "convert", str(tmp_path / "sq"), str(ros1)],
        capture_output=True,
        text=True,
        timeout=60,
        env={"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"},
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert contents(ros1) == want
    code, _ = rwt("bag", "convert", str(ros1), str(tmp_path / "back"))
    assert code == 0
    assert list((tmp_path / "back").glob("*.mcap"))
    assert contents(tmp_path / "back") == want


@pytest.mark.skipif(
    shutil.which("rosbag") is None or not Path(ROSBAG_PYTHON).exists(),
    reason="Debian's rosbag (python3-rosbag) is not installed",
)
def test_debian_rosbag_reads_the_converted_ros1_bag(tmp_path: Path) -> None:
    source = write_source(tmp_path / "source")
    ros1 = tmp_path / "run.bag"
    assert rwt("bag", "convert", str(source), str(ros1))[0] == 0
    done = subprocess.run(
        [ROSBAG_PYTHON, "-c", ROSBAG_READ, str(ros1)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    if done.returncode and "No module named 'rosbag'" in done.stderr:
        pytest.skip("Debian's python3-rosbag is not importable")
    assert done.returncode == 0, done.stderr
    read = json.loads(done.stdout)
    assert read["latching"] == {"/chatter": "0", "/point": "0", "/latched": "1"}
    want = [
        [topic, ns, [*value, 0] if topic == "/point" else value]  # the header's seq: 0
        for topic, ns, value in contents(source)
    ]
    assert sorted(read["messages"], key=lambda m: (m[1], m[0])) == want


def test_filter_by_topics_regex_exclusions_and_time(tmp_path: Path) -> None:
    source = write_source(tmp_path / "source")
    out = tmp_path / "points"
    code, said = rwt("bag", "filter", str(source), str(out), "--topics", "/point")
    assert code == 0, said
    assert {topic for topic, _, _ in contents(out)} == {"/point"}
    out = tmp_path / "window"
    code, said = rwt("bag", "filter", str(source), str(out), "--start", "0.5", "--end", "1.0")
    assert code == 0, said
    got = contents(out)
    assert {ns for _, ns, _ in got} == {START_NS + i * STEP_NS for i in range(5, 11)}
    assert [value[2] for topic, _, value in got if topic == "/point"] == [
        5.0,
        6.0,
        7.0,
        8.0,
        9.0,
        10.0,
    ]
    out = tmp_path / "regex"
    args = ["-e", "^/(chatter|latched)$", "--exclude", "hat", "--exclude-topics", "/none"]
    code, said = rwt("bag", "filter", str(source), str(out), *args)
    assert code == 0, said
    assert [value for _, _, value in contents(out)] == ["once"]  # /chatter left out again
    assert list(out.glob("*.mcap"))  # the input's format


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("convert", "{tmp}/missing", "{tmp}/x"), "cannot read"),
        (("convert", "{src}", "{src}"), "exists already"),
        (("convert", "{src}", "{tmp}/x", "--format", "ros1"), "a ros1 bag is a file named *.bag"),
        (("convert", "{src}", "{tmp}/x.bag", "--format", "mcap"), "a folder, not *.bag"),
        (("filter", "{src}", "{tmp}/x", "--topics", "/nothing"), "no topic matches"),
        (("filter", "{src}", "{tmp}/x", "--start", "2", "--end", "1"), "is before --start"),
        (("filter", "{tmp}", "{tmp}/x"), "without an .mcap or .db3 file"),
    ],
)
def test_bad_input_is_refused_with_one_line(
    tmp_path: Path, args: tuple[str, ...], says: str
) -> None:
    source = write_source(tmp_path / "source")
    code, said = rwt("bag", *(a.format(tmp=tmp_path, src=source) for a in args))
    assert code == 1, said
    (line,) = said.splitlines()
    assert line.startswith(f"rwt bag {args[0]}: ")
    assert says in line
    assert not (tmp_path / "x").exists()
    assert not (tmp_path / "x.bag").exists()
