"""A 1 kHz topic to a Server-Sent Events reader and a WebSocket reader, in one run.

``python -m benchmarks.http_sse [--seconds 5] [--rate 1000] [--rounds 3] [--smoke]``

The HTTP API's event stream (docs/http.md) against rosbridge over WebSocket on the
same server at the same time: an in-process server publishes ``/tick``
(``std_msgs/msg/String``) from the graph at ``--rate`` Hz for ``--seconds``, paced by
absolute deadlines; a reader process holds one rosbridge WebSocket subscriber
(``websockets``) and one ``GET /api/topics/tick/events`` (a plain socket, lines cut
by hand) and counts what each got. The figure is messages per second each reader
got over the publishing time, and sse/ws; the goal is sse/ws >= 0.9.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import time
from pathlib import Path

import anyio
from anyio.streams.text import TextReceiveStream

__all__ = ["main", "measure"]

ROOT = Path(__file__).resolve().parent.parent
TOPIC = "/tick"
END = "end"


async def _read_ws(url: str, ready: asyncio.Event) -> int:
    import websockets  # noqa: PLC0415 (the reader process only)

    count = 0
    async with websockets.connect(url, max_size=None) as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": TOPIC, "type": "std_msgs/String"}))
        await ws.send(json.dumps({"op": "call_service", "service": "/rosapi/get_time"}))
        while "get_time" not in str(await ws.recv()):  # the subscription is in place
            pass
        ready.set()
        async for frame in ws:
            op = json.loads(frame)
            if op.get("op") != "publish":
                continue
            if op["msg"]["data"] == END:
                return count
            count += 1
    return count


async def _read_sse(host: str, port: int, ready: asyncio.Event) -> int:
    reader, writer = await asyncio.open_connection(host, port)
    path = f"/api/topics{TOPIC}/events"
    writer.write(f"GET {path} HTTP/1.1\r\nHost: {host}\r\n\r\n".encode())
    while (await reader.readline()).strip():  # the head, until its blank line
        pass
    ready.set()  # the head comes once the subscription is in place
    count = 0
    end = b'data: {"data":"' + END.encode() + b'"}'
    while line := await reader.readline():
        if line.startswith(b"data: "):
            if line.rstrip() == end:
                break
            count += 1
    writer.close()
    return count


async def _reader(url: str) -> None:
    """The reader process: both readers, ``ready`` once both subscribed, then the counts."""
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    ws_ready, sse_ready = asyncio.Event(), asyncio.Event()
    tasks = asyncio.gather(_read_ws(url, ws_ready), _read_sse(host, int(port), sse_ready))
    await ws_ready.wait()
    await sse_ready.wait()
    print("ready", flush=True)
    ws, sse = await tasks
    print(json.dumps({"ws": ws, "sse": sse}), flush=True)


async def measure(seconds: float, rate_hz: float) -> dict[str, float]:
    """One run: the messages each reader got per second of publishing, and sse/ws.

    Raises:
        RuntimeError: the reader process failed.
    """
    from rwt_graph.graph import Graph  # noqa: PLC0415 (the server's side only)
    from rwt_transports.server import RosbridgeServer, ServerConfig  # noqa: PLC0415

    graph = Graph()
    publisher = graph.create_publisher(TOPIC, "std_msgs/msg/String")
    server = RosbridgeServer(graph, ServerConfig(port=0, tf=False))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        command = [sys.executable, "-m", "benchmarks.http_sse", "--reader", url]
        async with await anyio.open_process(command, cwd=ROOT) as reader:
            assert reader.stdout is not None
            lines = TextReceiveStream(reader.stdout)
            buffered = ""
            while "ready\n" not in buffered:
                buffered += await lines.receive()
            count = int(seconds * rate_hz)
            start = time.perf_counter()
            for n in range(count):
                delay = start + n / rate_hz - time.perf_counter()
                await anyio.sleep(max(0.0, delay))
                publisher.publish({"data": str(n)})
            elapsed = time.perf_counter() - start
            publisher.publish({"data": END})
            while buffered.count("\n") < 2:
                buffered += await lines.receive()
            await reader.wait()
        server.stop()
    got = json.loads(buffered.splitlines()[1])
    if not isinstance(got, dict):
        raise RuntimeError(f"the reader said {buffered!r}")
    return {
        "sent": count,
        "ws": got["ws"],
        "sse": got["sse"],
        "ws_per_s": got["ws"] / elapsed,
        "sse_per_s": got["sse"] / elapsed,
        "sse_over_ws": got["sse"] / max(1, got["ws"]),
    }


def main(argv: list[str] | None = None) -> None:
    """The command line (the module's docstring)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.http_sse")
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--smoke", action="store_true", help="a fraction of a second, once")
    parser.add_argument("--reader", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.reader:
        asyncio.run(_reader(args.reader))
        return
    if args.smoke:
        args.seconds, args.rounds = 0.2, 1
    runs = [anyio.run(measure, args.seconds, args.rate) for _ in range(args.rounds)]
    for each in runs:
        print(json.dumps(each), file=sys.stderr)
    print("| reader | messages/s (median) |\n|---|---|")
    for kind in ("ws", "sse"):
        print(f"| {kind} | {statistics.median(r[f'{kind}_per_s'] for r in runs):.1f} |")
    print(f"sse/ws: {statistics.median(r['sse_over_ws'] for r in runs):.3f}")


if __name__ == "__main__":
    main()
