"""Interface packages rclpy lacks, built on first use without holding up the server (docs/ros2.md).

When the link needs a type whose package rclpy cannot import and rwt can build
(``interfaces.BUILDS``: ``tf2_msgs``, for ``/tf``), ``OnDemand.start`` looks for the build
in the cache (on a worker thread) and, when it is not there, runs the build command
(``interfaces.COMMAND``) as a child process in its own session, at a lower CPU priority,
and waits for it on the event loop: clients are served meanwhile. The child is killed
with its whole process group past its time (``timeout_s``, by default
``interfaces.BUILD_TIMEOUT_S``, which the child also keeps to on its own) or when the
link stops. A finished build is loaded into this process
(``interfaces.load``) and the link is told (``on_change``): its next sweep carries the
types. Each package is tried once per process; a failure is logged with why and what
to do, and is what clients that use its types are told (``warning``).
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import anyio

from . import interfaces

if TYPE_CHECKING:
    from collections.abc import Callable

    from anyio.abc import ByteReceiveStream, Process, TaskGroup

__all__ = ["OnDemand"]

logger = logging.getLogger("rwt.ros2")

_HERE = str(Path(__file__).resolve().parents[1])  # the folder rwt_ros2 was imported from
_MAX_OUTPUT = 64 * 1024  # of the child's stdout and of its stderr: a prefix, or why it failed


@dataclass
class _State:
    failed: str | None = None  # why, once it failed
    ready: bool = False


class OnDemand:
    """The builds one link started, by package (see the module text).

    Args:
        on_change: called on the event loop with a package once it is importable, or
            once its build failed.
        enabled: build at all (False: a missing package stays missing).
        timeout_s: the longest one build may run, seconds (from its start, the wait
            for another process's build of the same package included).
    """

    def __init__(
        self,
        on_change: Callable[[str], None],
        *,
        enabled: bool = True,
        timeout_s: float = interfaces.BUILD_TIMEOUT_S,
    ) -> None:
        self._on_change = on_change
        self._enabled = enabled
        self._timeout_s = timeout_s
        self._states: dict[str, _State] = {}
        self._tg: TaskGroup | None = None

    def open(self, tg: TaskGroup) -> None:
        """Run builds in ``tg`` (the link's task group: they stop with the link)."""
        self._tg = tg

    def buildable(self, type_name: str) -> str | None:
        """The package of ``type_name`` when rwt builds it (``interfaces.BUILDS``), else None."""
        package = type_name.partition("/")[0]
        return package if self._enabled and package in interfaces.BUILDS else None

    def start(self, package: str) -> bool:
        """Start finding or building ``package`` unless it was tried already.

        Returns:
            Whether it is being found or built now: False once it is ready or
            failed, or when no task group runs builds yet.
        """
        state = self._states.get(package)
        if state is None:
            if self._tg is None:
                return False
            state = self._states[package] = _State()
            self._tg.start_soon(self._find_or_build, package, state)
        return state.failed is None and not state.ready

    def pending(self, type_name: str) -> bool:
        """Whether the package of ``type_name`` is being found or built now."""
        state = self._states.get(type_name.partition("/")[0])
        return state is not None and state.failed is None and not state.ready

    def warning(self, type_name: str, missing: str) -> str:
        """What a client using ``type_name`` is told while rclpy lacks its package.

        Args:
            type_name: a type of a package ``buildable`` named.
            missing: why rclpy cannot carry it (``runtime.interface_class``'s error).
        """
        state = self._states.get(type_name.partition("/")[0])
        if state is not None and state.failed is not None:
            return (
                f"{missing}; building it for rclpy failed: {state.failed} "
                f"(it does not cross to ROS 2; the server's log says more: event=ros2_build)"
            )
        if state is not None and state.ready:  # built, and still not importable
            return f"{missing} (it does not cross to ROS 2)"
        return (
            f"{missing}; rwt is building it for rclpy (first use, up to "
            f"{self._timeout_s:.0f} s, then cached): it crosses to ROS 2 once built"
        )

    async def _find_or_build(self, package: str, state: _State) -> None:
        started = time.monotonic()
        try:
            where = await anyio.to_thread.run_sync(interfaces.cached, package)
            how = "cached"
            if where is None:
                logger.info(
                    "event=ros2_build package=%s state=building cache=%s limit_s=%.0f reason=%r",
                    package,
                    interfaces.cache_root(),
                    self._timeout_s,
                    "rclpy has no Python package of it and PyPI no wheel: "
                    "rwt builds it from its definitions, once",
                )
                where, how = await _run_build(package, self._timeout_s), "built"
            interfaces.load(where)
        except interfaces.InterfaceBuildError as exc:
            state.failed = exc.reason
            logger.warning(
                "event=ros2_build package=%s state=failed reason=%r fix=%r",
                package,
                exc.reason,
                _fix(package),
            )
            self._on_change(package)
            return
        state.ready = True
        logger.info(
            "event=ros2_build package=%s state=ready how=%s took_s=%.1f prefix=%s",
            package,
            how,
            time.monotonic() - started,
            where,
        )
        self._on_change(package)


def _fix(package: str) -> str:
    """What to do when the build of ``package`` failed."""
    debian = package.replace("_", "-")
    return (
        f"with a C/C++ compiler and make (apt-get install build-essential) and PyPI "
        f"reachable, run `{interfaces.COMMAND} {package}` (it prints why it fails) and "
        f"restart the server; or source a ROS 2 install that has {package} "
        f"(apt install ros-<distro>-{debian})"
    )


async def _run_build(package: str, timeout_s: float) -> Path:
    """Run the build command for ``package`` for at most ``timeout_s``; the prefix it printed.

    Raises:
        InterfaceBuildError: it failed (its first line of stderr), or ran past the limit.
    """
    # the child runs this rwt, wherever this process found it
    path = os.pathsep.join(filter(None, [_HERE, os.environ.get("PYTHONPATH")]))
    process = await anyio.open_process(
        [sys.executable, "-m", "rwt_ros2.build", "--timeout", str(timeout_s), package],
        stdin=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": path},
        start_new_session=True,  # its own process group: killed with pip, cmake, cc
    )
    try:
        with anyio.move_on_after(timeout_s):
            async with anyio.create_task_group() as tg:
                outputs: list[bytes] = [b"", b""]
                for index, stream in enumerate((process.stdout, process.stderr)):
                    tg.start_soon(_read, stream, outputs, index)
            await process.wait()
    finally:
        _kill_group(process)
        with anyio.CancelScope(shield=True):
            await process.wait()
    out, err = (text.decode("utf-8", "replace").strip() for text in outputs)
    if process.returncode != 0:
        first = err.splitlines()[0] if err else f"exited {process.returncode}"
        if process.returncode == -signal.SIGKILL:
            first = f"stopped: it ran past {timeout_s:g} s (Ros2Options.build_timeout_s)"
        raise interfaces.InterfaceBuildError(first.removeprefix(f"{package}: "))
    if not out:
        raise interfaces.InterfaceBuildError("the build command printed no prefix")
    return Path(out.splitlines()[-1]).parent


async def _read(stream: ByteReceiveStream | None, into: list[bytes], index: int) -> None:
    """Read ``stream`` to its end, keeping its first ``_MAX_OUTPUT`` bytes in ``into[index]``."""
    if stream is None:
        return
    with contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError):
        while True:
            chunk = await stream.receive()
            if len(into[index]) < _MAX_OUTPUT:
                into[index] += chunk[: _MAX_OUTPUT - len(into[index])]


def _kill_group(process: Process) -> None:
    """Kill the build's process group, if anything of it still runs."""
    if process.returncode is None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)
