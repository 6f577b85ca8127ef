"""The scale table and the cost model (`scaleout --workers`, `--cost-model`) at their smallest."""

from __future__ import annotations

from pathlib import Path

import pytest
from benchmarks.__main__ import main
from benchmarks.scale_costs import cost_table, fit

pytest.importorskip("zenoh")


def test_the_scale_table_has_a_row_per_worker_count_and_drops_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # many topics (2 generators x 2 topics) beside idle clients, at their smallest
    argv = ["scaleout", "--workers", "1,2", "--fanouts", "2", "--subscribers", "3", "--smoke"]
    argv += ["--topics-per-fanout", "2", "--idle", "20"]
    status = main([*argv, "--out", str(tmp_path / "scale.json")])
    lines = capsys.readouterr().out.strip().splitlines()
    assert status == 0
    assert lines[0].startswith("| workers | fan-outs x subscribers | deliveries/s |")
    rows = [line.strip("|").split("|") for line in lines[2:]]
    load = "2 x 2 topics x 3 + 20 idle"
    assert [(r[0].strip(), r[1].strip()) for r in rows] == [("1", load), ("2", load)]
    for row in rows:
        delivered, expected = row[8].strip().replace(",", "").split("/")
        assert int(delivered) == int(expected) > 0
        assert row[9].strip() == "0"
        assert int(row[10].strip().replace(",", "")) > 0  # the server's memory, MB
    assert rows[0][3].strip() == "1.00"  # the ratios are against the first row
    assert not (tmp_path / "scale.json").exists()  # a smoke run saves nothing


def test_the_scale_table_with_topic_placement_drops_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["scaleout", "--workers", "1,2", "--fanouts", "2", "--subscribers", "3", "--smoke"]
    status = main([*argv, "--placement", "topic", "--out", str(tmp_path / "scale.json")])
    rows = [line.strip("|").split("|") for line in capsys.readouterr().out.splitlines()[2:]]
    assert status == 0
    assert [r[0].strip() for r in rows if r[0].strip()] == ["1", "2 (placed by topic)"]
    for row in rows:
        delivered, expected = row[8].strip().replace(",", "").split("/")
        assert int(delivered) == int(expected) > 0


def test_worker_counts_below_one_are_refused() -> None:
    with pytest.raises(SystemExit):
        main(["scaleout", "--workers", "0,2"])


def test_the_cost_model_recovers_its_constants_from_exact_figures() -> None:
    m, e, r, subscribers, workers = 10.0, 17.0, 20.0, [10, 50, 100], [1, 2, 4]
    per_delivery = {1: 3.0, 2: 3.5, 4: 4.0}
    found = {
        f"N{n} S{s}": {"us_per_msg": m + (e + (n - 1) * r if n > 1 else 0) + s * per_delivery[n]}
        for n in workers
        for s in subscribers
    }
    constants = fit(found, subscribers, workers)
    assert constants == pytest.approx(
        {"a1": m, "d1": 3.0, "a2": m + e + r, "d2": 3.5, "a4": m + e + 3 * r, "d4": 4.0}
        | {"m": m, "e": e, "r": r}
    )
    assert "| constant | us |" in cost_table(found, subscribers, workers)
