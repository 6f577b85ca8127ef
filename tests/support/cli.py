"""The ``rwt`` command line of this checkout, run as a user runs it: in a subprocess.

``run_rwt`` runs a command to its end; ``rwt_serve`` starts ``rwt serve`` and
yields once it listens. Both run this checkout's ``src`` whatever is installed.
``invoke_rwt`` runs a command in this process (typer's runner), for the many
small cases of options refused before anything starts.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import AsyncIterator, Mapping
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

import anyio
from anyio.streams.buffered import BufferedByteReceiveStream
from typer.testing import CliRunner

from rwt_cli.app import app
from tests.support.warm import WARM_RWT, rwt_env

if TYPE_CHECKING:
    from pathlib import Path

    from anyio.abc import Process
    from click.testing import Result

ENV = rwt_env()
#: ``rwt``, forked by this worker's warm ``rwt`` where it can be (tests/support/zygote.py).
RWT = [sys.executable, "-S", str(WARM_RWT)]
#: ``rwt`` started from scratch: for tests that look at the server's own process.
RWT_COLD = [sys.executable, "-m", "rwt"]
SERVE = [*RWT, "serve", "--host", "127.0.0.1"]
TIMEOUT_S = 60  # a bound on a hung process, not a speed requirement


def run_rwt(
    *args: str,
    cwd: Path | None = None,
    env: Mapping[str, str] | None = None,
    timeout: float = TIMEOUT_S,
    command: list[str] = RWT,
) -> subprocess.CompletedProcess[str]:
    """Run ``rwt ARGS`` to its end, stdin closed; its exit code and text output.

    Args:
        args: the command line after ``rwt``.
        cwd: the working directory (None: this process's).
        env: variables set over this process's environment.
        timeout: seconds before the run is killed and the test fails (a hang guard).
        command: what runs instead of ``python -m rwt`` (a wrapper script).
    """
    return subprocess.run(
        [*command, *args],
        env={**ENV, **(env or {})},
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def invoke_rwt(*args: str) -> Result:
    """Run ``rwt ARGS`` in this process: its ``exit_code``, ``output`` and ``stderr``."""
    return CliRunner().invoke(app, list(args), prog_name="rwt")


@asynccontextmanager
async def rwt_serve(
    *args: str, listeners: int = 1
) -> AsyncIterator[tuple[Process, dict[str, str]]]:
    """Start `rwt serve ARGS`; yield the process and its URLs by scheme once all are listening."""
    process = await anyio.open_process(
        [*SERVE, *args], env=ENV, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    urls: dict[str, str] = {}
    try:
        assert process.stdout is not None
        stdout = BufferedByteReceiveStream(process.stdout)
        with anyio.fail_after(20):
            while len(urls) < listeners:
                line = (await stdout.receive_until(b"\n", 1000)).decode()
                url = line.removeprefix("listening on ")
                urls[url.split("://")[0]] = url
        yield process, urls
    finally:
        if process.returncode is None:
            process.kill()
        with anyio.fail_after(10):
            await process.aclose()  # its pipes too: a killed run may hold them a moment longer


def port(url: str) -> int:
    """The port of a URL that ends with one (``ws://127.0.0.1:9090`` -> 9090)."""
    return int(url.rsplit(":", 1)[1])
