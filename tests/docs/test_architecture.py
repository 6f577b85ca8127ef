"""The contributor's map is true of the code: docs/architecture.md and the module maps.

docs/architecture.md draws every package and names modules, attributes and test
files; each must exist. The README's layout table has a row for every package.
``rwt_graph``, ``rwt_foxglove``, the connection runtime and ``rwt_transports`` with
each of its rooms map their modules in their docstrings; each module and subpackage
must be on the map.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

from tests.support.packages import REPO, SRC, packages

MAP_PAGES = [REPO / "docs" / "architecture.md", REPO / "CONTRIBUTING.md"]

# ``rwt_graph.mirror``, ``rwt_protocol.runtime.flow.FlowControl``, ``rwt_protocol/ops/``
DOTTED = re.compile(r"`(rwt_[a-z0-9_]+(?:\.[A-Za-z_][A-Za-z0-9_]*)*)`")
SLASHED = re.compile(r"`((?:rwt_[a-z0-9_]+|tests)(?:/[A-Za-z0-9_.]+)+/?)`")


def resolves(dotted: str) -> bool:
    """Whether ``dotted`` is a module, or an attribute of one (``module.Class.attr``)."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            value: object = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for name in parts[cut:]:
            if not hasattr(value, name):
                return False
            value = getattr(value, name)
        return True
    return False


def test_the_layer_drawing_names_every_package() -> None:
    text = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    drawing = text.split("## Layers", 1)[1].split("```text", 1)[1].split("```", 1)[0]
    assert [name for name in packages() if name not in drawing.split()] == []


def test_the_readme_layout_table_has_a_row_for_every_package_and_no_other() -> None:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    table = text.split("## Layout", 1)[1].split("\n\n", 2)[1]
    rows = re.findall(r"^\| `(rwt[a-z0-9_]*)` \|", table, flags=re.MULTILINE)
    assert len(rows) == len(set(rows))
    assert sorted(rows) == packages()


@pytest.mark.parametrize("page", MAP_PAGES, ids=lambda page: page.name)
def test_every_module_and_file_the_map_names_exists(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    dotted = sorted(set(DOTTED.findall(text)))
    slashed = sorted(set(SLASHED.findall(text)))
    assert dotted, "the page names no module: the pattern is stale"
    missing = [name for name in dotted if not resolves(name)]
    missing += [
        path for path in slashed if not (SRC / path).exists() and not (REPO / path).exists()
    ]
    assert missing == []


MAPPED = [
    "rwt_graph",
    "rwt_foxglove",
    "rwt_protocol.runtime",
    "rwt_transports",
    *(
        f"rwt_transports.{p.name}"
        for p in sorted((SRC / "rwt_transports").iterdir())
        if (p / "__init__.py").is_file()
    ),
]
"""Packages whose docstring maps every module and subpackage: the runtime and the server's
rooms (each room of ``rwt_transports`` is found, never typed in)."""


@pytest.mark.parametrize("package", MAPPED)
def test_a_package_docstring_maps_every_module(package: str) -> None:
    doc = importlib.import_module(package).__doc__ or ""
    root = SRC / package.replace(".", "/")
    parts = sorted(
        p.stem if p.is_file() else p.name
        for p in root.iterdir()
        if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").is_file()
    )
    # a subpackage of shipped data has no __init__.py: named too, but not required here
    assert [name for name in parts if f"``{name}``" not in doc] == []
