"""Smoke test of `python -m benchmarks.paper --quick`: it runs and reports rows (no timings)."""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks.paper import MODULES, ROW_KEYS
from benchmarks.paper.__main__ import BEGIN, END, available, main


def test_the_quick_run_reports_every_module_in_json_and_the_readme(tmp_path: Path) -> None:
    readme = tmp_path / "README.md"
    readme.write_text(f"# Benchmarks\n\nintro\n\n{BEGIN}\nold table\n{END}\n\nafter\n")
    results = tmp_path / "paper.json"
    rows = main(["--quick", "--results", str(results), "--readme", str(readme)])

    names = available()
    assert {"tf", "png"} <= set(names) <= set(MODULES)
    assert {"Fig. 3", "Table III"} <= {row["figure"] for row in rows}
    assert all(set(ROW_KEYS) <= set(row) for row in rows)
    assert all(isinstance(row["ours"], int | float) for row in rows)
    saved = json.loads(results.read_text())
    assert saved["quick"] is True and saved["modules"] == names
    assert len(saved["rows"]) == len(rows)
    text = readme.read_text()
    assert "old table" not in text and text.startswith("# Benchmarks\n\nintro\n")
    assert text.rstrip().endswith("after")
    assert "| Fig. 3 | client through the republisher | 96.0 |" in text


def test_a_readme_without_markers_gets_a_section(tmp_path: Path) -> None:
    readme = tmp_path / "README.md"
    readme.write_text("# Benchmarks\n")
    results = tmp_path / "p.json"
    main(["--quick", "--only", "png", "--results", str(results), "--readme", str(readme)])
    text = readme.read_text()
    assert text.count(BEGIN) == 1 and text.index(BEGIN) < text.index("Table III") < text.index(END)


def test_only_replaces_its_modules_rows_and_keeps_the_others(tmp_path: Path) -> None:
    readme, results = tmp_path / "README.md", tmp_path / "paper.json"
    readme.write_text(f"# Benchmarks\n\n{BEGIN}\n{END}\n")
    earlier = [
        {
            "figure": figure,
            "metric": "earlier",
            "paper": None,
            "ours": 1.0,
            "unit": "ms",
            "note": "",
        }
        for figure in ("Fig. 3", "Table III")
    ]
    payload = {"quick": True, "machine": "m", "modules": ["tf", "png"], "rows": earlier}
    results.write_text(json.dumps(payload))
    main(["--quick", "--only", "png", "--results", str(results), "--readme", str(readme)])
    saved = json.loads(results.read_text())
    assert saved["modules"] == ["tf", "png"]
    assert [row["figure"] for row in saved["rows"] if row["metric"] == "earlier"] == ["Fig. 3"]
    assert saved["rows"][-1]["figure"] == "Table III"  # the paper's order
    text = readme.read_text()
    assert "| Fig. 3 | earlier |" in text and "tf kept from an earlier run" in text

    payload["quick"] = False  # rows of a full run are not mixed with a quick one
    results.write_text(json.dumps(payload))
    main(["--quick", "--only", "png", "--results", str(results), "--readme", str(readme)])
    assert {row["figure"] for row in json.loads(results.read_text())["rows"]} == {"Table III"}
