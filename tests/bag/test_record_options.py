"""Recording options as ``ros2 bag record`` names them (docs/record-replay.md, Recording).

- ``rwt serve --record``: roslibpy publishes on five topics; ``--record-topics``
  plus ``--record-regex`` take three, ``--record-exclude-regex`` and
  ``--record-exclude-topics`` leave two of those out again. With
  ``--record-max-bag-size`` the bag comes in parts, each starting with the latched
  topic's message; with ``--record-chunk-compression zstd`` the official ``mcap``
  reader finds every chunk zstd-compressed and decodes every message.
- ``rwt record URL``: ``-e``, ``--exclude-topics``, ``--chunk-compression lz4``,
  ``--max-bag-duration`` and ``--no-repeat-latched`` (``/tf_static``, published
  in the first 2 s only, is not in the last part).
- Bad values (a broken expression, a level out of range, chunk compression for a
  sqlite3 bag, a limit under both names) are refused with one line.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import anyio
import anyio.to_thread
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from tests.integration.client_harness import REPO, ServerProcess
from tests.support.cli import RWT, invoke_rwt
from tests.support.realclients import run_python

from .support import CHECKPOINTS, RECORDER

pytestmark = pytest.mark.anyio

PUBLISH = (
    """
    import time
    import roslibpy
"""
    + RECORDER
    + """
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    keep = roslibpy.Topic(ros, "/keep", "std_msgs/String", latch=True)
    keep.advertise()
    names = ["/sel/a", "/sel/skip_me", "/sel/no", "/other"]
    topics = [roslibpy.Topic(ros, n, "std_msgs/String") for n in names]
    for t in topics:
        t.advertise()
    recorder(ros, "/sel/a", on=True)  # the look that takes it saw all the others
    keep.publish(roslibpy.Message({{"data": "kept"}}))
    for i in range(40):
        for t in topics:
            t.publish(roslibpy.Message({{"data": "%04d" % i + "x" * 200}}))
        time.sleep(0.005)
    ros.get_topics()  # answered once the publishes before it were taken
    ros.terminate()
    print("done")
"""
)


def parts_of(bag: Path) -> list[Path]:
    """The bag and its split parts (``bag``, ``bag_1``...), in order."""
    found = [bag]
    while (part := bag.with_name(f"{bag.name}_{len(found)}")).exists():
        found.append(part)
    return found


def topics_by_part(parts: list[Path]) -> list[list[tuple[str, str]]]:
    """(topic, data) of each part's messages, read by rosbags."""
    out = []
    for part in parts:
        with AnyReader([part]) as reader:
            out.append(
                [
                    (c.topic, getattr(reader.deserialize(raw, c.msgtype), "data", ""))
                    for c, _, raw in reader.messages()
                ]
            )
    return out


def mcap_chunks(part: Path) -> tuple[set[str], int]:
    """A part's chunk compressions, and how many messages the ``mcap`` reader decodes."""
    (file,) = part.glob("*.mcap")
    with file.open("rb") as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        compressions = {index.compression for index in summary.chunk_indexes}
        return compressions, sum(1 for _ in reader.iter_messages())


@CHECKPOINTS  # chunk compression is the checkpoint writer's
async def test_serve_record_selects_splits_compresses_and_repeats_latched(tmp_path: Path) -> None:
    bag = tmp_path / "sel"
    args = (
        *("--record", str(bag), "--record-topics", "/keep", "--record-regex", "^/sel/"),
        *("--record-exclude-regex", "skip", "--record-exclude-topics", "/sel/no"),
        *("--record-chunk-compression", "zstd", "--record-chunk-compression-level", "19"),
        *("--record-max-bag-size", "3000"),
    )
    server = ServerProcess(tmp_path, args)
    try:
        assert (await run_python(PUBLISH.format(port=server.port))).split() == ["done"]
    finally:
        assert server.stop() == 0, server.stderr_text()
    parts = parts_of(bag)
    assert len(parts) >= 3  # 40 messages of 204 bytes in parts of 3000
    messages = topics_by_part(parts)
    assert {topic for part in messages for topic, _ in part} == {"/keep", "/sel/a"}
    numbers = [data[:4] for part in messages for topic, data in part if topic == "/sel/a"]
    assert numbers == [f"{i:04d}" for i in range(40)]
    for part in messages:  # every part can be played alone: it has the latched /keep
        assert ("/keep", "kept") in part
    for part, got in zip(parts, messages, strict=True):
        compressions, count = mcap_chunks(part)
        assert compressions == {"zstd"}
        assert count == len(got)


PUBLISH_UNTIL = """
    import pathlib, time
    import roslibpy
    ros = roslibpy.Ros("127.0.0.1", {port})
    ros.run(timeout=20)
    static = roslibpy.Topic(ros, "/tf_static", "tf2_msgs/TFMessage", latch=True)
    static.advertise()
    topics = [roslibpy.Topic(ros, n, "std_msgs/String") for n in ("/sel/a", "/sel/no")]
    for t in topics:
        t.advertise()
    stop, bag = pathlib.Path({stop!r}), pathlib.Path({bag!r})
    start = time.monotonic()
    static_until = None
    i = 0
    while not stop.exists() and time.monotonic() - start < 60:
        if static_until is None and bag.exists():  # the recorder has started
            static_until = time.monotonic() + 2.0  # it subscribes within a second
        if static_until is None or time.monotonic() < static_until:
            static.publish(roslibpy.Message({{"transforms": []}}))
        for t in topics:
            t.publish(roslibpy.Message({{"data": "%06d" % i}}))
        i += 1
        time.sleep(0.02)
    ros.terminate()
"""


@CHECKPOINTS
async def test_rwt_record_regex_exclusions_lz4_and_duration_parts(tmp_path: Path) -> None:
    server = ServerProcess(tmp_path)
    bag = tmp_path / "run"
    stop = tmp_path / "stop"
    command = [*RWT, "record", server.url, str(bag)]
    command += ["--topics", "/tf_static", "-e", "^/sel", "--exclude-topics", "/sel/no"]
    command += ["--chunk-compression", "lz4", "--chunk-compression-level", "9"]
    command += ["--max-bag-duration", "0.5", "--no-repeat-latched", "--duration", "4.5"]
    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}
    try:
        async with anyio.create_task_group() as tg:
            script = PUBLISH_UNTIL.format(port=server.port, stop=str(stop), bag=str(bag))
            tg.start_soon(run_python, script)
            done = await anyio.to_thread.run_sync(
                lambda: subprocess.run(
                    command, capture_output=True, text=True, env=env, timeout=60, check=False
                )
            )
            stop.touch()
    finally:
        stop.touch()
        server.stop()
    assert done.returncode == 0, done.stderr
    parts = parts_of(bag)
    assert len(parts) >= 3  # 4 s of messages in parts of 0.5 s
    messages = topics_by_part(parts)
    assert {topic for part in messages for topic, _ in part} == {"/tf_static", "/sel/a"}
    # /tf_static stopped 2 s after the start, and --no-repeat-latched does not
    # carry it into the later parts
    assert {topic for topic, _ in messages[-1]} == {"/sel/a"}
    for part in parts:
        compressions, _ = mcap_chunks(part)
        assert compressions <= {"lz4"}


def invoke(*args: str) -> tuple[int, str]:
    """``rwt ARGS`` in-process: its exit code and output."""
    result = invoke_rwt(*args)
    return result.exit_code, result.output


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("--regex", "/a("), "--regex '/a(' is not a regular expression"),
        (("--exclude-regex", "*x"), "--exclude-regex '*x' is not a regular expression"),
        (("--chunk-compression", "zstd", "--chunk-compression-level", "30"), "-7 to 22"),
        (("--chunk-compression-level", "3"), "needs a compression"),
        (("--chunk-compression", "lz4", "--format", "sqlite3"), "is for MCAP bags"),
        (("--max-bag-size", "10", "--split-size", "1"), "give --max-bag-size or --split-size"),
    ],
)
def test_bad_recording_options_are_refused(
    tmp_path: Path, args: tuple[str, ...], says: str
) -> None:
    code, output = invoke("record", "ws://127.0.0.1:1", str(tmp_path / "x"), *args)
    assert code == 2, output
    assert says in output
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("--record-regex", "("), "--record-regex '(' is not a regular expression"),
        (
            ("--record-format", "sqlite3", "--record-chunk-compression", "zstd"),
            "--record-chunk-compression: chunk compression (zstd) is for MCAP bags, not sqlite3",
        ),
    ],
)
def test_serve_names_its_own_record_options_in_errors(
    tmp_path: Path, args: tuple[str, ...], says: str
) -> None:
    code, output = invoke("serve", "--port", "0", "--record", str(tmp_path / "x"), *args)
    assert code == 2, output
    assert says in output
    assert not (tmp_path / "x").exists()


def test_chunk_compression_with_the_checkpoints_shortcut_off_is_refused_clearly(
    tmp_path: Path,
) -> None:
    """Off, rosbags' own writer writes the bag, and it compresses no chunks
    (docs/shortcuts.md): a compression asked for is an error, not silently dropped."""
    bag = tmp_path / "x"
    command = [*RWT, "serve", "--port", "0", "--no-tf"]
    command += ["--record", str(bag), "--record-chunk-compression", "zstd"]
    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}
    env["RWT_NO_SHORTCUTS"] = "bag-checkpoints"
    done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=60, check=False)
    assert done.returncode == 1, done.stderr
    assert "MCAP chunk compression needs the bag-checkpoints shortcut (it is off)" in done.stderr
    assert "listening on" not in done.stdout
