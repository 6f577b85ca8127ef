"""Run real, unmodified clients (roslibpy; roslib in Node) in subprocesses, bounded in time."""

from __future__ import annotations

import os
import shutil
import subprocess
import textwrap
from pathlib import Path

import anyio

from tests.support.warm import PYTHON

REPO = Path(__file__).resolve().parents[2]
JS_DIR = REPO / "tests" / "js"
CLIENT_TIMEOUT_S = 60


def node_missing() -> str | None:
    """Why roslib-in-Node cannot run here, or None."""
    if shutil.which("node") is None:
        return "node is not on PATH"
    if not (JS_DIR / "node_modules" / "roslib").is_dir():
        return "tests/js/node_modules is missing: run `npm ci --prefix tests/js`"
    return None


async def run_python(code: str, env: dict[str, str] | None = None) -> str:
    """Run ``code`` with this interpreter; return its stdout.

    Raises:
        AssertionError: it failed or timed out; the message has its stderr.
    """
    return await _run([*PYTHON, "-c", textwrap.dedent(code)], env, REPO)


async def run_node(code: str) -> str:
    """Run an ES module with roslib importable (tests/js/node_modules); return its stdout."""
    script = JS_DIR / f".rwt-test-{os.getpid()}.mjs"
    script.write_text(textwrap.dedent(code), "utf-8")
    try:
        return await _run([shutil.which("node") or "node", str(script)], None, JS_DIR)
    finally:
        script.unlink(missing_ok=True)


async def run_command(*cmd: str) -> str:
    """Run ``cmd`` (a client's command line) in tests/js; return its stdout.

    Raises:
        AssertionError: it failed or timed out; the message has its stderr.
    """
    return await _run(list(cmd), None, JS_DIR)


async def _run(cmd: list[str], env: dict[str, str] | None, cwd: Path) -> str:
    full_env = {**os.environ, **(env or {}), "PYTHONPATH": str(REPO / "src")}
    with anyio.fail_after(CLIENT_TIMEOUT_S):
        result = await anyio.run_process(
            cmd, env=full_env, cwd=cwd, check=False, stdin=subprocess.DEVNULL
        )
    out = result.stdout.decode("utf-8", "replace")
    err = result.stderr.decode("utf-8", "replace")
    assert result.returncode == 0, (
        f"{cmd[0]} exited {result.returncode}\nstdout:\n{out}\nstderr:\n{err}"
    )
    return out
