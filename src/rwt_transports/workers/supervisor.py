"""``rwt serve --workers N``: N server processes on one port and one graph, supervised.

Each worker is ``rwt serve`` itself with the same options. The parent listens on the
WebSocket and TCP ports and every worker accepts from those listening sockets,
inherited (``--listen-fd``): one queue of new connections for all, which a worker
takes from while it runs. A worker that dies takes only the connections it had
accepted; those waiting in the queue, and those that come while it restarts, go to a
worker that is up. (With a listening socket of each worker's own, bound with
SO_REUSEPORT, the kernel chose a worker for each connection as it arrived, and reset
the connections it had queued for a worker that was killed: the first connection
after a kill could be reset.) The graphs are linked over Zenoh on loopback: worker 0
listens on a hub endpoint the others connect to (peers then gossip and mesh). The
parent serves nothing: it prints each ``listening on`` line once (when every worker
has said it: they all accept), restarts a worker that dies (logged with the
connections it held, with a growing pause if it keeps dying), and on SIGTERM or
SIGINT stops them all gracefully (docs/scaling.md).
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import subprocess
import sys
import tempfile
from typing import TYPE_CHECKING

import anyio
from anyio.abc import SocketAttribute
from anyio.streams.buffered import BufferedByteReceiveStream

from rwt_protocol.errors import ConfigError

from ..listen import ListenError
from .counts import STATE_PREFIX, read_count, reset_count

if TYPE_CHECKING:
    from collections.abc import Iterator, Mapping, Sequence

    from anyio.abc import SocketStream
    from anyio.streams.stapled import MultiListener

__all__ = [
    "LISTEN_FD_OPTION",
    "WorkerPlan",
    "child_args",
    "parse_listen_fds",
    "reserve_port",
    "reuse_port_supported",
    "run_workers",
]

logger = logging.getLogger("rwt.workers")

STOP_GRACE_S = 10.0
"""How long stopping workers get before they are killed, seconds."""
RESTART_PAUSES_S = (0.5, 1.0, 2.0, 5.0)
"""Pauses before restarting a worker that died; the last repeats."""
STABLE_S = 10.0
"""A worker that ran this long before dying is restarted after the first pause again."""

LISTEN_FD_OPTION = "--listen-fd"
"""A worker's option naming a listening socket it inherits: ``KIND:FD`` (``websocket``
or ``tcp``, and the descriptor), once per socket (``parse_listen_fds``)."""

#: serve options the parent sets itself for each worker (with their value).
_REPLACED = (
    "--workers",
    "--port",
    "--tcp-port",
    "--worker-state",
    "--worker-count",
    LISTEN_FD_OPTION,
)


def reuse_port_supported() -> bool:
    """Whether this platform spreads connections over SO_REUSEPORT sockets (Linux)."""
    return sys.platform.startswith("linux") and hasattr(socket, "SO_REUSEPORT")


def reserve_port(host: str, port: int) -> socket.socket:
    """A bound, not listening, SO_REUSEPORT socket holding ``port`` (0: a free one).

    Raises:
        OSError: the port cannot be bound.
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    return sock


def _without(args: Sequence[str], names: Sequence[str]) -> Iterator[str]:
    """``args`` without the options ``names`` (each with its value, either spelling)."""
    skip = False
    for arg in args:
        if skip:
            skip = False
            continue
        name = arg.split("=", 1)[0]
        if name in names:
            skip = "=" not in arg
            continue
        yield arg


class WorkerPlan:
    """What differs between workers: the ports they share and their Zenoh endpoints.

    Args:
        args: the ``serve`` options as given (``--workers`` and ports are replaced).
        port: the WebSocket port all workers bind (None: no WebSocket).
        tcp_port: the TCP port all workers bind (None: no TCP).
        hub: the loopback endpoint worker 0 listens on; None when the workers
            reach each other otherwise (``--zenoh-mode client``: through a router).
        state_dir: the folder of the workers' connection counts (``worker_counts``);
            None: they keep none.
        count: the number of workers (``--placement topic`` places by it).
        listen_fds: the parent's listening sockets every worker inherits, by kind
            (``websocket``, ``tcp``): their descriptors, one per address bound;
            none for a kind: each worker binds its own.
    """

    def __init__(
        self,
        args: Sequence[str],
        port: int | None,
        tcp_port: int | None,
        hub: str | None,
        state_dir: str | None = None,
        count: int = 1,
        listen_fds: Mapping[str, Sequence[int]] | None = None,
    ) -> None:
        self.args = list(args)
        self.count = count
        self.port = port
        self.tcp_port = tcp_port
        self.hub = hub
        self.state_dir = state_dir
        self.listen_fds = {kind: tuple(fds) for kind, fds in (listen_fds or {}).items()}

    def inherited(self) -> tuple[int, ...]:
        """The descriptors every worker inherits (``pass_fds``)."""
        return tuple(fd for fds in self.listen_fds.values() for fd in fds)

    def state(self, index: int) -> str | None:
        """The connection count file of worker ``index`` (None: not kept)."""
        if self.state_dir is None:
            return None
        return os.path.join(self.state_dir, f"{STATE_PREFIX}{index}")

    def command(self, index: int) -> list[str]:
        """The command line of worker ``index``."""
        return [sys.executable, "-m", "rwt", "serve", *child_args(self, index)]


def child_args(plan: WorkerPlan, index: int) -> list[str]:
    """The ``serve`` options of worker ``index``.

    A ``--zenoh-listen`` of the user goes to worker 0 only: two processes cannot
    listen on one Zenoh endpoint.
    """
    names = [*_REPLACED, *(() if index == 0 else ("--zenoh-listen",))]
    args = list(_without(plan.args, names))
    if plan.port is not None:
        args += ["--port", str(plan.port)]
    if plan.tcp_port is not None:
        args += ["--tcp-port", str(plan.tcp_port)]
    args += ["--reuse-port", "--zenoh"]
    if plan.hub is not None:
        args += ["--zenoh-listen" if index == 0 else "--zenoh-connect", plan.hub]
    if (state := plan.state(index)) is not None:
        args += ["--worker-state", state, "--worker-count", str(plan.count)]
    for kind, fds in plan.listen_fds.items():
        for fd in fds:
            args += [LISTEN_FD_OPTION, f"{kind}:{fd}"]
    return args


def parse_listen_fds(values: Sequence[str]) -> dict[str, tuple[int, ...]]:
    """The ``--listen-fd KIND:FD`` values of a worker, as ``{kind: descriptors}``.

    Raises:
        ValueError: a value is not ``KIND:FD`` with a non-negative integer descriptor.
    """
    fds: dict[str, tuple[int, ...]] = {}
    for value in values:
        kind, _, number = value.partition(":")
        if not kind or not number.isdigit():
            raise ValueError(f"{LISTEN_FD_OPTION} takes KIND:FD, got {value!r}")
        fds[kind] = (*fds.get(kind, ()), int(number))
    return fds


def run_workers(
    count: int, *, host: str, port: int | None, tcp_port: int | None, zenoh_mode: str
) -> int:
    """Run and supervise ``count`` workers until SIGTERM or SIGINT; the exit status.

    The ``serve`` options are read from ``sys.argv`` (after ``serve``). The parent
    listens on the WebSocket and TCP ports (0: a free one) and every worker inherits
    those sockets (module text).

    Raises:
        ConfigError: SO_REUSEPORT is not available (not Linux).
        ListenError: a port cannot be bound (also an ``OSError``).
    """
    if not reuse_port_supported():
        raise ConfigError("--workers needs SO_REUSEPORT to share ports: Linux only")
    argv = sys.argv[1:]
    args = argv[argv.index("serve") + 1 :] if "serve" in argv else argv
    hub = None
    if zenoh_mode == "peer":
        with reserve_port("127.0.0.1", 0) as probe:
            hub = f"tcp/127.0.0.1:{probe.getsockname()[1]}"
    with tempfile.TemporaryDirectory(prefix="rwt-workers-") as state_dir:
        plan = WorkerPlan(args, None, None, hub, state_dir, count)
        return anyio.run(_supervise, plan, host, {"websocket": port, "tcp": tcp_port})


async def _listen(
    host: str, wanted: Mapping[str, int | None], stack: contextlib.AsyncExitStack
) -> dict[str, MultiListener[SocketStream]]:
    """The parent's listening sockets, by kind, held open by ``stack`` while it runs.

    Raises:
        ListenError: a port cannot be bound.
    """
    names = {"websocket": "WebSocket", "tcp": "TCP"}
    listeners = {}
    for kind, port in wanted.items():
        if port is None:
            continue
        try:
            listener = await anyio.create_tcp_listener(local_host=host, local_port=port)
        except OSError as exc:
            raise ListenError(names[kind], host, port, exc) from exc
        listeners[kind] = await stack.enter_async_context(listener)
    return listeners


async def _supervise(plan: WorkerPlan, host: str, wanted: Mapping[str, int | None]) -> int:
    """Listen on the ports ``wanted`` (by kind; 0: a free one), then run the workers."""
    printed = _Announcer(plan.count)
    stopping = anyio.Event()
    async with contextlib.AsyncExitStack() as stack:  # the sockets, held until the end
        listeners = await _listen(host, wanted, stack)
        ports = {kind: each.extra(SocketAttribute.local_port) for kind, each in listeners.items()}
        plan.port, plan.tcp_port = ports.get("websocket"), ports.get("tcp")
        plan.listen_fds = {
            kind: tuple(one.extra(SocketAttribute.raw_socket).fileno() for one in each.listeners)
            for kind, each in listeners.items()
        }
        return await _supervise_all(plan, plan.count, printed, stopping)


class _Announcer:
    """The parent's stdout: each distinct line of the workers' once.

    A ``listening on`` line is printed once every worker has said it, so a client that
    connects on seeing it finds them all accepting; any other line when first said.

    Args:
        count: the number of workers.
    """

    def __init__(self, count: int) -> None:
        self._count = count
        self._printed: set[str] = set()
        self._said: dict[str, set[int]] = {}  # a listening line: the workers that said it

    def said(self, index: int, line: str) -> None:
        """Worker ``index`` wrote ``line`` on its stdout."""
        if line in self._printed:
            return
        if line.startswith("listening on "):
            workers = self._said.setdefault(line, set())
            workers.add(index)
            if len(workers) < self._count:
                return
        self._printed.add(line)
        print(line, flush=True)  # noqa: T201 - the serve command's stdout


async def _supervise_all(
    plan: WorkerPlan, count: int, printed: _Announcer, stopping: anyio.Event
) -> int:
    async with anyio.create_task_group() as tg:
        for index in range(count):
            tg.start_soon(_keep_running, plan, index, printed, stopping)
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for signum in signals:
                logger.info("event=signal name=%s", signal.Signals(signum).name)
                stopping.set()
                break
    return 0


async def _keep_running(
    plan: WorkerPlan, index: int, printed: _Announcer, stopping: anyio.Event
) -> None:
    failures = 0
    while not stopping.is_set():
        started = anyio.current_time()
        code = await _run_once(plan, index, printed, stopping)
        if stopping.is_set():
            logger.info("event=worker_stopped worker=%d code=%s", index, code)
            return
        if anyio.current_time() - started > STABLE_S:
            failures = 0
        pause = RESTART_PAUSES_S[min(failures, len(RESTART_PAUSES_S) - 1)]
        failures += 1
        state = plan.state(index)
        held = read_count(state) if state is not None else None
        logger.warning(
            "event=worker_exit worker=%d code=%s connections=%s restart_in_s=%g",
            index,
            code,
            "unknown" if held is None else held,
            pause,
        )
        with anyio.move_on_after(pause):
            await stopping.wait()


async def _run_once(
    plan: WorkerPlan, index: int, printed: _Announcer, stopping: anyio.Event
) -> int | None:
    if (state := plan.state(index)) is not None:
        with contextlib.suppress(OSError):  # without it the log says connections=unknown
            reset_count(state)  # a restarted worker starts from none
    process = await anyio.open_process(
        plan.command(index), stdin=subprocess.DEVNULL, stderr=None, pass_fds=plan.inherited()
    )
    logger.info("event=worker_started worker=%d pid=%d", index, process.pid)
    assert process.stdout is not None
    stdout = BufferedByteReceiveStream(process.stdout)

    async def relay() -> None:
        """Print each distinct stdout line once (``_Announcer``)."""
        with contextlib.suppress(
            anyio.EndOfStream, anyio.IncompleteRead, anyio.BrokenResourceError
        ):
            while True:
                line = (await stdout.receive_until(b"\n", 65536)).decode("utf-8", "replace")
                printed.said(index, line)

    async def stop_when_asked() -> None:
        await stopping.wait()
        with contextlib.suppress(ProcessLookupError):
            process.send_signal(signal.SIGTERM)
        with anyio.move_on_after(STOP_GRACE_S):
            await process.wait()
        with contextlib.suppress(ProcessLookupError):
            process.kill()

    try:
        async with anyio.create_task_group() as tg:
            tg.start_soon(relay)
            tg.start_soon(stop_when_asked)
            code = await process.wait()
            tg.cancel_scope.cancel()
    finally:
        with contextlib.suppress(ProcessLookupError):
            process.kill()  # only if the supervisor itself is cancelled mid-way
    return code
