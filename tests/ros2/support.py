"""Real ROS 2 beside `rwt serve --ros2`: a private domain per test module, loopback only.

``ros_environment`` gives each module its own ``ROS_DOMAIN_ID`` (from its name),
discovery limited to this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``)
and Fast DDS on 127.0.0.1 and shared memory only (``fastdds_loopback.xml``).
``Peer`` runs ``peer.py`` (a real rclpy node) in its own process and reads its
JSON lines with a bound.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import anyio
import pytest
from anyio.streams.buffered import BufferedByteReceiveStream

from rwt_protocol.distribution import install_hint
from tests.integration.client_harness import ServerProcess, _LineReader
from tests.support.warm import PYTHON, ros2_socket, rwt_env

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from anyio.abc import ByteReceiveStream

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
PEER = HERE / "peer.py"
WAIT_S = 20.0
READY_S = 60.0
"""A bound on a peer that hangs starting, not a speed requirement: rclpy's import and a
node's start take seconds of CPU, and a test may start four at once on a loaded machine."""

#: Domains from 150: clear of the default 0 and of what other tools here use.
DOMAIN_BASE = 150
#: Set to another base (0-205) so that two checkouts running the same module at once
#: (e.g. a full run and a single file elsewhere) stay on different domains.
DOMAIN_BASE_ENV = "RWT_TEST_ROS_DOMAIN_BASE"


def skip_without_rclpy() -> pytest.MarkDecorator:
    """Skip a module when rclpy cannot be imported (no ROS sourced, no ``rwt-rosbridge[ros2]``)."""
    missing = importlib.util.find_spec("rclpy") is None
    return pytest.mark.skipif(missing, reason=f"rclpy is not importable: {install_hint('ros2')}")


@contextlib.contextmanager
def ros_environment(module: str, tmp: Path) -> Iterator[dict[str, str]]:
    """Set the ROS 2 environment of ``module``'s processes in ``os.environ`` for the block.

    Each test module of this directory gets a domain of its own (by its place in
    the sorted list), so modules running at once on two workers never meet; the base is
    ``DOMAIN_BASE`` unless ``RWT_TEST_ROS_DOMAIN_BASE`` names another.
    """
    modules = sorted(path.stem for path in HERE.glob("test_*.py"))
    base = int(os.environ.get(DOMAIN_BASE_ENV, DOMAIN_BASE))
    domain = base + modules.index(module.rpartition(".")[2])
    values = {
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "FASTDDS_DEFAULT_PROFILES_FILE": str(HERE / "fastdds_loopback.xml"),
        "ROS_LOG_DIR": str(tmp / "ros_log"),
        "PYTHONUNBUFFERED": "1",
    }
    with pytest.MonkeyPatch.context() as patch:
        for key, value in values.items():
            patch.setenv(key, value)
        yield values


class Peer:
    """``peer.py MODE NAME [NODE]`` in its own process (see peer.py); ready once made,
    unless ``wait`` is False (then ``wait_ready`` before using it)."""

    def __init__(
        self, mode: str, name: str, tmp: Path, node: str | None = None, *, wait: bool = True
    ) -> None:
        label = "-".join([mode, name.strip("/").replace("/", "_"), *([node] if node else [])])
        self.stderr_path = tmp / f"peer-{label}.stderr"
        self._stderr = open(self.stderr_path, "wb")  # noqa: SIM115 - closed in stop()
        warm = ros2_socket()  # forked with rclpy loaded, or a new interpreter
        python = [*PYTHON] if warm else [sys.executable]
        self.proc = subprocess.Popen(
            [*python, str(PEER), mode, name, *([node] if node else [])],
            # rwt_env: the environment the zygote started with (this checkout's src first),
            # without which every peer was answered ``cold`` and started from scratch
            env={**rwt_env(), **({"RWT_TEST_WARM": warm} if warm else {})},
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
        )
        self._lines = _LineReader(self.proc.stdout, f"peer-{mode}")
        if wait:
            self.wait_ready()

    def wait_ready(self) -> None:
        """Until the node says it is ready (AssertionError with stderr if not in time)."""
        assert self.next(READY_S).get("ready"), self.stderr()

    def next(self, within: float = WAIT_S) -> dict[str, Any]:
        """The next JSON line (AssertionError with stderr if none in time)."""
        try:
            line = self._lines.get(time.monotonic() + within)
        except TimeoutError:
            line = None
        assert line is not None, f"peer printed nothing\n{self.stderr()}"
        return json.loads(line)

    def stderr(self) -> str:
        """Its stderr so far."""
        return self.stderr_path.read_text("utf-8", "replace")[-3000:]

    def terminate(self) -> None:
        """Ask it to end (SIGTERM) without waiting; ``stop`` waits."""
        if self.proc.poll() is None:
            self.proc.terminate()

    def stop(self) -> None:
        """Stop it (SIGTERM, then SIGKILL)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._stderr.close()

    def __enter__(self) -> Peer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


@contextlib.contextmanager
def peers(tmp: Path, *specs: tuple[str, ...]) -> Iterator[list[Peer]]:
    """``Peer(MODE, NAME[, NODE])`` for each spec, started at once rather than each
    after the one before is ready; all ready in the block, all stopped (at once) after."""
    started: list[Peer] = []
    try:
        for mode, name, *node in specs:
            started.append(Peer(mode, name, tmp, *node, wait=False))
        for peer in started:
            peer.wait_ready()
        yield started
    finally:
        for peer in started:
            peer.terminate()
        for peer in started:
            peer.stop()


async def until(condition: Callable[[], bool], what: str) -> None:
    """Poll ``condition`` every 50 ms until it holds; AssertionError naming ``what`` after 30 s."""
    try:
        with anyio.fail_after(30):
            while not condition():
                await anyio.sleep(0.05)
    except TimeoutError:
        raise AssertionError(f"no {what} within 30 s") from None


def serve_ros2(tmp: Path, *args: str) -> ServerProcess:
    """``rwt serve --ros2 --no-tf`` on a random port (the ROS 2 environment already set)."""
    return ServerProcess(tmp, ("--ros2", "--no-tf", *args))


def roslibpy_prelude(port: int) -> str:
    """The start of a roslibpy script connected to ``port`` (``ros``, ``wait_for``,
    ``own_node()``: the connection's node, where it may create parameters, D34)."""
    return f"""
import json, os, time
import roslibpy
ros = roslibpy.Ros("127.0.0.1", {port})
ros.run(timeout=20)

def wait_for(predicate, within=20.0):
    end = time.monotonic() + within
    while not predicate() and time.monotonic() < end:
        time.sleep(0.05)
    return predicate()

def own_node():
    topic = f"/owner_{{os.getpid()}}"
    roslibpy.Topic(ros, topic, "std_msgs/String").advertise()
    publishers = roslibpy.Service(ros, "/rosapi/publishers", "rosapi_msgs/srv/Publishers")
    found = []
    ask = lambda: publishers.call(roslibpy.ServiceRequest({{"topic": topic}}), timeout=10)
    wait_for(lambda: found.extend(ask()["publishers"]) or found)
    return found[0]
"""


def env_for_clients() -> dict[str, str]:
    """What client scripts need beyond ``os.environ`` (nothing of ROS)."""
    return {k: v for k, v in os.environ.items() if not k.startswith("ROS_")}


class JsonLines:
    """The JSON lines a child prints on stdout, one at a time.

    One read of a pipe may hold several lines or part of one; this reads whole lines.
    """

    def __init__(self, stream: ByteReceiveStream) -> None:
        self._stream = BufferedByteReceiveStream(stream)

    async def next(self) -> Any:
        """The next line, parsed (EndOfStream when the child is done)."""
        return json.loads(await self._stream.receive_until(b"\n", 1 << 20))

    async def last(self) -> Any:
        """The last line before the child ends, parsed."""
        last = None
        with contextlib.suppress(anyio.EndOfStream, anyio.IncompleteRead):
            while True:
                last = await self.next()
        return last
