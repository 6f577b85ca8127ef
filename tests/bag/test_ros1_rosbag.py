"""ROS 1 bags of ``rwt serve --record --record-format ros1`` in Debian's real rosbag.

roslibpy publishes standard types (std_msgs, geometry_msgs, sensor_msgs,
tf2_msgs) into a ROS 1 ``rwt serve`` that records them. The bag closed by
SIGINT passes ``rosbag check`` with no migration, and survives being opened for
appending with ``rosbag.Bag(path, 'a')`` and closed. The bag of a server killed
with SIGKILL is unindexed; ``rosbag reindex`` and ``rwt bag reindex`` each make
it readable, and rosbag's Python API reads back every message published before
the recorder's last checkpoint.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from benchmarks.servers import ROS1_PROBES, ROS1_PYTHON, imports_ok

from rwt_bag import BagError
from rwt_bag.reindex import reindex
from rwt_bag.reindex_ros1 import reindex_ros1
from tests.integration.client_harness import REPO, ServerProcess
from tests.support.cli import RWT

from .support import sample_messages, stamp
from .test_record_roundtrip import roslibpy_publisher

if TYPE_CHECKING:
    from collections.abc import Iterator

SYSTEM_PYTHON = ROS1_PYTHON
HAVE_ROSBAG = shutil.which("rosbag") is not None and imports_ok(
    SYSTEM_PYTHON, ROS1_PROBES["rosbag"]
)
pytestmark = pytest.mark.skipif(
    not HAVE_ROSBAG,
    reason="needs Debian's python3-rosbag, python3-sensor-msgs and python3-tf2-msgs (apt-get)",
)

ENV = {**os.environ, "PYTHONPATH": str(REPO / "src")}  # this checkout's rwt
REPEAT = 3
TF = {
    "transforms": [
        {
            "header": {"seq": 1, "stamp": stamp(True, 5, 6), "frame_id": "odom"},
            "child_frame_id": "base_link",
            "transform": {"translation": {"x": 1.5}, "rotation": {"w": 1.0}},
        }
    ]
}
MESSAGES = [*sample_messages(True), ("/rt/tf", "tf2_msgs/TFMessage", TF)]
WANT = {topic: REPEAT for topic, _, _ in MESSAGES}

# rosbag's own Python API (Debian's python3, not this interpreter): messages per topic
COUNT = """
import json, sys, rosbag
counts = {}
with rosbag.Bag(sys.argv[1]) as bag:
    for topic, msg, t in bag.read_messages():
        counts[topic] = counts.get(topic, 0) + 1
print(json.dumps(counts))
"""
APPEND = "import sys, rosbag; rosbag.Bag(sys.argv[1], 'a').close()"


def run(*cmd: str) -> subprocess.CompletedProcess[str]:
    """Run ``cmd`` (this checkout's rwt on its path) to its end; its output as text."""
    return subprocess.run(
        cmd,
        check=False,
        capture_output=True,
        text=True,
        timeout=60,
        env=ENV,
        stdin=subprocess.DEVNULL,
    )


def rosbag_counts(bag: Path) -> dict[str, int]:
    """Messages per topic of ``bag`` as real rosbag's Python API reads them."""
    out = run(SYSTEM_PYTHON, "-c", COUNT, str(bag))
    assert out.returncode == 0, out.stderr
    counts: dict[str, int] = json.loads(out.stdout)
    return counts


def rosbag(*args: str) -> subprocess.CompletedProcess[str]:
    return run("rosbag", *args)


def record(workdir: Path, name: str, *, kill: bool) -> Path:
    """Publish ``MESSAGES`` into a recording ROS 1 server; stop it with SIGINT or SIGKILL.

    Before a kill, waits until the recorder's checkpoint has put every message
    on disk (a reindexed copy holds them all).
    """
    bag = workdir / name
    args = ("--dialect", "ros1", "--record", str(bag), "--record-format", "ros1")
    server = ServerProcess(workdir, (*args, "--record-topics", "/rt/*"))
    try:
        script = roslibpy_publisher(server.port, MESSAGES, repeat=REPEAT)
        out = run(sys.executable, "-c", textwrap.dedent(script))
        assert out.stdout.split() == ["done"], out.stderr
        if kill:
            _wait_for_checkpoint(bag, workdir / "probe.bag")
            server.proc.kill()
    finally:
        code = server.stop()
    assert code == (-9 if kill else 0), server.stderr_text()
    return bag


def _wait_for_checkpoint(bag: Path, probe: Path) -> None:
    deadline = time.monotonic() + 20
    while True:
        probe.unlink(missing_ok=True)
        if bag.exists() and reindex_ros1(bag, probe).messages == sum(WANT.values()):
            probe.unlink()
            return
        assert time.monotonic() < deadline, "no checkpoint wrote the messages in 20 s"
        time.sleep(0.1)


@pytest.fixture(scope="module")
def closed_bag(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    yield record(tmp_path_factory.mktemp("closed"), "closed.bag", kill=False)


@pytest.fixture(scope="module")
def killed_bag(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    yield record(tmp_path_factory.mktemp("killed"), "killed.bag", kill=True)


def test_rosbag_reads_the_closed_bag(closed_bag: Path) -> None:
    assert rosbag_counts(closed_bag) == WANT


def test_rosbag_check_finds_no_migration(closed_bag: Path) -> None:
    """The definitions carry Noetic's texts (comments too), which rosbag check compares."""
    result = rosbag("check", str(closed_bag))
    assert result.returncode == 0, result.stderr
    assert "Bag file does not need any migrations." in result.stdout, result.stdout


def test_rosbag_append_keeps_the_bag_readable(closed_bag: Path, tmp_path: Path) -> None:
    """rosbag rewrites the header with its own padding: it must not eat the first chunk."""
    bag = tmp_path / "appended.bag"
    shutil.copy(closed_bag, bag)
    result = run(SYSTEM_PYTHON, "-c", APPEND, str(bag))
    assert result.returncode == 0, result.stderr
    assert rosbag_counts(bag) == WANT


def test_rosbag_reindex_recovers_the_killed_bag(killed_bag: Path, tmp_path: Path) -> None:
    before = rosbag("info", str(killed_bag))
    assert "unindexed" in before.stdout + before.stderr
    bag = tmp_path / "killed.bag"
    shutil.copy(killed_bag, bag)
    result = rosbag("reindex", str(bag))
    assert result.returncode == 0, result.stderr
    assert rosbag_counts(bag) == WANT
    info = rosbag("info", str(bag)).stdout
    assert f"messages:    {sum(WANT.values())}" in info, info


def test_rwt_bag_reindex_recovers_the_killed_bag(killed_bag: Path, tmp_path: Path) -> None:
    bag = tmp_path / "killed.bag"
    shutil.copy(killed_bag, bag)
    result = run(*RWT, "bag", "reindex", str(bag))
    assert result.returncode == 0, result.stderr
    total = sum(WANT.values())
    backup = tmp_path / "killed.orig.bag"
    assert f"reindexed {bag}: {total} messages" in result.stdout
    assert f"the original is {backup}" in result.stdout
    assert backup.read_bytes() == killed_bag.read_bytes()
    assert rosbag_counts(bag) == WANT
    # a second reindex would overwrite the backup: refused, with the reason
    with pytest.raises(BagError, match=f"{backup} exists already"):
        reindex(bag)
