"""Shared test fixtures: the async backend, TLS files, sessions paired on one graph, ports in use.

Helpers that tests import (clients of each transport, real clients in their own
processes, the ``rwt`` command line) are in tests/support/.
"""

from __future__ import annotations

import gc
import json
import os
import socket
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

# With PYTHONDONTWRITEBYTECODE set (as in many containers), every xdist worker would
# rewrite and compile all ~400 test modules anew on every run (about 15 s of CPU a
# worker before the first test), and every Python process a test starts (a server, a
# peer: hundreds in a run) would compile the rwt modules it imports (0.35 s of CPU
# each). Keep that bytecode under .pytest_cache instead, for this process (before it
# imports rwt) and the processes it starts: the source tree stays free of __pycache__
# as the setting asks, and the next run reads them back.
if sys.dont_write_bytecode:
    _PYCACHE = str(Path(__file__).resolve().parent.parent / ".pytest_cache" / "pycache")
    sys.pycache_prefix = _PYCACHE
    sys.dont_write_bytecode = False
    os.environ["PYTHONPYCACHEPREFIX"] = _PYCACHE
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
from tests.support import pycache  # the standard library only

if sys.pycache_prefix:
    # ...but not the standard library's and the installed packages' (tests/support/pycache.py)
    pycache.reuse_installed()
    pycache.link_loaded()  # what this process loaded: the xdist workers load it at their start

# (imported after the setting, so that rwt's modules are cached too)
import pytest
import trustme
from hypothesis import HealthCheck, settings

from rwt_graph.graph import Graph
from rwt_protocol.levels import StatusLevel
from rwt_protocol.server.session import Session, SessionConfig
from tests.support import helper_envs, warm
from tests.support.file_order import UNKNOWN_S, file_seconds

# The test process's garbage collector: a worker holds every collected test module and
# item and the caches of thousands of tests, so Python's default thresholds (700, 10, 10)
# made it walk that heap often: 17 % of the CPU of tests/session, protocol and graph. A
# tenfold first threshold, and everything collection made moved out of the collector's
# sight (``pytest_collection_finish``), take that to 8 %. Only this process: the servers
# and peers the tests start keep Python's defaults (or rwt's own, docs/limits.md).
gc.set_threshold(10_000, 10, 10)

# Property tests check behaviour, never speed: no per-example deadline, and no health
# check that fails a test because a shared, loaded machine generated examples slowly.
settings.register_profile(
    "rwt", deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large]
)
settings.load_profile("rwt")


class FakeClock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 100.0
        self.epoch = 1_700_000_000.25

    def monotonic(self) -> float:
        return self.now

    def wall(self) -> float:
        return self.epoch


class Peer:
    """A client connection reduced to its session: send ops as dicts, read frames as dicts."""

    def __init__(
        self,
        graph: Graph,
        name: str,
        level: StatusLevel = StatusLevel.ERROR,
        config: SessionConfig | None = None,
    ) -> None:
        config = replace(config or SessionConfig(), status_level=level)
        self.session = Session(graph.port, name, config=config)
        self.clock = graph.clock

    def send(self, **op: object) -> None:
        self.send_raw(json.dumps(op))

    def send_raw(self, frame: str | bytes) -> None:
        self.session.receive_frame(frame, self.clock.monotonic())

    def received(self) -> list[dict[str, object]]:
        return [json.loads(frame.data) for frame in self.session.frames_to_send()]

    def statuses(self) -> list[dict[str, object]]:
        return [m for m in self.received() if m["op"] == "status"]


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def graph(clock: FakeClock) -> Graph:
    return Graph(clock=clock)


@pytest.fixture
def peers(graph: Graph) -> Iterator[tuple[Peer, Peer]]:
    a, b = Peer(graph, "a"), Peer(graph, "b")
    yield a, b
    a.session.close()
    b.session.close()


def pytest_configure(config: pytest.Config) -> None:
    """In each process that runs tests, start its warm ``rwt`` (tests/support/zygote.py);
    in the xdist controller, prepare what every worker would otherwise do at once."""
    distributed = (getattr(config.option, "numprocesses", None) or 0) > 0
    if os.environ.get("PYTEST_XDIST_WORKER") or not distributed:
        warm.start()
    else:  # the controller: the bytecode that each worker would write at once (pycache.py)
        root = config.rootpath
        folders = [str(root / name) for name in ("src", "tests", "benchmarks", "conformance")]
        pycache.prime(config, folders, tests=config.args)
        _ask_other_pythons()
        helper_envs.start(root / "tests", config.args)  # a new machine's tools, made once


def _ask_other_pythons() -> None:
    """Ask Debian's Python once for the files that skip without ROS 1, before the workers
    start: they read the answers from the environment (``benchmarks.servers.imports_ok``)
    instead of each starting it again at collection (0.3 s a question, in every worker)."""
    from benchmarks.servers import ROS1_PROBES, ROS1_PYTHON, imports_ok  # noqa: PLC0415

    for code in ROS1_PROBES.values():
        imports_ok(ROS1_PYTHON, code)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The longest files first, for xdist's loadfile (tests/support/file_order.py).

    A stable sort by each file's seconds: a file's tests keep their order, together.
    """
    seconds = file_seconds()
    root = config.rootpath

    def longest_first(item: pytest.Item) -> float:
        try:
            path = item.path.relative_to(root).as_posix()
        except ValueError:
            return -UNKNOWN_S
        return -seconds.get(path, UNKNOWN_S)

    items.sort(key=longest_first)


def pytest_collection_finish(session: pytest.Session) -> None:
    """Move what collection made (modules, items, parameters) out of the collector's sight."""
    gc.collect()
    gc.freeze()


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    test = metafunc.definition
    if "anyio_backend" not in metafunc.fixturenames or not test.get_closest_marker("uvloop_too"):
        return
    # a test that names its own loops (``parametrize("anyio_backend", ...)``) keeps them
    if not any(mark.args[:1] == ("anyio_backend",) for mark in test.iter_markers("parametrize")):
        loops = [pytest.param({}, id="asyncio"), pytest.param({"use_uvloop": True}, id="uvloop")]
        metafunc.parametrize("anyio_backend", loops, indirect=True, scope="module")


@pytest.fixture(scope="module")
def anyio_backend(request: pytest.FixtureRequest) -> str | tuple[str, dict[str, bool]]:
    """Every async test runs on asyncio: the server's transports use asyncio's own.

    Module scope, as anyio's default, so module-scoped async fixtures may use it.
    A module marked ``uvloop_too`` (``pytestmark``) runs on uvloop's loop as well:
    where a path differs under uvloop (direct reads and writes, gathered writes).
    """
    options = getattr(request, "param", None)
    return "asyncio" if options is None else ("asyncio", options)


@pytest.fixture
def taken_tcp_port() -> Iterator[int]:
    """A TCP port on 127.0.0.1 that another socket listens on for the test's length."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        yield sock.getsockname()[1]


@pytest.fixture
def taken_udp_port() -> Iterator[int]:
    """A UDP port on 127.0.0.1 that another socket holds for the test's length."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        yield sock.getsockname()[1]


@pytest.fixture
def ca() -> trustme.CA:
    """A certificate authority made for the test."""
    return trustme.CA()


@pytest.fixture
def tls_files(ca: trustme.CA, tmp_path: Path) -> Iterator[tuple[Path, Path, Path]]:
    """``cert.pem``, ``key.pem`` for 127.0.0.1 and localhost, and the CA's ``ca.pem``."""
    cert = ca.issue_cert("127.0.0.1", "localhost")
    certfile, keyfile, cafile = tmp_path / "cert.pem", tmp_path / "key.pem", tmp_path / "ca.pem"
    cert.cert_chain_pems[0].write_to_path(certfile)
    cert.private_key_pem.write_to_path(keyfile)
    ca.cert_pem.write_to_path(cafile)
    yield certfile, keyfile, cafile
