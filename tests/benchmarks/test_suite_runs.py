"""The benchmark suite runs, and its checks catch a wrong server.

No timing is asserted here (the project's rule): the smoke run uses tiny counts and
only checks that the runner completes and prints its table.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from benchmarks.loadgen.engine import ExactSubscriber, GeneratorError
from benchmarks.loadgen.wire import FrameReader, client_frame, server_frame

from benchmarks import msgs

ROOT = Path(__file__).resolve().parents[2]


def _exact(block: bytes, frame_len: int) -> ExactSubscriber:
    sub = ExactSubscriber.__new__(ExactSubscriber)  # no socket: only the checking part
    sub.block, sub.frame_len, sub.pos, sub.received = block, frame_len, 0, 0
    sub.first_s = sub.last_s = None
    return sub


def test_exact_check_accepts_the_expected_stream_in_any_chunks() -> None:
    frames = [server_frame(msgs.string_publish("/t", i)) for i in range(4)]
    block = b"".join(frames)
    sub = _exact(block, len(frames[0]))
    stream = block * 2
    for start in range(0, len(stream), 37):
        sub.feed(stream[start : start + 37], 0.0)
    assert sub.received == 8


def test_exact_check_rejects_a_wrong_message() -> None:
    frames = [server_frame(msgs.string_publish("/t", i)) for i in range(4)]
    sub = _exact(b"".join(frames), len(frames[0]))
    wrong = server_frame(msgs.string_publish("/t", 2))  # message 1 skipped
    sub.feed(frames[0], 0.0)
    with pytest.raises(GeneratorError, match="message 1"):
        sub.feed(wrong, 0.0)


def test_frame_reader_cuts_frames_of_every_header_size() -> None:
    payloads = [b"a" * 5, b"b" * 300, b"c" * 70000]
    data = b"".join(server_frame(p, binary=i == 1) for i, p in enumerate(payloads))
    reader = FrameReader()
    frames = []
    for start in range(0, len(data), 1000):
        frames += reader.feed(data[start : start + 1000])
    assert [(op, len(p)) for op, p in frames] == [(1, 5), (2, 300), (1, 70000)]
    assert client_frame(b"x")[1] & 0x80  # client frames are masked


def test_runner_smoke() -> None:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(ROOT)]))
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks", "run", "B1", "B7", "--smoke"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    rows = [line for line in out.stdout.splitlines() if line.startswith("| B")]
    assert [row.split("|")[1].strip() for row in rows] == ["B1", "B1", "B7", "B7", "B7", "B7"]


def test_compare_runs_both_checkouts_side_by_side() -> None:
    """``compare HEAD`` starts rwt from a worktree of HEAD beside this checkout's rwt and
    reports a median for each, so a change can be measured against its parent in one run."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(ROOT)]))
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks", "compare", "HEAD", "B1", "--smoke"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    rows = [line.split("|") for line in out.stdout.splitlines() if line.startswith("| B1")]
    assert len(rows) == 2, out.stdout
    for row in rows:
        base, now = row[4].strip(), row[5].strip()
        assert float(base.replace(",", "")) > 0 and float(now.replace(",", "")) > 0, row
    listed = subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "list"], capture_output=True, text=True, check=True
    )
    assert "rwt-base-" not in listed.stdout  # the baseline's worktree is removed


def test_fuzz_benchmark_smoke_runs_and_reports() -> None:
    """B18's smoke form sends its fuzzed frames and finds no violation.

    A violation (a frame outside the invariant, a dead server, a bystander not
    served) makes the run exit 1 with the violations listed. No timing is asserted.
    """
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(ROOT)]))
    result = subprocess.run(
        [sys.executable, "-m", "benchmarks", "run", "B18", "--smoke", "--frames", "600"],
        check=False,
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert "| B18 | fuzz" in result.stdout, result.stderr[-2000:]
    assert result.returncode == 0, result.stderr[-3000:]
