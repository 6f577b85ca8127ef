"""Topic names in bags follow the rules of a client's ``advertise`` (docs/limits.md).

A bag (MCAP, sqlite3 or ROS 1) holding ``/chatter`` and topics named ``/x y``,
``/../..``, with U+202E, and 5000 characters long: ``rwt serve --play`` logs one
line naming the bag, the count and the skipped topics, rosapi lists none of
them, and roslibpy receives ``/chatter``. ``rwt bag info`` prints them escaped,
cut and marked as not played. A bag none of whose topics has a valid name is
refused by ``rwt serve --play`` and ``rwt play`` with one line and exit code 1;
so are names an attacker picks (empty, ``//``, ``~``, 5000 characters, a
newline, NUL, U+202E, a lone surrogate, bytes that are not UTF-8), never
with a traceback.
"""

from __future__ import annotations

import json
import subprocess
from typing import TYPE_CHECKING

import pytest

from tests.integration.client_harness import REPO, ServerProcess
from tests.support.cli import RWT, run_rwt
from tests.support.realclients import run_python

from .hostile import BAD_NAMES, bad_names, escaped_names, undecodable_name

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = pytest.mark.anyio

FORMATS = ["mcap", "sqlite3", "ros1"]
#: Names of a bag none of which can be played, and how the error line lists them.
INVALID = ("a b", "1x", "/bad name")
INVALID_LISTED = "3 skipped: 'a b','1x','/bad name'"
#: Names an attacker picks: each is refused, escaped and cut where it is shown.
ODD = ("", "//", "~", "/" + "n" * 5000, "/a\nb", "\x00", "/a\u202eb")

CLIENT = """
    import json, time
    import roslibpy
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    got = []
    # the server takes a connection's ops in order: the subscription is in before the seek
    roslibpy.Topic(ros, "/chatter", "std_msgs/String").subscribe(lambda m: got.append(m["data"]))
    seek = roslibpy.Service(ros, "/rwt/player/seek", "rwt_msgs/Seek")
    seek.call(roslibpy.ServiceRequest({{"offset": 0.0}}), timeout=10)
    for _ in range(100):
        if got:
            break
        time.sleep(0.1)
    print(json.dumps({{"topics": ros.get_topics(), "chatter": got}}))
    ros.terminate()
"""


@pytest.mark.parametrize("fmt", ["mcap", "sqlite3", "ros1"])
async def test_bad_topic_names_are_not_published(tmp_path: Path, fmt: str) -> None:
    bag = bad_names(tmp_path / "names", fmt)
    dialect = ("--dialect", "ros1") if fmt == "ros1" else ()
    server = ServerProcess(tmp_path, ("--play", str(bag), *dialect))
    try:
        out = await run_python(CLIENT.format(port=server.port))
    finally:
        assert server.stop() == 0, server.stderr_text()
    got = json.loads(out.strip().splitlines()[-1])
    assert "/chatter" in got["topics"]
    for name in BAD_NAMES:
        assert name not in got["topics"]
    assert got["chatter"] == ["hostile"]
    lines = [ln for ln in server.stderr_text().splitlines() if "bag_topics_skipped" in ln]
    assert len(lines) == 1, lines
    assert f"bag={bag}" in lines[0]
    assert f"count={len(BAD_NAMES)}" in lines[0]
    shown = "'/x y','/../..','/a\\u202eb','/" + "n" * 56 + "...'"
    assert f"topics={shown} reason=" in lines[0]


def test_bag_info_escapes_and_marks_bad_names(tmp_path: Path) -> None:
    bag = bad_names(tmp_path / "names", "mcap")
    result = subprocess.run(
        [*RWT, "bag", "info", str(bag)],
        capture_output=True,
        text=True,
        timeout=60,
        env={"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"},
        check=False,
    )
    assert result.returncode == 0, result.stderr
    rows = [ln for ln in result.stdout.splitlines() if ln.startswith("  Topic: ")]
    assert len(rows) == 1 + len(BAD_NAMES)
    assert "\u202e" not in result.stdout  # escaped, not written to the terminal
    assert all(len(row) < 300 for row in rows)
    marked = [row for row in rows if "(invalid name, not played)" in row]
    assert len(marked) == len(BAD_NAMES)
    assert "  Topic: '/a\\u202eb' (invalid name, not played) |" in result.stdout


def _play(command: str, bag: Path, fmt: str) -> subprocess.CompletedProcess[str]:
    """``rwt play BAG`` or ``rwt serve --play BAG`` on a free port, in the bag's dialect."""
    dialect = ("--dialect", "ros1") if fmt == "ros1" else ()
    if command == "serve":
        return run_rwt("serve", "--port", "0", "--play", str(bag), *dialect)
    return run_rwt("play", "--port", "0", str(bag), *dialect)


def _refused(result: subprocess.CompletedProcess[str], command: str) -> str:
    """The one error line of a command that stopped before listening (asserted so)."""
    assert result.returncode == 1, result.stderr
    assert "listening" not in result.stdout
    assert "Traceback" not in result.stderr, result.stderr
    (line,) = [ln for ln in result.stderr.splitlines() if ln.startswith(f"rwt {command}: ")]
    if command == "play":  # rwt play logs nothing else: the line is all of stderr
        assert result.stderr.splitlines() == [line]
    return line


@pytest.mark.parametrize("command", ["serve", "play"])
@pytest.mark.parametrize("fmt", FORMATS)
def test_a_bag_of_only_invalid_names_is_refused_in_one_line(
    tmp_path: Path, fmt: str, command: str
) -> None:
    bag = bad_names(tmp_path / "names", fmt, INVALID, chatter=False)
    line = _refused(_play(command, bag, fmt), command)
    assert line.startswith(f"rwt {command}: cannot play {bag}: no topic to play has a valid name")
    assert INVALID_LISTED in line
    assert "invalid name 'a b' (expected ROS name tokens" in line


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_mix_plays_the_valid_topics_and_names_the_others_once(tmp_path: Path, fmt: str) -> None:
    bag = bad_names(tmp_path / "mix", fmt, INVALID)
    result = _play("play", bag, fmt)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert "played 1 messages" in result.stdout  # /chatter's
    (line,) = result.stderr.splitlines()
    assert "event=bag_topics_skipped" in line
    assert f"bag={bag} count=3 topics='a b','1x','/bad name' reason=invalid name 'a b'" in line


@pytest.mark.parametrize("fmt", FORMATS)
def test_odd_names_are_refused_escaped_without_a_traceback(tmp_path: Path, fmt: str) -> None:
    # rosbags cannot open a ROS 1 bag with an empty topic name: that case is below
    names = ODD[1:] if fmt == "ros1" else ODD
    bag = bad_names(tmp_path / "odd", fmt, names, chatter=False)
    line = _refused(_play("play", bag, fmt), "play")
    assert f"no topic to play has a valid name ({len(names)} skipped: '" in line
    assert f"... ({len(names) - 5} more)): invalid name " in line
    if fmt != "ros1":  # rosbags' ROS 1 reader orders them otherwise, and reads '//' as '/'
        listed = "'','//','~','/" + "n" * 56 + "...','/a\\nb',... (2 more)"
        assert f"({len(names)} skipped: {listed}): " in line
    assert len(line) < 1000
    assert not {"\x00", "\u202e"} & set(line)


@pytest.mark.parametrize("fmt", FORMATS)
def test_odd_names_beside_a_valid_one_are_logged_escaped(tmp_path: Path, fmt: str) -> None:
    names = ODD[1:] if fmt == "ros1" else ODD
    bag = bad_names(tmp_path / "odd", fmt, names)
    result = _play("play", bag, fmt)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert "played 1 messages" in result.stdout
    (line,) = result.stderr.splitlines()  # the newline of '/a\nb' did not split it
    assert f"count={len(names)} topics='" in line
    assert f"... ({len(names) - 5} more) reason=invalid name " in line
    assert len(line) < 1000
    assert not {"\x00", "\u202e"} & set(line)


def test_a_ros1_bag_with_an_empty_topic_name_is_refused_in_one_line(tmp_path: Path) -> None:
    bag = bad_names(tmp_path / "empty", "ros1", ("",))
    line = _refused(_play("play", bag, "ros1"), "play")
    assert line.startswith(f"rwt play: cannot read {bag}: ")


@pytest.mark.parametrize("fmt", ["mcap", "sqlite3"])
def test_lone_surrogate_names_are_escaped(tmp_path: Path, fmt: str) -> None:
    alone = escaped_names(tmp_path / "alone", fmt, ("/\\ud800x", "/a\\udc80"), chatter=False)
    line = _refused(_play("serve", alone, fmt), "serve")
    assert "(2 skipped: '/\\ud800x','/a\\udc80')" in line
    mixed = escaped_names(tmp_path / "mixed", fmt, ("/\\ud800x",))
    result = _play("play", mixed, fmt)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert "played 1 messages" in result.stdout
    (line,) = result.stderr.splitlines()
    assert "count=1 topics='/\\ud800x' reason=" in line


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_name_that_is_not_utf8_is_refused_in_one_line(tmp_path: Path, fmt: str) -> None:
    bag = undecodable_name(tmp_path / "bytes", fmt)
    line = _refused(_play("play", bag, fmt), "play")
    assert line.startswith(f"rwt play: cannot read {bag}: ")


def test_a_bag_without_topics_plays_nothing(tmp_path: Path) -> None:
    bag = bad_names(tmp_path / "empty", "mcap", (), chatter=False)
    result = _play("play", bag, "mcap")
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    assert "played 0 messages" in result.stdout
