"""The API reference of ``rwt`` and its namespaces builds from the docstrings without a warning.

tests/docs/api_reference.py builds it with pdoc (docs/README.md, "API reference");
this runs that build into a temporary folder, as a user would, offline.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from typing import TYPE_CHECKING

import pytest

from .blocks import REPO

if TYPE_CHECKING:
    from pathlib import Path

if importlib.util.find_spec("pdoc") is None:  # not imported here: the build runs in its own process
    pytest.skip("pdoc is in the test extra: pip install -e '.[test]'", allow_module_level=True)


def test_the_reference_builds_clean_and_names_everything_rwt(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join((str(REPO / "src"), str(REPO)))}
    run = subprocess.run(
        [sys.executable, "-m", "tests.docs.api_reference", str(tmp_path)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert "0 warnings" in run.stdout
    page = (tmp_path / "rwt.html").read_text("utf-8")
    for name in ("Graph", "SessionConfig", "ConfigError", "ListenError"):
        assert f'id="{name}"' in page, name  # every public name has its section
    # a signature's types link to their sections on the same page, as rwt.X
    assert '<a href="#SessionConfig">SessionConfig</a>' in page
    assert "rwt_protocol.server.session.SessionConfig" not in page
    # each namespace has its page, and rwt's signatures link into them
    assert '<a href="rwt/types.html#TypeRegistry">' in page
    for space, name in [("zenoh", "open_zenoh_link"), ("tf", "TFBuffer"), ("bag", "Recorder")]:
        assert f'id="{name}"' in (tmp_path / "rwt" / f"{space}.html").read_text("utf-8")
