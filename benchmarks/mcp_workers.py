"""B24: MCP tool calls a second, ``rwt serve --mcp`` against ``--mcp --workers 2``.

``python -m benchmarks.mcp_workers [--seconds 6] [--rounds 3] [--concurrency 16]``.
Two servers side by side, started before any round: a plain ``rwt serve --mcp`` (one
process) and ``rwt serve --mcp --workers 2``. Each round drives one of them, in turn,
for ``--seconds``: ``--concurrency`` agents in this process, each sending 2026-07-28
``tools/call`` requests of a read tool (``echo`` of the latched ``/client_count``) one
after another, each request a connection of its own (the server answers
``Connection: close``) from a source address of its own in 127.0.0.0/8, as many agents
on many hosts would (a server's caps are per host: ``TOOL_CALLS_PER_S``).

The load generator speaks raw HTTP over sockets (no SDK client: its CPU would bound
the figure on two cores); a call counts when it answered 200 with a result that is no
tool error. Per server the table gives the calls a second (median of the rounds), the
ratio to the plain server, the server's CPU per call (every thread of every process
of its tree, from ``/proc``) and the generator's. Writes
``benchmarks/results/mcp_workers.json``. Compare rows of one run only: both servers
share the machine's cores with the generator.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import statistics
import sys
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import asdict, dataclass
from pathlib import Path

from .proctree import tree_cpu_ns
from .scale_workers import serve_workers

__all__ = ["Burst", "main", "measure", "table"]

RESULTS = Path(__file__).resolve().parent / "results" / "mcp_workers.json"
HOSTS = [f"127.0.{a}.{b}" for a in range(1, 9) for b in range(1, 255)]
"""Source addresses the agents call from, in turn (2,032 hosts of the loopback net)."""
WARM_UP_S = 1.0

_BODY = json.dumps(
    {
        "jsonrpc": "2.0",
        "id": 1,
        "method": "tools/call",
        "params": {
            "name": "echo",
            "arguments": {"topic": "/client_count"},
            "_meta": {
                "io.modelcontextprotocol/protocolVersion": "2026-07-28",
                "io.modelcontextprotocol/clientCapabilities": {},
            },
        },
    }
).encode()


def _request(port: int) -> bytes:
    head = (
        f"POST /mcp HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
        "Accept: application/json, text/event-stream\r\nContent-Type: application/json\r\n"
        "MCP-Protocol-Version: 2026-07-28\r\nMcp-Method: tools/call\r\nMcp-Name: echo\r\n"
        f"Content-Length: {len(_BODY)}\r\n\r\n"
    )
    return head.encode() + _BODY


@dataclass(frozen=True)
class Burst:
    """One round against one server: calls answered, failed, over ``wall_s`` seconds."""

    calls: int
    errors: int
    wall_s: float
    server_cpu_s: float
    client_cpu_s: float

    @property
    def per_s(self) -> float:
        """Calls answered a second."""
        return self.calls / self.wall_s


async def _agents(port: int, seconds: float, concurrency: int) -> tuple[int, int, list[bytes]]:
    request = _request(port)
    hosts = itertools.cycle(HOSTS)
    calls = errors = 0
    samples: list[bytes] = []
    end = time.monotonic() + seconds

    async def agent() -> None:
        nonlocal calls, errors
        while time.monotonic() < end:
            reader, writer = await asyncio.open_connection(
                "127.0.0.1", port, local_addr=(next(hosts), 0)
            )
            writer.write(request)
            answer = await reader.read()
            writer.close()
            if answer.startswith(b"HTTP/1.1 200") and b'"isError":false' in answer:
                calls += 1
            else:
                errors += 1
                if len(samples) < 3:
                    samples.append(answer[:300])

    await asyncio.gather(*(agent() for _ in range(concurrency)))
    return calls, errors, samples


def _loop_factory() -> Callable[[], asyncio.AbstractEventLoop] | None:
    """uvloop's loop where installed (the ``uvloop`` extra): the generator's CPU per call
    is what the servers do not get of the two cores; else asyncio's."""
    try:
        import uvloop  # noqa: PLC0415 (optional)
    except ImportError:
        return None
    return uvloop.new_event_loop


def measure(pid: int, port: int, seconds: float, concurrency: int) -> Burst:
    """Drive the server ``pid`` on ``port`` for ``seconds``; its figures."""
    cpu0, client0, wall0 = tree_cpu_ns(pid), time.process_time(), time.monotonic()
    with asyncio.Runner(loop_factory=_loop_factory()) as runner:
        calls, errors, samples = runner.run(_agents(port, seconds, concurrency))
    wall = time.monotonic() - wall0
    burst = Burst(
        calls,
        errors,
        wall,
        (tree_cpu_ns(pid) - cpu0) / 1e9,
        time.process_time() - client0,
    )
    if errors:
        print(f"{errors} failed calls on port {port}: {samples}", file=sys.stderr)
    return burst


def main(
    seconds: float, rounds: int, concurrency: int, warm_up_s: float = WARM_UP_S
) -> dict[str, list[Burst]]:
    """Rounds against both servers in turn; the bursts of each (first the plain one's)."""
    runs: dict[str, list[Burst]] = {"rwt serve --mcp": [], "rwt serve --mcp --workers 2": []}
    with ExitStack() as stack:
        servers = [
            stack.enter_context(serve_workers(1, ["--mcp"])),
            stack.enter_context(serve_workers(2, ["--mcp"])),
        ]
        for pid, port in servers:  # the first calls build caches: not timed
            measure(pid, port, warm_up_s, concurrency)
        for _ in range(rounds):
            for name, (pid, port) in zip(runs, servers, strict=True):
                runs[name].append(measure(pid, port, seconds, concurrency))
    return runs


def table(runs: dict[str, list[Burst]]) -> str:
    """A Markdown table of ``main``'s figures (medians of the rounds)."""
    lines = [
        "| server | calls/s | x one process | server CPU per call (ms) | generator CPU per call"
        " (ms) | failed calls |",
        "|---|---|---|---|---|---|",
    ]
    first = None
    for name, bursts in runs.items():
        rate = statistics.median(b.per_s for b in bursts)
        first = first or rate
        server = statistics.median(b.server_cpu_s / max(b.calls, 1) * 1e3 for b in bursts)
        client = statistics.median(b.client_cpu_s / max(b.calls, 1) * 1e3 for b in bursts)
        errors = sum(b.errors for b in bursts)
        lines.append(
            f"| {name} | {rate:.0f} | {rate / first:.2f} | {server:.2f} | {client:.2f} | {errors} |"
        )
    return "\n".join(lines)


def _cli() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--concurrency", type=int, default=16)
    args = parser.parse_args()
    runs = main(args.seconds, args.rounds, args.concurrency)
    print(table(runs))
    RESULTS.parent.mkdir(exist_ok=True)
    record = {
        "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "seconds": args.seconds,
        "concurrency": args.concurrency,
        "runs": {name: [asdict(b) for b in bursts] for name, bursts in runs.items()},
    }
    RESULTS.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    _cli()
