"""`rwt serve --zenoh` processes and real clients running beside them, bounded and always killed.

``serving`` starts a server on a random WebSocket port whose Zenoh endpoints are
all on 127.0.0.1 (checked as in ``support``); ``Process.line`` reads the next
stdout line within a bound; every process is killed when its block ends.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING

import anyio
from anyio.abc import Process as AnyioProcess
from anyio.streams.buffered import BufferedByteReceiveStream

from rwt_zenoh.config import ZenohOptions
from tests.support.cli import RWT, RWT_COLD

from .support import checked

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

REPO = Path(__file__).resolve().parents[2]
JS_DIR = REPO / "tests" / "js"
LINE_TIMEOUT_S = 30.0


class Process:
    """A child process whose stdout is read line by line."""

    def __init__(self, process: AnyioProcess, name: str, log: Path) -> None:
        self.process = process
        self.name = name
        self.log = log
        assert process.stdout is not None
        self._stdout = BufferedByteReceiveStream(process.stdout)

    async def line(self, within: float = LINE_TIMEOUT_S) -> str:
        """The next stdout line.

        Raises:
            AssertionError: none within ``within`` seconds or the process ended; with its stderr.
        """
        try:
            with anyio.fail_after(within):
                raw = await self._stdout.receive_until(b"\n", 1 << 20)
        except (TimeoutError, anyio.EndOfStream, anyio.IncompleteRead) as exc:
            raise AssertionError(f"{self.name}: no line ({exc!r})\n{self.stderr()}") from None
        return raw.decode("utf-8", "replace")

    async def rest(self) -> str:
        """Everything left on stdout, once the process has ended."""
        chunks = []
        with anyio.fail_after(LINE_TIMEOUT_S), contextlib.suppress(anyio.EndOfStream):
            while True:
                chunks.append(await self._stdout.receive())
        return b"".join(chunks).decode("utf-8", "replace")

    def stderr(self) -> str:
        """What it wrote on stderr so far (the last 4000 characters: for a message)."""
        return self.whole_stderr()[-4000:]

    def whole_stderr(self) -> str:
        """Everything it wrote on stderr so far (to count lines in)."""
        return self.log.read_text("utf-8", "replace")

    def kill(self) -> None:
        """SIGKILL it (a crash, as far as others can tell)."""
        with contextlib.suppress(ProcessLookupError):
            self.process.kill()


@contextlib.asynccontextmanager
async def started(cmd: list[str], name: str, cwd: Path = REPO) -> AsyncIterator[Process]:
    """Run ``cmd``; stderr goes to a temporary file; killed when the block ends.

    The process leads a session of its own, and the whole group is killed: the
    workers of ``rwt serve --workers`` outlived their killed supervisor before,
    and every run of the suite left two servers behind.
    """
    env = {**os.environ, "PYTHONPATH": str(REPO / "src"), "PYTHONUNBUFFERED": "1"}
    with tempfile.NamedTemporaryFile(prefix="rwt-zenoh-", suffix=".log") as log:
        process = await anyio.open_process(
            cmd, cwd=cwd, env=env, stdin=subprocess.PIPE, stderr=log.file, start_new_session=True
        )
        try:
            yield Process(process, name, Path(log.name))
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
            with anyio.move_on_after(10):
                # its pipes too: a warm run's child holds them until the zygote has killed it
                await process.aclose()


def rwt(*args: str, cold: bool = False) -> list[str]:
    """The command line of ``rwt ARGS``: forked by the test worker's warm ``rwt``
    (tests/support/zygote.py), or ``cold``, a new interpreter, for a test that reads
    the server's own process (its pid, children or memory). ``--workers`` is always
    cold: its workers must be in the process group ``started`` kills (a warm run's
    group is the zygote's, and its workers outlived the supervisor the zygote killed).
    """
    cold = cold or "--workers" in args
    return [*(RWT_COLD if cold else RWT), *args]


@contextlib.asynccontextmanager
async def serving(
    name: str,
    *,
    listen: str | None = None,
    connect: tuple[str, ...] = (),
    extra: tuple[str, ...] = (),
    cold: bool = False,
) -> AsyncIterator[tuple[Process, str]]:
    """``rwt serve --zenoh`` on 127.0.0.1 only; yields the process and its ws:// URL.

    ``cold``: a new interpreter (``rwt``), for a test that reads the server's process.
    """
    args = ["serve", "--port", "0", "--zenoh", "--no-tf"]
    # the config the server makes of these options: loopback only, multicast off
    mode = extra[extra.index("--zenoh-mode") + 1] if "--zenoh-mode" in extra else "peer"
    checked(ZenohOptions(mode=mode, listen=(listen,) if listen else (), connect=connect))
    if listen:
        args += ["--zenoh-listen", listen]
    for each in connect:
        args += ["--zenoh-connect", each]
    async with started(rwt(*args, *extra, cold=cold), name) as process:
        first = await process.line()
        assert first.startswith("listening on ws://"), first
        yield process, first.removeprefix("listening on ").strip()


def python_client(code: str, name: str) -> contextlib.AbstractAsyncContextManager[Process]:
    """A Python client script (roslibpy) running beside the test."""
    return started([sys.executable, "-c", textwrap.dedent(code)], name)


@contextlib.asynccontextmanager
async def node_client(code: str, name: str) -> AsyncIterator[Process]:
    """An ES module with roslib importable (tests/js/node_modules), running beside the test."""
    script = JS_DIR / f".rwt-zenoh-{os.getpid()}-{name}.mjs"
    script.write_text(textwrap.dedent(code), "utf-8")
    try:
        async with started([shutil.which("node") or "node", str(script)], name, JS_DIR) as p:
            yield p
    finally:
        script.unlink(missing_ok=True)
