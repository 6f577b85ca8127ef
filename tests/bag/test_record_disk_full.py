"""``rwt serve --record`` when the disk refuses data: the recording ends, the server goes on.

The server runs under a file size limit (``prlimit --fsize``, EFBIG on the write
that passes it, as a full disk gives ENOSPC): roslibpy publishes more than fits,
then checks that the server still serves it. One error line names the bag and
the cause, and the bag reads back what reached it.
"""

from __future__ import annotations

import json
import shutil
import sys
from typing import TYPE_CHECKING

import pytest

from rwt_bag import BagError
from rwt_bag.info import bag_info
from rwt_bag.reindex import reindex
from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

from .support import CHECKPOINTS
from .test_record_limits import PUBLISH

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.skipif(shutil.which("prlimit") is None, reason="needs util-linux prlimit"),
    CHECKPOINTS,
]

LIMIT_BYTES = 120_000  # about 100 of the 200 1 KB messages


@pytest.mark.parametrize("fmt", ["mcap", "sqlite3", "ros1"])
async def test_a_refused_write_ends_the_recording_not_the_server(tmp_path: Path, fmt: str) -> None:
    bag = tmp_path / ("capped.bag" if fmt == "ros1" else "capped")
    args = ["--record", str(bag), "--record-topics", "/big"]
    args += ["--record-format", fmt]
    if fmt == "ros1":
        args += ["--dialect", "ros1"]
    cmd = [
        "prlimit",
        f"--fsize={LIMIT_BYTES}",
        sys.executable,
        "-m",
        "rwt",
        "serve",
        "--host",
        "127.0.0.1",
        "--port",
        "0",
        *args,
    ]
    server = ServerProcess(tmp_path, cmd=cmd)
    try:
        # paced, so that checkpoints (every second) fall between the messages
        paced = PUBLISH.replace("time.sleep(0.005)", "time.sleep(0.015)")
        out = await run_python(paced.format(port=server.port, stops=True))
    finally:
        code = server.stop()
    log = server.stderr_text()
    assert json.loads(out.strip().splitlines()[-1]) == {"echo": ["still here"]}, log
    assert code == 0, log
    failed = [ln for ln in log.splitlines() if "event=record_failed" in ln]
    assert len(failed) == 1, log
    assert str(bag) in failed[0]
    assert "Traceback" not in log
    done = [ln for ln in log.splitlines() if "event=record_done recorded" in ln]
    assert len(done) == 1, log  # the summary: what reached the bag, where
    assert str(bag) in done[0]
    if fmt == "ros1":
        # a ROS 1 bag has its index written at the end only: as after a kill, it needs
        # `rwt bag reindex` (or `rosbag reindex`), which keeps the chunks of the
        # checkpoints before the refused write (docs/record-replay.md)
        with pytest.raises(BagError, match="not indexed"):
            bag_info(bag)
        reindex(bag)
    # what a user reads it with: rwt bag info (and rwt play), up to the last checkpoint
    # (sqlite3's write-ahead log, a second file under the limit, may have taken all)
    assert 0 < bag_info(bag).messages <= 200
