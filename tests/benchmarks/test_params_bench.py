"""The parameters benchmark (benchmarks/params.py) runs tiny against rwt."""

from __future__ import annotations

import subprocess
import sys

from benchmarks.servers import ROOT


def test_a_quick_run_sets_the_values_and_times_a_bystander() -> None:
    run = subprocess.run(
        [sys.executable, "-m", "benchmarks.params", "--quick", "--only", "rosapi", "foxglove50"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    rows = {
        cells[1].strip(): cells
        for line in run.stdout.split("\n\n")[0].splitlines()  # each round's row
        if len(cells := line.split("|")) == 10 and cells[2].strip() == "rwt"
    }
    assert set(rows) == {"rosapi", "foxglove50"}
    for cells in rows.values():
        assert int(cells[4]) > 0  # the bystander was answered while the values were set
