"""rwt's packages as the source tree has them: lists of packages are found, never typed in."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SRC = REPO / "src"


def packages() -> list[str]:
    """Every package under ``src/`` (a directory with an ``__init__.py``), sorted."""
    return sorted(p.name for p in SRC.iterdir() if (p / "__init__.py").is_file())
