"""B25: an MCP flood beside a rosbridge and a Foxglove bystander.

``python -m benchmarks.mcp_flood [--idle 5] [--flood 10] [--agents 16] [--listeners 8]``.
One ``rwt serve --mcp --foxglove`` (its own process), a robot (a rosbridge client in a
process of its own, serving ``/fibonacci``: a goal runs until canceled or 2 s), and two
bystanders from another host (127.0.0.2, ``benchmarks/bystander.py``, each a process):
a rosbridge client calling ``/rosapi/get_time`` and a Foxglove client asking
``getParameters``, one round trip every 50 ms. First ``--idle`` seconds with nothing
else; then ``--flood`` seconds of an MCP flood from one host (127.0.0.1), in this
process, of every kind of 2026-07-28 request:

- ``--agents`` agents, each sending back to back, in turn: ``tools/call`` of ``echo``,
  ``send_action_goal`` as a task (the Tasks extension declared), ``tasks/get`` and
  ``tasks/cancel`` of its last task (every request a connection of its own);
- ``--listeners`` ``subscriptions/listen`` streams held open through the flood, each on
  a resource of a topic.

The flood's host meets the caps (``TOOL_CALLS_PER_S`` per tool and host, the host's
connections): most of its requests are refused, as they must be. Per bystander the table
gives p50 / p99 / max of its round trips idle and under the flood, and the ratio of the
p99s (the target: at most 2x); then what the flood's requests got (answers by kind).
Writes ``benchmarks/results/mcp_flood.json``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

from .servers import rwt_pythonpath, stop_process

__all__ = ["Phase", "main", "table"]

RESULTS = Path(__file__).resolve().parent / "results" / "mcp_flood.json"
OTHER_HOST = "127.0.0.2"
FLOOD_HOST = "127.0.0.1"
FIB = "example_interfaces/action/Fibonacci"
TASKS = "io.modelcontextprotocol/tasks"
START_S = 60.0

_ENV = {**os.environ, "PYTHONPATH": rwt_pythonpath(), "PYTHONUNBUFFERED": "1"}
_ROBOT = """
import sys
import anyio
from rwt_client import Action, Ros

async def main() -> None:
    async with Ros(sys.argv[1]) as ros:
        async def fibonacci(goal):
            await goal.send_feedback({"sequence": [0, 1]})
            with anyio.move_on_after(2.0):
                await goal.cancel_requested.wait()
                goal.canceled()
            return {"sequence": [0, 1]}
        await Action(ros, "/fibonacci", sys.argv[2]).advertise(fibonacci)
        print("ready", flush=True)
        await anyio.sleep_forever()

anyio.run(main)
"""


@dataclass(frozen=True)
class Phase:
    """A bystander's round trips in one phase, milliseconds."""

    calls: int
    p50_ms: float
    p99_ms: float
    max_ms: float

    @classmethod
    def of(cls, rtts: list[float]) -> Phase:
        """The figures of ``rtts`` (seconds)."""
        if not rtts:
            return cls(0, 0.0, 0.0, 0.0)
        ordered = sorted(rtts)
        p99 = ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))]
        return cls(len(rtts), statistics.median(rtts) * 1e3, p99 * 1e3, ordered[-1] * 1e3)


def _meta(tasks: bool = False) -> dict[str, object]:
    capabilities: dict[str, object] = {"extensions": {TASKS: {}}} if tasks else {}
    return {
        "io.modelcontextprotocol/protocolVersion": "2026-07-28",
        "io.modelcontextprotocol/clientCapabilities": capabilities,
    }


def _post(port: int, method: str, params: dict[str, object], name: str | None = None) -> bytes:
    body = json.dumps({"jsonrpc": "2.0", "id": 1, "method": method, "params": params}).encode()
    head = (
        f"POST /mcp HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
        "Accept: application/json, text/event-stream\r\nContent-Type: application/json\r\n"
        f"MCP-Protocol-Version: 2026-07-28\r\nMcp-Method: {method}\r\n"
        + (f"Mcp-Name: {name}\r\n" if name else "")
        + f"Content-Length: {len(body)}\r\n\r\n"
    )
    return head.encode() + body


def _kind(answer: bytes) -> str:
    """What a flood request got: its status, and for a 200 a result, task or error."""
    status = answer[9:12].decode("latin-1", "replace") or "none"
    if status != "200":
        return status
    if b'"isError":true' in answer:
        return "200 tool error"
    if b'"error":' in answer:
        return "200 JSON-RPC error"
    return "200 task" if b'"resultType":"task"' in answer else "200 result"


async def _exchange(port: int, request: bytes) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(FLOOD_HOST, 0))
    try:
        writer.write(request)
        return await reader.read()
    finally:
        writer.close()


async def _flood(port: int, seconds: float, agents: int, listeners: int) -> Counter[str]:
    tally: Counter[str] = Counter()
    end = time.monotonic() + seconds
    echo = _post(
        port,
        "tools/call",
        {"name": "echo", "arguments": {"topic": "/client_count"}, "_meta": _meta()},
        "echo",
    )
    goal_args = {"action": "/fibonacci", "type": FIB, "goal": {"order": 5}}
    goal = _post(
        port,
        "tools/call",
        {"name": "send_action_goal", "arguments": goal_args, "_meta": _meta(tasks=True)},
        "send_action_goal",
    )

    async def agent() -> None:
        task_id = "w0-" + "0" * 32
        while time.monotonic() < end:
            for step in (echo, goal, "tasks/get", "tasks/cancel"):
                if isinstance(step, str):
                    params: dict[str, object] = {"taskId": task_id, "_meta": _meta(tasks=True)}
                    request = _post(port, step, params)
                else:
                    request = step
                try:
                    answer = await _exchange(port, request)
                except OSError as exc:
                    tally[f"socket error {exc.errno}"] += 1
                    continue
                kind = _kind(answer)
                tally[kind] += 1
                if kind == "200 task":
                    task_id = json.loads(answer.partition(b"\r\n\r\n")[2])["result"]["taskId"]

    async def listener(n: int) -> None:
        topic = "ros://topics/client_count"
        params = {"notifications": {"resourceSubscriptions": [topic]}, "_meta": _meta()}
        request = _post(port, "subscriptions/listen", params)
        with contextlib.suppress(OSError):
            reader, writer = await asyncio.open_connection(
                "127.0.0.1", port, local_addr=(FLOOD_HOST, 0)
            )
            writer.write(request)
            first = await reader.read(12)
            tally[f"listen {first[9:12].decode('latin-1', 'replace')}"] += 1
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(reader.read(), end - time.monotonic())
            writer.close()

    await asyncio.gather(
        *(agent() for _ in range(agents)), *(listener(n) for n in range(listeners))
    )
    return tally


@contextlib.contextmanager
def _process(cmd: list[str], ready: str) -> Iterator[subprocess.Popen[str]]:
    """A process of ours, once it printed a line starting with ``ready``; stopped after."""
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, env=_ENV, text=True
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        if not line.startswith(ready):
            raise RuntimeError(f"{cmd[:4]} did not start: {line!r}")
        proc.first_line = line.strip()  # type: ignore[attr-defined]
        yield proc
    finally:
        stop_process(proc)


def _round_trips(proc: subprocess.Popen[str]) -> list[tuple[float, float]]:
    """A stopped bystander's (send time, round trip) pairs, seconds."""
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=30)
    pairs = []
    for line in out.splitlines():
        fields = line.split()
        if len(fields) >= 2 and fields[0] != "ready":
            pairs.append((float(fields[0]), float(fields[1])))
    return pairs


def main(
    idle_s: float, flood_s: float, agents: int, listeners: int
) -> tuple[dict[str, dict[str, Phase]], Counter[str]]:
    """Both phases; (per bystander its idle and flood phases, the flood's answers)."""
    serve = [sys.executable, "-m", "rwt", "serve", "--port", "0", "--mcp", "--foxglove"]
    serve += ["--no-tf", "--log-level", "warning"]
    with contextlib.ExitStack() as stack:
        server = stack.enter_context(_process(serve, "listening on "))
        url = server.first_line.removeprefix("listening on ")  # type: ignore[attr-defined]
        port = int(url.rsplit(":", 1)[1])
        stack.enter_context(_process([sys.executable, "-c", _ROBOT, url, FIB], "ready"))
        bystanders = {
            "rosbridge": stack.enter_context(
                _process([sys.executable, "-m", "benchmarks.bystander", url], "ready")
            ),
            "Foxglove": stack.enter_context(
                _process([sys.executable, "-m", "benchmarks.bystander", url, "--foxglove"], "ready")
            ),
        }
        idle0 = time.monotonic()
        time.sleep(idle_s)
        flood0 = time.monotonic()
        tally = _run_flood(port, flood_s, agents, listeners)
        flood1 = time.monotonic()
        phases: dict[str, dict[str, Phase]] = {}
        for name, proc in bystanders.items():
            pairs = _round_trips(proc)
            phases[name] = {
                "idle": Phase.of([rtt for sent, rtt in pairs if idle0 <= sent < flood0]),
                "flood": Phase.of([rtt for sent, rtt in pairs if flood0 <= sent < flood1]),
            }
    return phases, tally


def _run_flood(port: int, seconds: float, agents: int, listeners: int) -> Counter[str]:
    try:
        import uvloop  # noqa: PLC0415 (optional: the flood's own CPU is not the server's)
    except ImportError:
        return asyncio.run(_flood(port, seconds, agents, listeners))
    with asyncio.Runner(loop_factory=uvloop.new_event_loop) as runner:
        return runner.run(_flood(port, seconds, agents, listeners))


def table(phases: dict[str, dict[str, Phase]]) -> str:
    """A Markdown table: each bystander's idle and flood round trips, the ratio of p99s."""
    lines = [
        "| bystander | idle ms p50 / p99 / max | under the flood | p99 x idle |",
        "|---|---|---|---|",
    ]
    for name, both in phases.items():
        idle, flood = both["idle"], both["flood"]
        ratio = flood.p99_ms / idle.p99_ms if idle.p99_ms else float("inf")
        lines.append(
            f"| {name} | {idle.p50_ms:.1f} / {idle.p99_ms:.1f} / {idle.max_ms:.1f} | "
            f"{flood.p50_ms:.1f} / {flood.p99_ms:.1f} / {flood.max_ms:.1f} | {ratio:.2f} |"
        )
    return "\n".join(lines)


def _cli() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--idle", type=float, default=5.0)
    parser.add_argument("--flood", type=float, default=10.0)
    parser.add_argument("--agents", type=int, default=16)
    parser.add_argument("--listeners", type=int, default=8)
    args = parser.parse_args()
    phases, tally = main(args.idle, args.flood, args.agents, args.listeners)
    print(table(phases))
    print("flood:", ", ".join(f"{kind} {n}" for kind, n in tally.most_common()))
    RESULTS.parent.mkdir(exist_ok=True)
    record = {
        "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "args": vars(args),
        "phases": {k: {p: asdict(v) for p, v in both.items()} for k, both in phases.items()},
        "flood": dict(tally),
    }
    RESULTS.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    _cli()
