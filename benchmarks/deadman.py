"""How soon the safety envelope's dead-man stop reaches a subscriber.

``python -m benchmarks.deadman [--rounds 10] [--smoke]``

``rwt serve --safety`` (this checkout's ``src``, a process of its own) with the rules of
docs/safety.md (``/cmd_vel``: ``deadman_s = 0.5``). Each round, a WebSocket publisher
sends a Twist at 10 Hz for one second, then either goes quiet while connected or closes
its connection; a WebSocket subscriber of ``/cmd_vel`` notes when the stop arrives. The
figure is the time from the publisher's last command (quiet) or its close (gone) to
the stop's arrival at the subscriber, both read on this process's monotonic clock: so
it includes the sockets and the server's loop. The envelope promises ``deadman_s +
0.1`` s (0.6 s); the table gives the minimum, median, 95th percentile and maximum of
each case, and the load average beside them.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["main", "measure"]

ROOT = Path(__file__).resolve().parent.parent
RULES = """\
[[topic]]
name = "/cmd_vel"
type = "geometry_msgs/msg/Twist"
on_violation = "clamp"
deadman_s = 0.5
[topic.bounds]
"linear.x" = [-0.5, 0.5]
[topic.stop]
linear = { x = 0.0, y = 0.0, z = 0.0 }
angular = { x = 0.0, y = 0.0, z = 0.0 }
"""
DEADMAN_S = 0.5
PROMISE_S = DEADMAN_S + 0.1
RATE_S = 0.1
COMMANDS = 10
WAIT_S = 10.0  # a bound on a stop that never comes


def _twist(x: float) -> dict[str, object]:
    return {"linear": {"x": x, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


async def _round(url: str, close: bool) -> float:
    """One round: seconds from the last command (or the close) to the stop's arrival."""
    import websockets  # noqa: PLC0415 (the bench extra's)

    async with websockets.connect(url) as subscriber:
        await subscriber.send(json.dumps({"op": "subscribe", "topic": "/cmd_vel"}))
        await subscriber.send(json.dumps({"op": "call_service", "service": "/rosapi/get_time"}))
        while "service_response" not in str(await subscriber.recv()):
            pass
        publisher = await websockets.connect(url)
        op = {"op": "publish", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"}
        for _ in range(COMMANDS):
            await publisher.send(json.dumps({**op, "msg": _twist(0.2)}))
            mark = time.monotonic()
            await asyncio.sleep(RATE_S)
        if close:
            mark = time.monotonic()
            await publisher.close()
        async with asyncio.timeout(WAIT_S):
            while True:
                message = json.loads(await subscriber.recv())
                if message.get("op") == "publish" and message["msg"]["linear"]["x"] == 0.0:
                    arrived = time.monotonic()
                    break
        if not close:
            await publisher.close()
    return arrived - mark


async def _rounds(url: str, rounds: int) -> dict[str, list[float]]:
    figures: dict[str, list[float]] = {"quiet": [], "gone": []}
    for _ in range(rounds):
        figures["quiet"].append(await _round(url, close=False))
        figures["gone"].append(await _round(url, close=True))
    return figures


def measure(rounds: int) -> dict[str, list[float]]:
    """Seconds to the stop, ``rounds`` of each case, against a fresh ``rwt serve``."""
    with tempfile.TemporaryDirectory() as folder:
        rules = Path(folder) / "safety.toml"
        rules.write_text(RULES, "utf-8")
        env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
        command = [sys.executable, "-m", "rwt", "serve", "--port", "0", "--safety", str(rules)]
        command += ["--log-level", "error"]
        server = subprocess.Popen(command, stdout=subprocess.PIPE, env=env)
        try:
            assert server.stdout is not None
            url = server.stdout.readline().decode().strip().removeprefix("listening on ")
            return asyncio.run(_rounds(url, rounds))
        finally:
            server.terminate()
            server.wait(10)
            if server.stdout is not None:
                server.stdout.close()


def table(figures: dict[str, list[float]]) -> str:
    """The figures as a Markdown table (milliseconds)."""
    load = os.getloadavg()[0]
    lines = [
        f"load average {load:.2f}; promise: {PROMISE_S * 1000:.0f} ms",
        "",
        "| case | rounds | min ms | median ms | p95 ms | max ms | within the promise |",
        "|---|---|---|---|---|---|---|",
    ]
    for case, values in figures.items():
        ordered = sorted(values)
        p95 = ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]
        within = sum(value <= PROMISE_S for value in values)
        lines.append(
            f"| {case} | {len(values)} | {ordered[0] * 1000:.0f} | "
            f"{statistics.median(values) * 1000:.0f} | {p95 * 1000:.0f} | "
            f"{ordered[-1] * 1000:.0f} | {within}/{len(values)} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict[str, list[float]]:
    """Run the rounds and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--smoke", action="store_true", help="one round of each case")
    args = parser.parse_args(argv)
    figures = measure(1 if args.smoke else args.rounds)
    print(table(figures))
    return figures


if __name__ == "__main__":
    main()
