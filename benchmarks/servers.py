"""Start the two servers under test and read their CPU and memory from /proc.

Both servers run as subprocesses bound to 127.0.0.1 on a free port; ``rwt
serve`` runs from this checkout's ``src`` (PYTHONPATH), or from the ``src`` that
``RWT_BENCH_SRC`` names (another checkout: ``python -m benchmarks compare`` uses it
for the baseline), the bare relay is ``benchmarks/relay.py``. Each prints
``listening on ws://HOST:PORT`` first.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

__all__ = [
    "ROOT",
    "ROS1_PROBES",
    "ROS1_PYTHON",
    "ProcStats",
    "Server",
    "imports_ok",
    "proc_stats",
    "rwt_pythonpath",
    "start_server",
    "stop_process",
]

ROOT = Path(__file__).resolve().parent.parent
_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")
_START_LIMIT_S = 20.0


def rwt_pythonpath(src: Path | None = None) -> str:
    """PYTHONPATH for an ``rwt`` process: ``src`` (default ``$RWT_BENCH_SRC``, else this
    checkout's ``src``), then this checkout's root (the ``benchmarks`` package)."""
    chosen = src or Path(os.environ.get("RWT_BENCH_SRC") or ROOT / "src")
    return os.pathsep.join([str(chosen), str(ROOT)])


@dataclass(frozen=True, slots=True)
class ProcStats:
    """A reading of one process: CPU seconds used so far and resident memory."""

    cpu_s: float
    rss_bytes: int


ROS1_PYTHON = "/usr/bin/python3"
"""Debian's Python, whose packages bring ROS 1 (``python3-rospy``, ``python3-rosbag``)."""
ROS1_PROBES = {
    "rospy": "import rospy, std_msgs.msg, sensor_msgs.msg",
    "rosbag": "import rosbag, sensor_msgs.msg, tf2_msgs.msg",
}
"""What the ROS 1 benchmarks and tests import from ``ROS1_PYTHON`` (``imports_ok``)."""


def imports_ok(python: str, code: str) -> bool:
    """Whether ``python`` (another interpreter: Debian's ROS 1) runs ``code`` (its imports).

    Asked once per process tree: the answer is kept in this process's environment
    (``RWT_PROBE_<digest>``), which the processes it starts inherit; the test suite's
    controller asks before its workers start (tests/conftest.py), so no worker asks again.
    """
    key = "RWT_PROBE_" + hashlib.sha1(f"{python}\0{code}".encode()).hexdigest()[:16]
    known = os.environ.get(key)
    if known is None:
        ran = (
            Path(python).exists()
            and not subprocess.run(
                [python, "-c", code], capture_output=True, check=False
            ).returncode
        )
        known = os.environ[key] = "1" if ran else "0"
    return known == "1"


def stop_process(proc: subprocess.Popen[Any], grace_s: float = 15.0) -> None:
    """SIGTERM ``proc``, SIGKILL it after ``grace_s``, and close its stdout pipe."""
    proc.terminate()
    try:
        proc.wait(grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    if proc.stdout is not None:
        proc.stdout.close()


def proc_stats(pid: int) -> ProcStats:
    """CPU (user + system, /proc/<pid>/stat) and VmRSS (/proc/<pid>/status) of a process."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        fields = f.read().rpartition(")")[2].split()
    cpu = (int(fields[11]) + int(fields[12])) * _TICK_S
    rss = 0
    with open(f"/proc/{pid}/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1]) * 1024
                break
    return ProcStats(cpu, rss)


class Server:
    """One running server process (``kind`` is ``bare`` or ``rwt``)."""

    def __init__(self, kind: str, process: subprocess.Popen[bytes], port: int) -> None:
        self.kind = kind
        self.process = process
        self.port = port

    def stats(self) -> ProcStats:
        """CPU (user + system, from /proc/<pid>/stat) and VmRSS (/proc/<pid>/status)."""
        return proc_stats(self.process.pid)

    def alive(self) -> bool:
        """Whether the process is still running."""
        return self.process.poll() is None

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after 5 s."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(5.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5.0)
        if self.process.stdout is not None:
            self.process.stdout.close()

    def __enter__(self) -> Server:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _command(kind: str, uvloop: bool, extra: list[str]) -> list[str]:
    if kind == "bare":
        command = [sys.executable, "-m", "benchmarks.relay", "--port", "0"]
    else:
        command = [sys.executable, "-m", "rwt", "serve", "--port", "0"]
        command += ["--log-level", os.environ.get("RWT_BENCH_LOG_LEVEL", "warning")]
    if uvloop:
        command.append("--uvloop")
    return command + extra


def start_server(
    kind: str,
    *,
    uvloop: bool = False,
    extra: list[str] | None = None,
    src: Path | None = None,
    stderr: IO[bytes] | None = None,
) -> Server:
    """Start ``bare`` (the relay) or ``rwt`` (from ``src``, see ``rwt_pythonpath``) and
    wait for its listening line; its log goes to ``stderr`` (None: this process's).

    Raises:
        RuntimeError: the process exited or said nothing within 20 s.
    """
    env = dict(os.environ)
    env["PYTHONPATH"] = rwt_pythonpath(src)
    process = subprocess.Popen(
        _command(kind, uvloop, extra or []),
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        stderr=stderr,
    )
    line: list[bytes] = []
    reader = threading.Thread(target=lambda: line.append(process.stdout.readline()), daemon=True)  # type: ignore[union-attr]
    reader.start()
    reader.join(_START_LIMIT_S)
    text = line[0].decode().strip() if line else ""
    if not text.startswith("listening on ws://"):
        process.kill()
        raise RuntimeError(f"{kind} server did not start: {text!r}")
    return Server(kind, process, int(text.rsplit(":", 1)[1]))
