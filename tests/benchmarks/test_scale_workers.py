"""The scale table (`scaleout --workers`) at its smallest: its shape, nothing dropped."""

from __future__ import annotations

from pathlib import Path

import pytest
from benchmarks.__main__ import main

pytest.importorskip("zenoh")


def test_the_scale_table_has_a_row_per_worker_count_and_drops_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["scaleout", "--workers", "1,2", "--fanouts", "2", "--subscribers", "3", "--smoke"]
    status = main([*argv, "--out", str(tmp_path / "scale.json")])
    lines = capsys.readouterr().out.strip().splitlines()
    assert status == 0
    assert lines[0].startswith("| workers | fan-outs x subscribers | deliveries/s |")
    rows = [line.strip("|").split("|") for line in lines[2:]]
    assert [(r[0].strip(), r[1].strip()) for r in rows] == [("1", "2 x 3"), ("2", "2 x 3")]
    for row in rows:
        delivered, expected = row[7].strip().replace(",", "").split("/")
        assert int(delivered) == int(expected) > 0
        assert row[8].strip() == "0"
    assert rows[0][3].strip() == "1.00"  # the ratios are against the first row
    assert not (tmp_path / "scale.json").exists()  # a smoke run saves nothing


def test_worker_counts_below_one_are_refused() -> None:
    with pytest.raises(SystemExit):
        main(["scaleout", "--workers", "0,2"])
