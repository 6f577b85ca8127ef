"""Topic names in bags follow the rules of a client's ``advertise`` (docs/limits.md).

A bag (MCAP, sqlite3 or ROS 1) holding ``/chatter`` and topics named ``/x y``,
``/../..``, with U+202E, and 5000 characters long: ``rwt serve --play`` logs one
line naming the bag and the count of skipped topics, rosapi lists none of them,
and roslibpy receives ``/chatter``. ``rwt bag info`` prints them escaped, cut
and marked as not played.
"""

from __future__ import annotations

import json
import subprocess
import sys
from typing import TYPE_CHECKING

import pytest

from tests.integration.client_harness import REPO, ServerProcess
from tests.transports.realclients import run_python

from .hostile import BAD_NAMES, bad_names

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = pytest.mark.anyio

CLIENT = """
    import json, time
    import roslibpy
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    got = []
    roslibpy.Topic(ros, "/chatter", "std_msgs/String").subscribe(lambda m: got.append(m["data"]))
    time.sleep(0.5)
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


def test_bag_info_escapes_and_marks_bad_names(tmp_path: Path) -> None:
    bag = bad_names(tmp_path / "names", "mcap")
    result = subprocess.run(
        [sys.executable, "-m", "rwt", "bag", "info", str(bag)],
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
