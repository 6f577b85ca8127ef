"""A worker's connection count outlives it (``rwt_transports.workers.counts``); its command line."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from rwt_transports.workers.counts import ConnectionCountWriter, read_count, reset_count
from rwt_transports.workers.supervisor import (
    LISTEN_FD_OPTION,
    WorkerPlan,
    child_args,
    parse_listen_fds,
)


def test_the_count_a_killed_process_wrote_is_read_after_it(tmp_path: Path) -> None:
    path = str(tmp_path / "worker-0")
    reset_count(path)
    assert read_count(path) == 0
    code = (
        "import os, signal, sys\n"
        "from rwt_transports.workers.counts import ConnectionCountWriter\n"
        "w = ConnectionCountWriter(sys.argv[1])\n"
        "for n in (1, 2, 3, 2, 7): w.write(n)\n"
        "os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    done = subprocess.run([sys.executable, "-c", code, path], check=False)
    assert done.returncode == -signal.SIGKILL
    assert read_count(path) == 7  # the last write, though nothing was flushed or closed
    reset_count(path)  # a restarted worker starts from none
    assert read_count(path) == 0


def test_a_missing_or_short_file_reads_as_unknown(tmp_path: Path) -> None:
    assert read_count(str(tmp_path / "never")) is None
    short = tmp_path / "short"
    short.write_bytes(b"\x01")
    assert read_count(str(short)) is None
    writer = ConnectionCountWriter(str(short))  # the writer makes it whole
    writer.write(5)
    writer.close()
    assert read_count(str(short)) == 5


def test_each_worker_gets_a_file_of_its_own_and_a_users_option_is_replaced() -> None:
    plan = WorkerPlan(["--no-tf", "--worker-state", "/elsewhere"], 9090, None, None, "/run/w")
    args = child_args(plan, 1)
    assert "/elsewhere" not in args
    assert args[args.index("--worker-state") + 1] == os.path.join("/run/w", "worker-1")
    assert "--worker-state" not in child_args(WorkerPlan(["--no-tf"], 9090, None, None), 0)


def test_every_worker_inherits_the_parents_listening_sockets() -> None:
    fds = {"websocket": (5, 6), "tcp": (7,)}
    plan = WorkerPlan(["--no-tf", "--listen-fd", "websocket:99"], 9090, 9091, None, listen_fds=fds)
    assert plan.inherited() == (5, 6, 7)
    for index in (0, 1):
        args = child_args(plan, index)
        given = [args[i + 1] for i, arg in enumerate(args) if arg == LISTEN_FD_OPTION]
        assert given == ["websocket:5", "websocket:6", "tcp:7"]  # a user's is replaced
        assert parse_listen_fds(given) == fds
    with pytest.raises(ValueError, match="KIND:FD"):
        parse_listen_fds(["websocket"])
