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
