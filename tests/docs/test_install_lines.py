"""Every install line and hint names rwt's own distribution, never the PyPI project ``rwt``.

The PyPI name ``rwt`` belongs to an unrelated project: ``pip install "rwt[ros2]"``
installs it (and ``-U`` replaces this one). The distribution is
``rwt_protocol.distribution.DISTRIBUTION``; the docs tests resolve the install
lines of runnable blocks against this checkout (test_code_blocks.py), and this
looks at the prose, the CLI's hints and the error messages too.
"""

from __future__ import annotations

import re
import tomllib

from rwt_protocol.distribution import DISTRIBUTION, install_hint

from .blocks import REPO

# ``pip install rwt``, ``pip install "rwt[zenoh]"``, ``'rwt[video]'``, ``rwt[ros2]`` alone
WRONG = re.compile(r"""pip install ['"]?rwt(?![-\w])|['"`(]rwt\[[a-z0-9_,]+\]""")


def _texts() -> dict[str, str]:
    files = [REPO / "README.md", REPO / "CONTRIBUTING.md", *sorted((REPO / "docs").glob("*.md"))]
    files += sorted((REPO / "src").rglob("*.py")) + sorted((REPO / "examples").rglob("*.py"))
    return {str(path.relative_to(REPO)): path.read_text(encoding="utf-8") for path in files}


def test_no_line_installs_the_other_project() -> None:
    found = [
        f"{name}:{text.count(chr(10), 0, match.start()) + 1}: {match.group(0)}"
        for name, text in _texts().items()
        for match in WRONG.finditer(text)
    ]
    assert found == []


def test_the_distribution_is_the_one_pyproject_builds() -> None:
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["name"] == DISTRIBUTION
    extras = project["optional-dependencies"]
    assert all(
        not re.match(r"rwt\[", dep) for group in extras.values() for dep in group
    )  # the extras that include others name the distribution too
    assert install_hint("zenoh") == f'pip install "{DISTRIBUTION}[zenoh]"'
    assert "zenoh" in extras
