"""`python -m benchmarks peer`: the comparison with a running rosbridge_suite (ROS 1).

The peer comes from RWT_ROSBRIDGE_ROS1_URL; without it the command says it skips,
and the run against the peer is skipped here with that reason.
"""

from __future__ import annotations

import os
import socket

import pytest
from benchmarks.__main__ import main

from benchmarks import peer

PEER = os.environ.get(peer.PEER_ENV)


def _free_port() -> int:
    with socket.socket() as closed:
        closed.bind(("127.0.0.1", 0))
        return int(closed.getsockname()[1])


def test_the_listening_process_is_found_by_its_port() -> None:
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        assert peer.listening_pid(listener.getsockname()[1]) == os.getpid()
    assert peer.listening_pid(_free_port()) is None


def test_without_a_peer_the_command_skips_and_says_why(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv(peer.PEER_ENV, raising=False)
    assert main(["peer"]) == 0
    assert "skipped" in capsys.readouterr().err


def test_a_peer_url_where_nothing_listens_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["peer", "--peer-url", f"ws://127.0.0.1:{_free_port()}"]) == 2
    assert "nothing listens" in capsys.readouterr().err


@pytest.mark.skipif(
    not PEER,
    reason=f"{peer.PEER_ENV} is not set: no rosbridge_suite (ROS 1) to benchmark against",
)
def test_one_tiny_run_against_the_three_servers(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["peer", "--smoke"]) == 0
    table = capsys.readouterr().out
    assert "| scenario | figure | bare relay | rwt serve --dialect ros1 | rosbridge 0.11 |" in table
    for row in (
        "B1 String 100 B, 1 -> 1 | msg/s",
        "B2",
        "B7 String 100 B at 100 Hz, 1 -> 10 | p99",
    ):
        assert row in table
    assert "| - |" not in table  # every server measured every figure
