"""`rwt play BAG` serves the bag, plays it once and exits 0 with one summary line (not a TTY)."""

from __future__ import annotations

import subprocess
from pathlib import Path

from tests.integration.client_harness import REPO
from tests.support.cli import RWT

from .bags import write_bag


def test_rwt_play_plays_once_and_prints_a_summary(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "robot", "mcap")
    result = subprocess.run(
        [*RWT, "play", str(bag), "--port", "0", "--rate", "4"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env={"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"},
        check=False,
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("listening on ws://127.0.0.1:")
    assert lines[1:] == ["played 37 messages, 0:01.1 of 0:01.1 at 4x"]
