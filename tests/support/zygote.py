"""A warm ``rwt``: one process per test worker that imports the CLI once and forks each run.

The suite starts ``python -m rwt`` about 300 times; each start paid about 0.45 s of
CPU for the interpreter and rwt's imports before doing anything of its own (a fifth
of the suite's CPU on two cores: CONTRIBUTING.md, "Suite time"). Here that is paid
once per worker: ``python zygote.py SOCKET`` imports the commands and waits on a Unix
socket; ``warm_rwt.py`` (what tests run as ``rwt``) connects, hands over its argv,
working directory, environment, open-file limit and its stdin, stdout and stderr,
and this process forks a child that runs ``rwt`` in them, as a new interpreter
would from there on: a real process with its own pid, exit code and signals.

What a fork cannot give is a different start: an environment that differs in what is
read at import (``PYTHON*``, ``RWT_*``, the library path) is answered ``cold``, and
``warm_rwt.py`` then execs the real ``python -m rwt`` itself. Tests that look at the
server's own process (its memory, its children) start it cold (``RWT_COLD``,
``ServerProcess(cold=True)``); the docs' blocks and tests/cli/test_lazy_imports.py
start real ``rwt`` commands from scratch, so the start itself stays tested.

Wire (one connection a run): the client sends one JSON line ``{"argv", "cwd", "env",
"nofile", "ignored"}`` with its fds 0, 1 and 2 attached (``SCM_RIGHTS``); the zygote answers
``cold``, or ``pid N`` and, when the child ends, ``exit STATUS`` (``waitpid``'s).
If the client goes away first, the child is killed.
"""

from __future__ import annotations

import array
import atexit
import contextlib
import gc
import importlib
import io
import json
import os
import resource
import runpy
import selectors
import signal
import socket
import sys
import threading
import traceback
import types
from collections.abc import Callable

# run as a script: its folder is sys.path[0]
from pycache import reuse_installed

#: The commands a test worker runs most.
PRELOAD = (
    "rwt_cli.app",
    "rwt_cli.serve",
    "rwt_cli.play",
    "rwt_cli.record",
    "rwt_cli.bag",
    "rwt_conformance.cli",
)
#: What ``rwt mcp`` and ``rwt serve --mcp`` load (the MCP SDK, 0.6 s of CPU a start), for
#: the 20 or so runs a suite makes of them; without the SDK those commands refuse to start,
#: and every other run stays warm.
PRELOAD_OPTIONAL = ("rwt_mcp.cli", "rwt_transports.http.mcp")
#: What Python clients of the tests import before they connect (roslibpy's twisted):
#: preloaded for ``--python`` runs. Not the reactor, which opens a descriptor, nor
#: autobahn's twisted half, which sets txaio to twisted for good (roslibpy's asyncio
#: transport needs it unset).
PRELOAD_CLIENTS = (
    "twisted.internet.epollreactor",
    "twisted.internet.protocol",
    "twisted.internet.defer",
    "twisted.internet.task",
    "twisted.internet.threads",
    "roslibpy",
)
#: What the tests' rclpy nodes (tests/ros2/peer.py) import: preloaded by a zygote of their
#: own (``zygote.py SOCKET ENV ros2``, ``warm.ros2_socket``), which forks no ``rwt`` run:
#: importing rclpy starts threads (C++ ones), and a fork copies their locks, not them.
PRELOAD_ROS2 = (
    "rclpy",
    "rclpy.action",
    "rclpy.callback_groups",
    "rclpy.executors",
    "rclpy.parameter",
    "rclpy.qos",
    "builtin_interfaces.msg",
    "geometry_msgs.msg",
    "rcl_interfaces.msg",
    "rcl_interfaces.srv",
    "rosgraph_msgs.msg",
    "sensor_msgs.msg",
    "std_msgs.msg",
    "std_srvs.srv",
)
#: Variables read while Python starts or rwt imports: a run whose values differ is cold.
IMPORT_TIME = ("PYTHON", "RWT_", "LD_", "LANG", "LC_")
MAX_REQUEST = 1 << 20
#: This process's own ``PYTHONPATH`` entries, which a run's replace.
_ZYGOTE_PATH = {p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p}


#: Read again in the child (its stdio, its ``sys.path``): these may differ.
PER_RUN = ("RWT_TEST_WARM", "PYTHONUNBUFFERED", "PYTHONPATH")


def _import_env(env: dict[str, str]) -> dict[str, str]:
    """What of ``env`` a started interpreter has already read, and the checkout of rwt."""
    kept = {k: v for k, v in env.items() if k.startswith(IMPORT_TIME) and k not in PER_RUN}
    kept["rwt from"] = env.get("PYTHONPATH", "").split(os.pathsep)[0]
    # ROS 2's wheels set this at start-up in an order of their own: the entries are what count
    kept["LD_LIBRARY_PATH"] = ":".join(sorted(set(env.get("LD_LIBRARY_PATH", "").split(":"))))
    return kept


def _set_path(cwd: str) -> None:
    """``sys.path`` as ``python -m`` makes it in ``cwd`` with this run's ``PYTHONPATH``."""
    ours = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    base = [p for p in sys.path[1:] if p not in _ZYGOTE_PATH]
    sys.path[:] = [cwd, *ours, *base]


def _reset_stdio() -> None:
    """New ``sys.std*`` on fds 0-2, as the interpreter makes them at start."""
    unbuffered = bool(os.environ.get("PYTHONUNBUFFERED"))
    encoding = sys.__stdout__.encoding if sys.__stdout__ else "utf-8"
    stdin = open(0, "rb", closefd=False)  # noqa: SIM115 - sys.stdin's, for the run's life
    sys.stdin = sys.__stdin__ = io.TextIOWrapper(stdin, encoding=encoding, errors="strict")
    for fd, errors, name in ((1, "strict", "stdout"), (2, "backslashreplace", "stderr")):
        raw = open(fd, "wb", buffering=0 if unbuffered else -1, closefd=False)  # noqa: SIM115
        tty = os.isatty(fd)
        stream = io.TextIOWrapper(
            raw,  # type: ignore[arg-type]
            encoding=encoding,
            errors=errors,
            line_buffering=tty or fd == 2,
            write_through=unbuffered,
        )
        setattr(sys, name, stream)
        setattr(sys, f"__{name}__", stream)


def _run_child(request: dict, fds: list[int], own: list[int]) -> None:
    """In the forked child: become ``rwt ARGV`` in the caller's stdio, cwd and env."""
    status = 1
    try:
        for fd in own:
            with contextlib.suppress(OSError):
                os.close(fd)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        for number in (signal.SIGTERM, signal.SIGHUP, signal.SIGUSR1, signal.SIGUSR2):
            signal.signal(number, signal.SIG_DFL)
        for number in request["ignored"]:
            signal.signal(number, signal.SIG_IGN)
        for target, fd in enumerate(fds):
            os.dup2(fd, target)
            os.close(fd)
        os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        soft, hard = request["nofile"]
        if (soft, hard) != resource.getrlimit(resource.RLIMIT_NOFILE):
            resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
        _reset_stdio()
        status = _main(_runner(request))
    finally:
        with contextlib.suppress(BaseException):
            threading._shutdown()  # type: ignore[attr-defined] # as the interpreter's exit
        with contextlib.suppress(BaseException):
            atexit._run_exitfuncs()
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(BaseException):
                stream.flush()
        os._exit(status)


def _runner(request: dict) -> Callable[[], object]:
    """Set ``sys.argv`` and ``sys.path`` as the interpreter would for the run; what runs it.

    ``rwt ARGS``, or with ``"python"`` a Python command line: ``-c CODE ARGS`` or
    ``SCRIPT ARGS`` (``sys.path[0]`` then ``''`` or the script's folder, as Python sets it).
    """
    argv = request["argv"]
    if not request.get("python"):
        _set_path(os.getcwd())
        main = importlib.import_module("rwt").__file__
        sys.argv = [os.path.join(os.path.dirname(main or ""), "__main__.py"), *argv]
        return lambda: runpy.run_module("rwt", run_name="__main__", alter_sys=True)
    if argv[0] == "-c":
        _set_path("")
        sys.argv = ["-c", *argv[2:]]
        code = compile(argv[1], "<string>", "exec")
        main = types.ModuleType("__main__")
        sys.modules["__main__"] = main
        return lambda: exec(code, main.__dict__)
    script = os.path.abspath(argv[0])
    _set_path(os.path.dirname(script))
    sys.argv = list(argv)
    return lambda: runpy.run_path(script, run_name="__main__")


def _main(run: Callable[[], object]) -> int:
    """Run as the interpreter runs its main module; the exit status."""
    try:
        run()
    except SystemExit as exc:
        if exc.code is None:
            return 0
        if isinstance(exc.code, int):
            return exc.code & 0xFF
        print(exc.code, file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # as the interpreter: killed by the SIGINT it did not handle
        traceback.print_exc()
        sys.stderr.flush()
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGINT)
        return 130
    except BaseException:
        traceback.print_exc()
        return 1
    return 0


def _prebuild() -> None:
    """What most runs build first, built here once: each dialect's type store.

    A registry of the default definitions shares the store built for them
    (``TypeRegistry.typestore``): building one took a run 0.2-0.5 s of CPU (rosbags
    makes each type's class and serializer), the first thing a bag, a recording, a
    Zenoh link or a binary encoding asked for. A run with definitions of its own
    builds its own, as it would have.
    """
    try:
        from rwt_graph.types.names import Dialect  # noqa: PLC0415 - as the preload
        from rwt_graph.types.registry import TypeRegistry  # noqa: PLC0415

        for dialect in Dialect:
            TypeRegistry(dialect).typestore()
    except Exception:  # another rwt: its runs build theirs
        traceback.print_exc()


class _Run:
    def __init__(self, conn: socket.socket) -> None:
        self.conn = conn
        self.buffer = b""
        self.fds: list[int] = []
        self.pid: int | None = None
        self.pidfd: int | None = None


class Zygote:
    """The fork server: accepts runs, forks them, reports their ends."""

    def __init__(self, path: str, start_env: str) -> None:
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.listener.bind(path)
        self.listener.listen(64)
        self.selector = selectors.DefaultSelector()
        self.selector.register(self.listener, selectors.EVENT_READ, None)
        self.selector.register(sys.stdin, selectors.EVENT_READ, "parent")
        with open(start_env, encoding="utf-8") as file:  # as given, before site's .pth files
            given: dict[str, str] = json.load(file)
        self.env = _import_env(given)
        #: What site's start-up hooks changed in the environment, as they would in each run.
        self.site_set = {k: v for k, v in os.environ.items() if given.get(k) != v}
        self.site_unset = [k for k in given if k not in os.environ]
        self.warm = True
        self.warm_python = True
        self.warm_rwt = True  # False in the rclpy zygote: its runs are Python command lines
        self.runs: set[_Run] = set()

    def preload(self, kind: str = "rwt") -> None:
        if kind == "ros2":
            self.warm_rwt = False
        for name in PRELOAD if self.warm_rwt else ():
            try:
                importlib.import_module(name)
            except Exception:  # a command that cannot load runs cold
                self.warm = False
        for name in PRELOAD_OPTIONAL if self.warm_rwt else ():
            with contextlib.suppress(ImportError):
                importlib.import_module(name)
        for name in PRELOAD_CLIENTS if self.warm_rwt else PRELOAD_ROS2:
            try:
                importlib.import_module(name)
            except Exception:  # a client that cannot load runs cold
                self.warm_python = False
        if os.getenv("COVERAGE_PROCESS_START") or os.getenv("COVERAGE_PROCESS_CONFIG"):
            self.warm = False  # coverage of subprocesses: each run measured from its start
        if "twisted.internet.reactor" in sys.modules:  # its poller would be every run's
            self.warm = self.warm_python = False
        if threading.active_count() > 1:  # a fork would copy a thread's locks, not the thread
            self.warm = False
        if self.warm and self.warm_rwt:
            _prebuild()
        # What is loaded now is every run's: out of the collector's sight, so that a run's
        # collections (rwt serve's own gc.freeze at start) do not walk it all again, nor
        # touch its pages (copied on write).
        gc.collect()
        gc.freeze()

    def own_fds(self) -> list[int]:
        return [key.fd for key in self.selector.get_map().values()] + [self.selector.fileno()]

    def serve(self) -> None:
        """Serve runs until the test worker ends; a run's trouble never ends the zygote."""
        while True:
            for key, _ in self.selector.select():
                if self.selector.get_map().get(key.fd) is not key:
                    continue  # unregistered by an event before it in this batch
                try:
                    if self._event(key.data):
                        return
                except Exception:  # logged; the worker's other runs go on
                    traceback.print_exc()

    def _event(self, data: object) -> bool:
        """Handle one ready source; True when the worker has ended."""
        if data is None:
            conn, _ = self.listener.accept()
            run = _Run(conn)
            self.runs.add(run)
            self.selector.register(conn, selectors.EVENT_READ, run)
        elif data == "parent":  # the test worker's pipe: closed when it ends
            if not os.read(sys.stdin.fileno(), 4096):
                for run in list(self.runs):
                    self._drop(run, kill=True)
                return True
        elif isinstance(data, tuple):
            self._ended(data[0])
        elif isinstance(data, _Run):
            self._readable(data)
        return False

    def _readable(self, run: _Run) -> None:
        try:
            data, ancdata, _, _ = run.conn.recvmsg(65536, socket.CMSG_SPACE(3 * 4))
        except OSError:
            data, ancdata = b"", []
        for level, kind, payload in ancdata:
            if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
                fds = array.array("i")
                fds.frombytes(payload[: len(payload) - len(payload) % fds.itemsize])
                run.fds.extend(fds)
        if not data:  # the client went away: so does its child
            self._drop(run, kill=True)
            return
        if run.pid is not None:
            return
        run.buffer += data
        if not run.buffer.endswith(b"\n"):
            if len(run.buffer) > MAX_REQUEST:
                self._drop(run, kill=False)
            return
        self._start(run, json.loads(run.buffer))

    def _start(self, run: _Run, request: dict) -> None:
        python = bool(request.get("python"))
        warm = self.warm and (self.warm_python if python else self.warm_rwt)
        if not warm or len(run.fds) != 3 or _import_env(request["env"]) != self.env:
            self._reply(run, b"cold\n")
            self._drop(run, kill=False)
            return
        own = self.own_fds()
        env = {**request["env"], **self.site_set}
        for name in self.site_unset:
            env.pop(name, None)
        pid = os.fork()
        if pid == 0:
            _run_child({**request, "env": env}, run.fds, own)
        for fd in run.fds:
            os.close(fd)
        run.fds = []
        run.pid = pid
        run.pidfd = os.pidfd_open(pid)
        self.selector.register(run.pidfd, selectors.EVENT_READ, (run,))
        self._reply(run, f"pid {pid}\n".encode())

    def _ended(self, run: _Run) -> None:
        if run.pid is None:
            return
        _, status = os.waitpid(run.pid, 0)
        self._close_pidfd(run)
        run.pid = None
        self._reply(run, f"exit {status}\n".encode())
        self._drop(run, kill=False)

    def _reply(self, run: _Run, line: bytes) -> None:
        with contextlib.suppress(OSError):
            run.conn.sendall(line)

    def _close_pidfd(self, run: _Run) -> None:
        if run.pidfd is not None:
            self.selector.unregister(run.pidfd)
            os.close(run.pidfd)
            run.pidfd = None

    def _drop(self, run: _Run, *, kill: bool) -> None:
        if kill and run.pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(run.pid, signal.SIGKILL)
            with contextlib.suppress(ChildProcessError):
                os.waitpid(run.pid, 0)
            run.pid = None
            self._close_pidfd(run)
        for fd in run.fds:
            os.close(fd)
        run.fds = []
        with contextlib.suppress(KeyError, ValueError):
            self.selector.unregister(run.conn)
        run.conn.close()
        self.runs.discard(run)


def main() -> None:
    reuse_installed()  # before the preload: installed modules' own bytecode (pycache.py)
    zygote = Zygote(sys.argv[1], sys.argv[2])
    zygote.preload(*sys.argv[3:4])  # "ros2": the tests' rclpy nodes
    zygote.serve()


if __name__ == "__main__":
    main()
