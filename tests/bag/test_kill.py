"""`rwt record URL OUT` and signals: SIGINT or SIGTERM close the bag, SIGKILL leaves it readable.

roslibpy publishes numbered messages (20 kB each, 100 per second) into a live
`rwt serve`;
`rwt record` records them as a client. Killed with SIGKILL mid-run, the bag
(without any repair) opens with rosbags and holds an unbroken run of messages
up to its last checkpoint; stopped with SIGTERM (or SIGINT), it holds every
message up to the stop and the recorder prints its one summary line.
"""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import anyio
import anyio.to_thread
import pytest
import yaml

from tests.integration.client_harness import REPO, ServerProcess
from tests.support.cli import RWT
from tests.support.realclients import run_python

from .support import CHECKPOINTS, read_bag

pytestmark = [pytest.mark.anyio, CHECKPOINTS]

PAD = "x" * 20_000


def publisher(port: int, stop_file: Path) -> str:
    """Publish numbered messages every 10 ms until ``stop_file`` exists (at most 60 s)."""
    return f"""
        import pathlib, time
        import roslibpy
        ros = roslibpy.Ros("127.0.0.1", {port})
        ros.run(timeout=20)
        topic = roslibpy.Topic(ros, "/count", "std_msgs/String")
        topic.advertise()
        stop = pathlib.Path({str(stop_file)!r})
        start = time.monotonic()
        i = 0
        while not stop.exists() and time.monotonic() - start < 60:
            topic.publish(roslibpy.Message({{"data": f"{{i:06d}} {PAD}"}}))
            i += 1
            time.sleep(0.01)
        ros.terminate()
        print(i)
    """


def start_recorder(url: str, bag: Path, cwd: Path) -> subprocess.Popen[str]:
    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}
    return subprocess.Popen(
        [*RWT, "record", url, str(bag), "--topics", "/count"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=cwd,
        env=env,
    )


def numbers(bag: Path) -> list[int]:
    msgs = read_bag(bag).get("/count", [])
    for msg in msgs:
        assert msg["data"].endswith(PAD)
    return [int(msg["data"][:6]) for msg in msgs]


def checkpointed(bag: Path) -> int:
    """Messages the bag's last full checkpoint counted (its ``metadata.yaml``), 0 before one."""
    try:
        info = yaml.safe_load((bag / "metadata.yaml").read_text("utf-8"))
        return int(info["rosbag2_bagfile_information"]["message_count"])
    except (OSError, yaml.YAMLError, TypeError, KeyError, ValueError):  # none yet, or mid-write
        return 0


async def _record_and_stop(
    tmp_path: Path, how: signal.Signals, least: int
) -> tuple[list[int], str, int]:
    """Record until a checkpoint holds ``least`` messages (mid-run), then send ``how``."""
    server = ServerProcess(tmp_path)
    bag = tmp_path / "run"
    stop_file = tmp_path / "stop"
    recorder = start_recorder(server.url, bag, tmp_path)
    try:
        async with anyio.create_task_group() as tg:
            tg.start_soon(run_python, publisher(server.port, stop_file))
            # checkpoints run every second: a bound on a recorder that stopped making them
            with anyio.fail_after(30):
                while checkpointed(bag) < least:
                    await anyio.sleep(0.05)
            # mid-run: the publisher goes on until stop_file
            recorder.send_signal(how)
            out, err = await anyio.to_thread.run_sync(lambda: recorder.communicate(timeout=20))
            stop_file.touch()
    finally:
        stop_file.touch()
        if recorder.poll() is None:
            recorder.kill()
        server.stop()
    return numbers(bag), out + err, recorder.returncode


async def test_sigkill_leaves_a_readable_bag(tmp_path: Path) -> None:
    got, _, code = await _record_and_stop(tmp_path, signal.SIGKILL, least=50)
    assert code == -signal.SIGKILL
    assert (tmp_path / "run" / "metadata.yaml").exists()
    # killed after a checkpoint counted 50 messages (half a second's): the bag,
    # unrepaired, reads at least those
    assert len(got) >= 50, got
    assert got == list(range(got[0], got[0] + len(got))), "a gap or a reordering"


async def test_sigterm_closes_the_bag(tmp_path: Path) -> None:
    """SIGINT takes the same path (one signal receiver for both); the serve --record
    round trips stop their server with SIGINT."""
    start = time.monotonic()
    got, output, code = await _record_and_stop(tmp_path, signal.SIGTERM, least=100)
    assert code == 0, output
    assert time.monotonic() - start < 60
    assert len(got) >= 100, got
    assert got == list(range(got[0], got[0] + len(got)))
    (summary,) = [line for line in output.splitlines() if line.startswith("recorded ")]
    assert f"recorded {len(got)} messages" in summary
    assert str(tmp_path / "run") in summary
