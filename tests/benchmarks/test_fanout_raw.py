"""Z2's raw-socket generator counts every delivery of a real `rwt serve`, and only those."""

from __future__ import annotations

from pathlib import Path

from benchmarks.fanout_raw import FanOut, fan_out_raw

from tests.integration.client_harness import ServerProcess


def test_every_subscriber_gets_every_timed_message(tmp_path: Path) -> None:
    server = ServerProcess(tmp_path, ("--no-tf",), cold=True)
    try:
        result = fan_out_raw(server.port, 5, 0.3, window=16)
    finally:
        server.stop()
    assert result["sent"] > 0
    assert result["delivered"] == result["expected"] == result["sent"] * 5
    assert result["deliveries_per_s"] > 0


def test_kept_peers_count_each_burst_and_the_server_cpu_it_took(tmp_path: Path) -> None:
    server = ServerProcess(tmp_path, ("--no-tf",), cold=True)
    readings = iter([1_000, 5_000, 7_000, 7_500])
    asked: list[int] = []

    def cpu_ns(pid: int) -> int:
        asked.append(pid)
        return next(readings)

    try:
        fan = FanOut(server.port, 4)
        try:
            first = fan.burst(0.2, server.proc.pid, cpu_ns)
            second = fan.burst(0.2, server.proc.pid, cpu_ns)
            sent = fan.pub.sent
        finally:
            fan.close()
    finally:
        server.stop()
    assert first[0] > 0
    assert second[0] == sent * 4  # the counts start again with each burst
    assert (first[1], second[1]) == (4_000, 500)
    assert asked == [server.proc.pid] * 4


def test_a_paced_burst_sends_no_faster_than_its_rate(tmp_path: Path) -> None:
    server = ServerProcess(tmp_path, ("--no-tf",), cold=True)
    try:
        fan = FanOut(server.port, 3)
        try:
            delivered, _ = fan.burst(0.5, server.proc.pid, lambda pid: 0, rate_hz=40)
            sent = fan.pub.sent
        finally:
            fan.close()
    finally:
        server.stop()
    assert 1 <= sent <= 21  # 40 a second for 0.5 s, the first at once
    assert delivered == sent * 3
