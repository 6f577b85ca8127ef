"""Runs tests/js/foxglove_extras.mjs, the real Foxglove client in Node, for a scenario."""

from __future__ import annotations

import json
import shutil
import subprocess
from typing import Any

from tests.integration.client_harness import JS_DIR, node_missing_reason

SCRIPT = JS_DIR / "foxglove_extras.mjs"


def missing() -> str | None:
    """Why the Node client cannot run here, or None."""
    if (reason := node_missing_reason()) is not None:
        return reason
    if not (JS_DIR / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        return "tests/js/node_modules lacks @foxglove/ws-protocol: run `npm ci --prefix tests/js`"
    return None


def command(scenario: str, url: str, *args: str, script: str = SCRIPT.name) -> list[str]:
    """The command line of ``scenario`` against ``url`` (``script``: a file of tests/js)."""
    node = shutil.which("node")
    assert node is not None
    return [node, str(JS_DIR / script), scenario, url, *args]


def result_of(stdout: str) -> Any:
    """The scenario's result: its last stdout line's ``result``."""
    return json.loads(stdout.strip().splitlines()[-1])["result"]


def run(scenario: str, url: str, *args: str, script: str = SCRIPT.name) -> Any:
    """Run ``scenario`` of ``script`` to its end (bounded: 120 s) and return its result."""
    done = subprocess.run(
        command(scenario, url, *args, script=script),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd=JS_DIR,
    )
    assert done.returncode == 0, done.stderr
    return result_of(done.stdout)
