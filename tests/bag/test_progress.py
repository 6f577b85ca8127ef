"""The progress display: a live line on a terminal, one summary line otherwise."""

from __future__ import annotations

import io
import os
from functools import partial
from pathlib import Path

import anyio
import pytest

import rwt
from rwt_bag.progress import record_line, show_progress

pytestmark = pytest.mark.anyio


async def _record(tmp_path: Path, out: io.TextIOBase | object) -> rwt.bag.Recorder:
    graph = rwt.Graph()
    pub = graph.create_publisher("/p", "std_msgs/String")
    recorder = rwt.bag.Recorder(graph, tmp_path / "bag")
    async with recorder, anyio.create_task_group() as tg:
        tg.start_soon(partial(show_progress, interval_s=0.05), partial(record_line, recorder), out)
        for i in range(5):
            pub.publish({"data": str(i)})
            await anyio.sleep(0.1)
        tg.cancel_scope.cancel()
    return recorder


async def test_not_a_terminal_gets_one_summary_line(tmp_path: Path) -> None:
    out = io.StringIO()
    await _record(tmp_path, out)
    (line,) = out.getvalue().splitlines()
    assert line.startswith("recorded ")
    assert "on 1 topics" in line and str(tmp_path / "bag") in line


async def test_a_terminal_gets_a_live_line(tmp_path: Path) -> None:
    master, slave = os.openpty()
    with os.fdopen(slave, "w") as terminal:
        await _record(tmp_path, terminal)
    os.set_blocking(master, False)
    shown = b""
    try:
        while chunk := os.read(master, 65536):
            shown += chunk
    except OSError:  # EIO (or EAGAIN) once what the closed terminal held is read
        pass
    finally:
        os.close(master)
    text = shown.decode("utf-8", "replace")
    assert "recording " in text  # redrawn while it ran
    assert "recorded " in text  # and the summary at the end
