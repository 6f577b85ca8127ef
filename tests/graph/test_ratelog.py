"""The episode log: a peer that repeats trouble writes one line, then counts."""

from __future__ import annotations

import logging

import pytest

from rwt_graph import ratelog
from rwt_graph.ratelog import EpisodeLog


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


def lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "test.ratelog"]


def test_a_flood_writes_one_line_then_a_summary(caplog, clock):
    log = EpisodeLog(logging.getLogger("test.ratelog"), every_s=10, quiet_s=10, clock=clock)
    caplog.set_level(logging.INFO, "test.ratelog")
    for i in range(1000):
        clock.now = i * 0.005  # 200 per second for 5 s
        log.log(logging.WARNING, "bad", "bad sample on %s", "/x")
    assert lines(caplog) == ["bad sample on /x"]
    clock.now = 11.0
    assert log.log(logging.WARNING, "bad", "bad sample on %s", "/x")
    assert lines(caplog)[-1] == "bad sample on /x (repeated 1000 times in 11 s)"


def test_quiet_ends_the_episode_with_its_count(caplog, clock):
    log = EpisodeLog(logging.getLogger("test.ratelog"), every_s=10, quiet_s=2, clock=clock)
    caplog.set_level(logging.INFO, "test.ratelog")
    log.log(logging.WARNING, "k", "first")
    log.log(logging.WARNING, "k", "again")
    clock.now = 5.0
    assert log.log(logging.WARNING, "k", "new episode")
    assert lines(caplog) == [
        "first",
        "event=log_episode_end kind=k repeats=1 seconds=0",
        "new episode",
    ]


def test_kinds_are_separate_and_bounded(caplog, clock):
    log = EpisodeLog(logging.getLogger("test.ratelog"), clock=clock)
    caplog.set_level(logging.INFO, "test.ratelog")
    assert log.log(logging.WARNING, "a", "a")
    assert log.log(logging.WARNING, "b", "b")
    assert not log.log(logging.WARNING, "a", "a")
    for i in range(ratelog.MAX_KINDS * 4):
        log.log(logging.WARNING, f"k{i}", "k")
    assert len(log._episodes) <= ratelog.MAX_KINDS
