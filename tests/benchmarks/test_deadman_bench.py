"""The dead-man benchmark's smoke run: both cases get their stop (figures mean nothing here)."""

from __future__ import annotations

from benchmarks import deadman


def test_one_round_of_each_case_gets_its_stop() -> None:
    figures = deadman.main(["--smoke"])
    assert {case: len(values) for case, values in figures.items()} == {"quiet": 1, "gone": 1}
    assert "| quiet | 1 |" in deadman.table(figures)
