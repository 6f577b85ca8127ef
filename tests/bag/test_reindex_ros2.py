"""``rwt bag reindex`` of ROS 2 bags whose recorder was killed, read back by real readers.

roslibpy publishes into ``rwt serve --record`` (MCAP, sqlite3); once a
checkpoint holds every message the server is killed with SIGKILL. What a kill
at a worse moment, or another recorder, leaves is then made from that bag:
``ros2 bag record`` killed leaves no ``metadata.yaml`` (it writes it when it
stops), and an MCAP writer killed while it writes a chunk leaves that chunk
cut short and no summary or footer. rosbags refuses both; after ``rwt bag
reindex`` rosbags (and for MCAP, the official ``mcap`` reader through the new
summary) reads every message back, and the original is kept as ``NAME.orig``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from typing import TYPE_CHECKING

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML, YAMLError

from rwt_bag import BagError
from rwt_bag.reindex import reindex
from tests.integration.client_harness import REPO, ServerProcess
from tests.support.cli import RWT

from .support import CHECKPOINTS, read_bag, sample_messages
from .test_record_roundtrip import roslibpy_publisher

if TYPE_CHECKING:
    from pathlib import Path

REPEAT = 2
MESSAGES = sample_messages(False)
WANT = {topic: REPEAT for topic, _, _ in MESSAGES}
ENV = {**os.environ, "PYTHONPATH": str(REPO / "src")}  # this checkout's rwt


def run(*cmd: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=60, env=ENV)


def killed_recording(workdir: Path, fmt: str) -> Path:
    """A bag of ``rwt serve --record`` killed (SIGKILL) after a checkpoint holding ``WANT``."""
    bag = workdir / "run"
    args = ("--record", str(bag), "--record-format", fmt, "--record-topics", "/rt/*")
    server = ServerProcess(workdir, args)
    try:
        script = textwrap.dedent(roslibpy_publisher(server.port, MESSAGES, repeat=REPEAT))
        out = run(sys.executable, "-c", script)
        assert out.stdout.split() == ["done"], out.stderr
        deadline = time.monotonic() + 20
        while _checkpointed(bag) < sum(WANT.values()):  # the next checkpoint: within 1 s
            assert time.monotonic() < deadline, "no checkpoint wrote the messages in 20 s"
            time.sleep(0.1)
        server.proc.send_signal(signal.SIGKILL)
    finally:
        code = server.stop()
    assert code == -signal.SIGKILL, server.stderr_text()
    return bag


def _checkpointed(bag: Path) -> int:
    try:
        meta = YAML(typ="safe").load((bag / "metadata.yaml").read_text("utf-8"))
        return int(meta["rosbag2_bagfile_information"]["message_count"])
    except (OSError, YAMLError, TypeError, KeyError):  # not written yet, or being rewritten
        return 0


def counts(bag: Path) -> dict[str, int]:
    return {topic: len(msgs) for topic, msgs in read_bag(bag).items()}


def refused_by_rosbags(bag: Path) -> bool:
    try:
        with AnyReader([bag]) as reader:
            sum(1 for _ in reader.messages())
    except Exception:  # rosbags' errors: no metadata, no footer
        return True
    return False


TORN_CHUNK = b"\x06" + (4096).to_bytes(8, "little") + bytes(20)  # a chunk record cut short


@CHECKPOINTS  # a killed recording: readable up to its last checkpoint
def test_mcap_cut_short_in_a_chunk(tmp_path: Path) -> None:
    bag = killed_recording(tmp_path, "mcap")
    (file,) = bag.glob("*.mcap")
    data = file.read_bytes()
    # the footer (last 37 bytes) says where the summary starts; the data end record
    # (13 bytes) is just before it: keep the data, then a chunk whose write was cut
    summary_start = int.from_bytes(data[-37 + 9 : -37 + 17], "little")
    torn = data[: summary_start - 13] + TORN_CHUNK
    file.write_bytes(torn)
    (bag / "metadata.yaml").unlink()
    assert refused_by_rosbags(bag)
    result = run(*RWT, "bag", "reindex", str(bag))
    assert result.returncode == 0, result.stderr
    total = sum(WANT.values())
    want = f"reindexed {bag}: {total} messages, {len(TORN_CHUNK)} bytes of a cut-short tail"
    assert want in result.stdout
    assert (tmp_path / "run.orig" / file.name).read_bytes() == torn
    assert counts(bag) == WANT
    # the official MCAP reader, through the summary (its index) the reindex wrote
    (rebuilt,) = bag.glob("*.mcap")
    with rebuilt.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics is not None
        assert summary.statistics.message_count == sum(WANT.values())
        topics = [channel.topic for _, channel, _ in reader.iter_messages()]
    assert {t: topics.count(t) for t in set(topics)} == WANT


@CHECKPOINTS  # a killed recording: readable up to its last checkpoint
def test_sqlite3_without_metadata(tmp_path: Path) -> None:
    bag = killed_recording(tmp_path, "sqlite3")
    (bag / "metadata.yaml").unlink()
    assert refused_by_rosbags(bag)
    reindex(bag)
    assert counts(bag) == WANT
    assert _checkpointed(bag) == sum(WANT.values())
    assert sorted(p.name for p in (tmp_path / "run.orig").iterdir()) == ["run.db3"]
    with pytest.raises(BagError, match=r"run\.orig exists already"):
        reindex(bag)


def test_what_is_not_a_bag_is_refused_with_one_line(tmp_path: Path) -> None:
    text = tmp_path / "notes.bag"
    text.write_text("not a bag\n")
    (tmp_path / "empty").mkdir()
    result = run(*RWT, "bag", "reindex", str(text))
    assert result.returncode == 1
    (line,) = result.stderr.strip().splitlines()
    why = "is not a bag (a ROS 1 .bag file, or a ROS 2 bag folder)"
    assert line == f"rwt bag reindex: {text} {why}"
    for path, why in [
        (tmp_path / "empty", "is not a ROS 2 bag (no .mcap or .db3 file, or both)"),
        (tmp_path / "missing", "does not exist"),
    ]:
        with pytest.raises(BagError) as refused:
            reindex(path)
        assert str(refused.value) == f"{path} {why}"
    assert text.read_text() == "not a bag\n"  # left as it was, no backup made
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty", "notes.bag"]
