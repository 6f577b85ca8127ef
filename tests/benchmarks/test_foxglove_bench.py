"""``python -m benchmarks foxglove --quick`` runs both servers and counts every delivery.

No timing is asserted (the project's rule): tiny counts, every scenario on rwt
and on the Foxglove SDK's server, and the readers' counts checked.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("foxglove", reason="the Foxglove SDK (pip install foxglove-sdk) is not here")

ROOT = Path(__file__).resolve().parents[2]


def test_quick_run_delivers_everything_on_both_servers(tmp_path: Path) -> None:
    out = tmp_path / "foxglove.json"
    env = os.environ | {"PYTHONPATH": f"{ROOT / 'src'}{os.pathsep}{ROOT}"}
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks", "foxglove", "--quick", f"--out={out}"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "| 300 x 100 B to 10 readers: delivered % | 100.0 | 100.0 | 1.00 |" in proc.stdout
    results = json.loads(out.read_text())["results"]
    assert set(results) == {
        "burst1",
        "burst10",
        "batch1",
        "batch10",
        "large",
        "image1",
        "image5",
        "alone",
        "stalled",
    }
    for name, runs in results.items():
        for kind in ("rwt", "sdk"):
            (figures,) = runs[kind]
            # well within both servers' queues: nothing may be lost
            assert figures["delivered"] == figures["expected"] > 0, (name, kind, figures)
            assert figures["cpu_us_per_msg"] > 0
            if name.startswith("image"):
                assert 0 < figures["p50_ms"] <= figures["p99_ms"]
            if name == "stalled":
                assert "peak_growth_mb" in figures
                if kind == "rwt":  # its queue's figures, from rwt's log of that connection
                    assert figures["stalled_dropped"] >= 0
                    assert figures["queue_peak_mb"] > 0
