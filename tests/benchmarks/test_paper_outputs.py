"""`python -m benchmarks.paper --quick` leaves the tracked results alone."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from benchmarks.paper.__main__ import QUICK_DIR, README, RESULTS, output_paths

REPO = Path(__file__).resolve().parents[2]


def test_a_full_run_writes_the_tracked_results() -> None:
    assert output_paths(quick=False) == (RESULTS, README)
    assert RESULTS == REPO / "benchmarks" / "results" / "paper.json"
    assert README == REPO / "benchmarks" / "README.md"


def test_a_quick_run_writes_elsewhere() -> None:
    results, readme = output_paths(quick=True)
    assert results not in (RESULTS, README) and readme not in (RESULTS, README)
    assert results.is_relative_to(QUICK_DIR) and readme.is_relative_to(QUICK_DIR)


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not on PATH")
def test_the_quick_folder_is_git_ignored() -> None:
    probe = QUICK_DIR / "paper.json"
    ignored = subprocess.run(
        ["git", "check-ignore", "-q", str(probe)], cwd=REPO, check=False, timeout=30
    )
    assert ignored.returncode == 0, f"{QUICK_DIR} is not git-ignored"


def test_paths_given_explicitly_win(tmp_path: Path) -> None:
    results, readme = tmp_path / "p.json", tmp_path / "R.md"
    assert output_paths(quick=True, results=results, readme=readme) == (results, readme)
    assert output_paths(quick=False, results=results) == (results, README)
