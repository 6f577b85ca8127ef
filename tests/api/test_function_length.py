"""No function in src/ is longer than 90 lines: a longer one is split into named steps.

Measured from the ``def`` (decorators excluded) to its last line, docstring and
signature included, so a command with dozens of options cannot hide its length
in its parameter list (``rwt serve`` takes its options as groups instead:
``rwt_cli.groups``).
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src"
MAX_LINES = 90


def long_functions(root: Path, limit: int) -> list[str]:
    """``path:line name (N lines)`` of each function under ``root`` longer than ``limit``."""
    found = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text("utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > limit:
                    where = path.relative_to(root.parent)
                    found.append(f"{where}:{node.lineno} {node.name} ({length} lines)")
    return found


def test_no_function_in_src_is_longer_than_90_lines() -> None:
    assert long_functions(SRC, MAX_LINES) == []


def test_the_check_sees_a_long_function(tmp_path: Path) -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_LINES))
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "long.py").write_text(f"async def long() -> None:\n{body}\n")
    assert long_functions(tmp_path / "pkg", MAX_LINES) == [
        f"pkg/long.py:1 long ({MAX_LINES + 1} lines)"
    ]
