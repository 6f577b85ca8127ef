"""What the attack replays share: the server, the bystander, the phases and the verdict.

``benchmarks/attacks.py`` replays each class of a hardening campaign against a fresh
``rwt serve`` (``Served``: this checkout's ``src``, or ``$RWT_BENCH_SRC``'s) with a
bystander (``benchmarks/bystander.py``, its own process, from 127.0.0.2) timing a
round trip every 50 ms: a baseline, then the attack. An ``Attack`` says how to serve
and how to attack; ``replay`` runs it and gives a ``Replay``: the bystander's round
trips in both phases, the server's CPU and memory during the attack, what the
attacker got and the verdict.
"""

from __future__ import annotations

import os
import re
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Awaitable, Callable
from contextlib import AsyncExitStack, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import anyio
import anyio.to_thread

from .servers import ROOT, proc_stats, rwt_pythonpath

__all__ = [
    "MARGIN_S",
    "Attack",
    "Context",
    "Outcome",
    "Phase",
    "Replay",
    "replay",
]

MARGIN_S = 0.150
"""The issue's bound: no bystander round trip more than this over its baseline's max."""
GRACE_S = 1.0
"""Seconds the bystander runs on after the attack, so a call sent during it is answered."""
START_LIMIT_S = 60.0
SAMPLE_S = 0.05
OTHER_HOST = "127.0.0.2"
"""Where the bystander and the other hosts' clients connect from; attackers use 127.0.0.1."""


@dataclass
class Outcome:
    """What the attacker (and any victim) got, and whether the class's rule held for them.

    Attributes:
        facts: what was seen, by name (status codes and their counts, refusals, errors).
        ok: whether no client acted beyond its rights and errors were clear.
        check: what ``ok`` looked at, in words.
    """

    facts: dict[str, Any]
    ok: bool
    check: str


@dataclass
class Context:
    """A running server, for an attack: its URLs, its process, a place to keep things.

    Attributes:
        ws_url: ``ws://127.0.0.1:PORT``.
        http: ``http://127.0.0.1:PORT`` (WebRTC signalling and MCP are on this port).
        tcp_port: the raw TCP port (``Attack.tcp``), else 0.
        pid: the server's process id.
        log: its stderr.
        work: a temporary folder of the class (secrets, packages).
        seconds: how long the attack runs (its flood, its watch).
        stack: closed after the attack (background publishers, connections).
        secret: the rosauth secret the server was given, if any.
        baseline_cores: the server's CPU in the baseline, cores (set as the attack starts).
    """

    ws_url: str
    http: str
    tcp_port: int
    pid: int
    log: Path
    work: Path
    seconds: float
    stack: AsyncExitStack
    secret: str | None = None
    baseline_cores: float = 0.0


@dataclass
class Attack:
    """One class of the campaign: how to serve it, set it up and attack.

    Attributes:
        number: the class's number in the campaign (``"1"``, ``"11+12"``).
        title: what it is, in a few words.
        serve: ``rwt serve`` options, given the class's folder.
        attack: the attack; its ``Outcome``.
        scaled: how the issue's attack was scaled to fit (words).
        bound: the documented bound on what the server may hold (bytes over what it held
            as the attack began) and where it is documented; None: no such bound.
        setup: runs before the baseline (publishers the class needs, which keep running).
        baseline: the baseline phase (default: ``Context.seconds``-independent 2 s of
            quiet); the attack's load without the attacker, where the class has one.
        tcp: also serve raw TCP.
        nofile: the server's RLIMIT_NOFILE (soft and hard), else inherited.
        secret: serve with ``--auth-secret-file`` (the bystander authenticates).
        seconds: the attack's length at full scale.
    """

    number: str
    title: str
    serve: Callable[[Path], list[str]]
    attack: Callable[[Context], Awaitable[Outcome]]
    scaled: str
    bound: tuple[int, str] | None = None
    setup: Callable[[Context], Awaitable[None]] | None = None
    baseline: Callable[[Context, float], Awaitable[None]] | None = None
    tcp: bool = False
    nofile: int | None = None
    secret: bool = False
    seconds: float = 20.0


@dataclass
class Phase:
    """The bystander's round trips in one phase, milliseconds."""

    calls: int
    p50_ms: float
    p99_ms: float
    max_ms: float
    unanswered: int = 0


@dataclass
class Replay:
    """One class replayed on one server: the figures and the verdict."""

    number: str
    title: str
    scaled: str
    serve_args: list[str]
    baseline: Phase
    attack: Phase
    attack_s: float
    baseline_cpu_s: float
    cpu_s: float
    rss_start_mb: float
    rss_peak_mb: float
    rss_end_mb: float
    bound_mb: float | None
    bound_source: str | None
    outcome: dict[str, Any]
    rights_ok: bool
    rights_check: str
    log_bytes: int
    log_errors: int
    log_tracebacks: int
    verdict: str
    reasons: list[str] = field(default_factory=list)


# ---- the server ---------------------------------------------------------------------


class _Serve:
    """``rwt serve --host 127.0.0.1 --port 0 ARGS`` from ``rwt_pythonpath()``, log to a file."""

    def __init__(self, args: list[str], log: Path, nofile: int | None) -> None:
        command = [sys.executable, "-m", "rwt", "serve", "--host", "127.0.0.1", "--port", "0"]
        env = {**os.environ, "PYTHONPATH": rwt_pythonpath(), "PYTHONUNBUFFERED": "1"}

        def limit() -> None:
            if nofile is not None:
                resource.setrlimit(resource.RLIMIT_NOFILE, (nofile, nofile))

        with log.open("wb") as stderr:
            self.process = subprocess.Popen(
                [*command, *args],
                cwd=ROOT,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=stderr,
                preexec_fn=limit if nofile is not None else None,  # noqa: PLW1509 (no threads yet)
            )
        self.log = log
        self.urls: dict[str, str] = {}

    def wait_listening(self, tcp: bool) -> None:
        """Read the ``listening on`` lines (WebSocket, and TCP when asked for)."""
        assert self.process.stdout is not None
        lines: list[str] = []

        def read() -> None:
            assert self.process.stdout is not None
            while True:
                line = self.process.stdout.readline().decode()
                if not line:
                    return
                lines.append(line)
                if line.startswith("listening on ws://") and not tcp:
                    return
                if tcp and any(x.startswith("listening on tcp://") for x in lines):
                    return

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        reader.join(START_LIMIT_S)
        for line in lines:
            url = line.strip().removeprefix("listening on ")
            self.urls.setdefault(url.split("://")[0], url)
        if "ws" not in self.urls or (tcp and "tcp" not in self.urls):
            self.stop()
            tail = self.log.read_text(errors="replace")[-2000:]
            raise RuntimeError(f"rwt serve did not start: {lines!r}\n{tail}")

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(10.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(10.0)
        if self.process.stdout is not None:
            self.process.stdout.close()


class _Memory:
    """The server's peak resident memory over a phase: VmHWM (reset at the start through
    ``/proc/PID/clear_refs``) and VmRSS sampled every 50 ms, whichever is higher."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.peak = 0
        self._running = True
        with suppress(OSError):
            Path(f"/proc/{pid}/clear_refs").write_text("5")
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()

    def _sample(self) -> None:
        while self._running:
            with suppress(OSError):
                self.peak = max(self.peak, proc_stats(self.pid).rss_bytes)
            time.sleep(SAMPLE_S)

    def stop(self) -> int:
        self._running = False
        self._thread.join()
        with suppress(OSError):
            status = Path(f"/proc/{self.pid}/status").read_text()
            if match := re.search(r"^VmHWM:\s+(\d+) kB", status, re.MULTILINE):
                self.peak = max(self.peak, int(match.group(1)) * 1024)
        return self.peak


# ---- the bystander --------------------------------------------------------------------


class _Bystander:
    """``benchmarks/bystander.py`` in its own process; its round trips once stopped."""

    def __init__(self, ws_url: str, secret: str | None) -> None:
        command = [sys.executable, "-m", "benchmarks.bystander", ws_url, "--host", OTHER_HOST]
        if secret is not None:
            command += ["--secret", secret]
        self.process = subprocess.Popen(
            command,
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            text=True,
        )
        self.lines: list[str] = []
        self.ready = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            if line.startswith("ready"):
                self.ready.set()
            else:
                self.lines.append(line)
        self.ready.set()

    def stop(self) -> list[tuple[float, float, bool]]:
        """Stop it: each call's send time, round trip (s) and whether it was answered."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(10.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
        self._reader.join(10.0)
        if self.process.stdout is not None:
            self.process.stdout.close()
        trips = []
        for line in self.lines:
            parts = line.split()
            trips.append((float(parts[0]), float(parts[1]), len(parts) == 2))
        return trips


def _phase(trips: list[tuple[float, float, bool]], start: float, end: float) -> Phase:
    times = [rtt for sent, rtt, _ in trips if start <= sent < end]
    unanswered = sum(1 for sent, _, answered in trips if start <= sent < end and not answered)
    if not times:
        return Phase(0, 0.0, 0.0, 0.0, unanswered)
    ordered = sorted(times)
    p99 = ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))]
    return Phase(
        len(times),
        round(statistics.median(ordered) * 1000, 1),
        round(p99 * 1000, 1),
        round(ordered[-1] * 1000, 1),
        unanswered,
    )


# ---- a replay ---------------------------------------------------------------------------


def _log_facts(log: Path) -> tuple[int, int, int]:
    text = log.read_text(errors="replace") if log.exists() else ""
    errors = sum(1 for line in text.splitlines() if "level=ERROR" in line or " ERROR " in line)
    return len(text.encode()), errors, text.count("Traceback (most recent call last)")


async def _quiet(_: Context, seconds: float) -> None:
    await anyio.sleep(seconds)


async def replay(attack: Attack, *, scale: float = 1.0, baseline_s: float = 2.0) -> Replay:
    """Serve ``attack``'s server afresh, run the bystander, the baseline and the attack.

    ``scale`` multiplies the attack's length (the smoke test's tiny runs); below 1/4 the
    baseline and the grace after the attack shorten too.

    Raises:
        RuntimeError: the server did not start.
    """
    with tempfile.TemporaryDirectory(prefix=f"attack{attack.number}-") as folder:
        work = Path(folder)
        args = attack.serve(work)
        secret = None
        if attack.secret:
            secret = "bench-secret-bench-secret"
            (work / "secret").write_text(secret + "\n")
            args += ["--auth-secret-file", str(work / "secret")]
        if attack.tcp:
            args += ["--tcp-port", "0"]
        server = _Serve(args, work / "serve.log", attack.nofile)
        try:
            await anyio.to_thread.run_sync(server.wait_listening, attack.tcp)
            ws_url = server.urls["ws"]
            tcp = int(server.urls["tcp"].rsplit(":", 1)[1]) if attack.tcp else 0
            async with AsyncExitStack() as stack:
                context = Context(
                    ws_url,
                    ws_url.replace("ws://", "http://"),
                    tcp,
                    server.process.pid,
                    server.log,
                    work,
                    attack.seconds * scale,
                    stack,
                    secret,
                )
                return await _phases(attack, context, args, min(1.0, 4 * scale), baseline_s)
        finally:
            server.stop()


async def _phases(
    attack: Attack, context: Context, args: list[str], shorten: float, baseline_s: float
) -> Replay:
    if attack.setup is not None:
        await attack.setup(context)
    bystander = _Bystander(context.ws_url, context.secret)
    try:
        if not await anyio.to_thread.run_sync(bystander.ready.wait, START_LIMIT_S):
            raise RuntimeError("the bystander did not connect")
        base_start, base_cpu = time.monotonic(), proc_stats(context.pid).cpu_s
        await (attack.baseline or _quiet)(context, baseline_s * shorten)
        before = proc_stats(context.pid)
        context.baseline_cores = (before.cpu_s - base_cpu) / (time.monotonic() - base_start)
        memory = _Memory(context.pid)
        start = time.monotonic()
        outcome = await attack.attack(context)
        end = time.monotonic()
        after = proc_stats(context.pid)
        peak = memory.stop()
        await anyio.sleep(GRACE_S * shorten)
    finally:
        trips = await anyio.to_thread.run_sync(bystander.stop)
    await context.stack.aclose()
    end_rss = proc_stats(context.pid).rss_bytes
    return _judge(
        attack,
        args,
        _phase(trips, base_start, start),
        _phase(trips, start, end),
        (before.cpu_s - base_cpu, after.cpu_s - before.cpu_s, end - start),
        (before.rss_bytes, peak, end_rss),
        outcome,
        _log_facts(context.log),
    )


def _judge(
    attack: Attack,
    args: list[str],
    baseline: Phase,
    during: Phase,
    cpu: tuple[float, float, float],
    rss: tuple[int, int, int],
    outcome: Outcome,
    log: tuple[int, int, int],
) -> Replay:
    mb = 1024 * 1024
    reasons = []
    if during.calls == 0 or during.max_ms > baseline.max_ms + MARGIN_S * 1000:
        reasons.append(
            f"bystander max {during.max_ms:.0f} ms > baseline max {baseline.max_ms:.0f} + 150 ms"
        )
    if during.unanswered:
        reasons.append(f"{during.unanswered} bystander calls unanswered")
    bound = attack.bound
    if bound is not None and rss[1] - rss[0] > bound[0]:
        reasons.append(f"memory +{(rss[1] - rss[0]) / mb:.0f} MB > bound {bound[0] / mb:.0f} MB")
    if not outcome.ok:
        reasons.append(f"rights/errors: not {outcome.check}")
    return Replay(
        number=attack.number,
        title=attack.title,
        scaled=attack.scaled,
        serve_args=args,
        baseline=baseline,
        attack=during,
        attack_s=round(cpu[2], 2),
        baseline_cpu_s=round(cpu[0], 2),
        cpu_s=round(cpu[1], 2),
        rss_start_mb=round(rss[0] / mb, 1),
        rss_peak_mb=round(rss[1] / mb, 1),
        rss_end_mb=round(rss[2] / mb, 1),
        bound_mb=None if bound is None else round(bound[0] / mb, 1),
        bound_source=None if bound is None else bound[1],
        outcome=outcome.facts,
        rights_ok=outcome.ok,
        rights_check=outcome.check,
        log_bytes=log[0],
        log_errors=log[1],
        log_tracebacks=log[2],
        verdict="held" if not reasons else "NOT held",
        reasons=reasons,
    )
