"""``python -m benchmarks.params``: what large parameters cost the server and a bystander.

    git archive REF src | tar -x -C /tmp/base
    python -m benchmarks.params [--base-src /tmp/base/src] [--rounds 3] [--only rosapi ros2 ...]
    python -m benchmarks.params --table benchmarks/results/params.json   # a saved run's medians

Each case runs against ``rwt serve`` from this checkout (``rwt``) and, with
``--base-src DIR``, from another checkout's ``src`` (``base``: the code before a
change), alternating round by round in one run, so each ratio comes from one
machine state. In every case a bystander rosbridge client calls
``/rosapi/get_time`` one call after another (10 ms apart) and records each round
trip, in a process of its own; the figures are the server's CPU
(``/proc/<pid>/stat``) over the case and the bystander's round trips while it ran
(p50, p99, max).

Cases (docs/limits.md, "Per server", and "ROS 2 link"):

- ``rosapi``: a rosbridge client sets a parameter of its own node to an array of
  ``--ints`` integers (1,000,000) four times through ``/rosapi/set_param``.
- ``rosapi50``: the same with 50 idle Foxglove clients connected.
- ``foxglove50``: the same through a Foxglove client's ``setParameters``, with 50
  idle Foxglove clients connected.
- ``ros2``: ``rwt serve --ros2 --no-tf``; an rclpy node (its own process) declares
  ``--ros2-params`` (20,000) integer parameters; the figures cover the 20 s after
  it started (the link copies its first share of them and refreshes the copy every
  second), against ``ros2-control``, the same 20 s without that node. Needs rclpy
  (the ``ros2`` extra).

The table, and the medians with rwt/base, go to stdout; every row to
``results/params.json``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import statistics
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from .servers import ROOT, Server, start_server

RESULTS = Path(__file__).resolve().parent / "results"
PING_EVERY_S = 0.01
"""The bystander's pause between one round trip and the next call."""
FOXGLOVE_CLIENTS = 50
SETS = 4
ROS2_WINDOW_S = 20.0
"""How long the ``ros2`` case watches after the node started."""
DOMAIN = 125
"""The ``ros2`` case's ``ROS_DOMAIN_ID``: clear of the tests' (from 150) and ros2_graph's."""
CASES = ("rosapi", "rosapi50", "foxglove50", "ros2")

NODE = """
import sys
import rclpy
count = int(sys.argv[1])
rclpy.init()
node = rclpy.create_node("param_bench")
node.declare_parameters("", [(f"p{n:05}", n) for n in range(count)])
print("ready", flush=True)
rclpy.spin(node)
"""


@dataclass
class Figures:
    """One case on one server: its CPU and the bystander's round trips (ms)."""

    case: str
    server: str
    cpu_s: float
    calls: int
    p50_ms: float
    p99_ms: float
    max_ms: float
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


class Bystander:
    """A rosbridge client in a process of its own timing ``/rosapi/get_time`` round trips.

    Its own process: the JSON this process builds for the sets (megabytes) would
    otherwise delay the bystander's own loop and count as the server's.
    """

    def __init__(self, port: int) -> None:
        self.port = port
        self._proc: asyncio.subprocess.Process | None = None

    async def start(self) -> None:
        """Start timing; returns once the bystander is connected."""
        self._proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            "benchmarks.params",
            "bystander",
            str(self.port),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            cwd=ROOT,
        )
        assert self._proc.stdout is not None
        assert (await self._proc.stdout.readline()).strip() == b"connected"

    async def stop(self) -> list[float]:
        """Stop; the round trips (s)."""
        assert self._proc is not None and self._proc.stdin is not None
        self._proc.stdin.write(b"stop\n")
        await self._proc.stdin.drain()
        out, _ = await asyncio.wait_for(self._proc.communicate(), 120)
        return list(json.loads(out.decode().splitlines()[-1]))


async def _bystander(port: int) -> None:
    """The bystander process: ping until a line comes on stdin; print the round trips."""
    import websockets  # noqa: PLC0415

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_reader(sys.stdin.fileno(), stop.set)
    rtts: list[float] = []
    url = f"ws://127.0.0.1:{port}"
    async with websockets.connect(url, max_size=None, compression=None, ping_interval=None) as ws:
        print("connected", flush=True)
        n = 0
        while not stop.is_set():
            n += 1
            started = time.perf_counter()
            call = {"op": "call_service", "service": "/rosapi/get_time", "id": f"t{n}"}
            await ws.send(json.dumps(call))
            while json.loads(await ws.recv()).get("id") != f"t{n}":
                pass
            rtts.append(time.perf_counter() - started)
            await asyncio.sleep(PING_EVERY_S)
    print(json.dumps(rtts), flush=True)


async def _recv_until(ws: Any, predicate: Any, within: float = 120.0) -> dict[str, Any]:
    async with asyncio.timeout(within):
        while True:
            frame = await ws.recv()
            if isinstance(frame, str):
                op = json.loads(frame)
                if predicate(op):
                    return op  # type: ignore[no-any-return]


async def _own_node(ws: Any, probe: Any, topic: str) -> str:
    """The node of the connection that advertised ``topic`` (rosapi's publishers of it)."""
    for _ in range(100):
        await probe.send(
            json.dumps(
                {
                    "op": "call_service",
                    "service": "/rosapi/publishers",
                    "args": {"topic": topic},
                    "id": "who",
                }
            )
        )
        reply = await _recv_until(probe, lambda op: op.get("id") == "who")
        if reply["values"]["publishers"]:
            return str(reply["values"]["publishers"][0])
        await asyncio.sleep(0.05)
    raise RuntimeError(f"nobody publishes {topic}")


def _value_text(ints: int) -> str:
    return json.dumps(list(range(ints)))


async def _set_through_rosapi(port: int, ints: int) -> None:
    import websockets  # noqa: PLC0415

    url = f"ws://127.0.0.1:{port}"
    async with websockets.connect(url, max_size=None, compression=None, ping_interval=None) as ws:
        await ws.send(
            json.dumps({"op": "advertise", "topic": "/bench/me", "type": "std_msgs/String"})
        )
        node = await _own_node(ws, ws, "/bench/me")
        for n in range(SETS):
            text = _value_text(ints + n)
            args = {"name": f"{node}:big", "value": text}
            call = {"op": "call_service", "service": "/rosapi/set_param", "args": args, "id": "s"}
            await ws.send(json.dumps(call))
            reply = await _recv_until(ws, lambda op: op.get("id") == "s")
            assert reply["values"]["successful"] is True, str(reply)[:300]


async def _set_through_foxglove(port: int, ints: int) -> None:
    import websockets  # noqa: PLC0415

    url = f"ws://127.0.0.1:{port}"
    async with (
        websockets.connect(
            url,
            subprotocols=["foxglove.sdk.v1"],  # type: ignore[list-item]
            max_size=None,
            compression=None,
            ping_interval=None,
        ) as fox,
        websockets.connect(url, max_size=None, compression=None, ping_interval=None) as probe,
    ):
        await _recv_until(fox, lambda op: op.get("op") == "serverInfo")
        channel = {
            "id": 1,
            "topic": "/bench/fox",
            "encoding": "json",
            "schemaName": "std_msgs/msg/String",
            "schema": "",
        }
        await fox.send(json.dumps({"op": "advertise", "channels": [channel]}))
        node = await _own_node(fox, probe, "/bench/fox")
        for n in range(SETS):
            value = list(range(ints + n))
            parameter = {"name": f"{node}.big", "value": value}
            await fox.send(
                json.dumps({"op": "setParameters", "parameters": [parameter], "id": "s"})
            )
            reply = await _recv_until(fox, lambda op: op.get("op") in ("parameterValues", "status"))
            assert reply.get("op") == "parameterValues", str(reply)[:300]


@contextlib.asynccontextmanager
async def _idle_foxglove(port: int, count: int) -> Any:
    import websockets  # noqa: PLC0415

    url = f"ws://127.0.0.1:{port}"
    async with contextlib.AsyncExitStack() as stack:
        for _ in range(count):
            ws = await stack.enter_async_context(
                websockets.connect(  # type: ignore[list-item]
                    url, subprotocols=["foxglove.sdk.v1"], compression=None, ping_interval=None
                )
            )
            await _recv_until(ws, lambda op: op.get("op") == "serverInfo")
        yield


def _figures(case: str, server: Server, cpu_s: float, rtts: list[float], note: str = "") -> Figures:
    ms = sorted(1000 * rtt for rtt in rtts) or [float("nan")]
    p99 = ms[min(len(ms) - 1, int(0.99 * len(ms)))]
    return Figures(case, server.kind, cpu_s, len(rtts), statistics.median(ms), p99, ms[-1], note)


async def _value_case(case: str, server: Server, ints: int) -> Figures:
    idle = FOXGLOVE_CLIENTS if case.endswith("50") else 0
    async with _idle_foxglove(server.port, idle):
        bystander = Bystander(server.port)
        await bystander.start()
        await asyncio.sleep(0.5)
        before = server.stats().cpu_s
        if case.startswith("foxglove"):
            await _set_through_foxglove(server.port, ints)
        else:
            await _set_through_rosapi(server.port, ints)
        cpu = server.stats().cpu_s - before
        rtts = await bystander.stop()
    return _figures(case, server, cpu, rtts)


def _ros_env() -> dict[str, str]:
    from .ros2_bridge import ros_env  # noqa: PLC0415

    return {**os.environ, **ros_env(DOMAIN)}


async def _names_of(port: int, prefix: str) -> int:
    import websockets  # noqa: PLC0415

    async with websockets.connect(f"ws://127.0.0.1:{port}", max_size=None) as ws:
        call = {"op": "call_service", "service": "/rosapi/get_param_names", "id": "n"}
        await ws.send(json.dumps(call))
        reply = await _recv_until(ws, lambda op: op.get("id") == "n")
        return sum(name.startswith(prefix) for name in reply["values"]["names"])


async def _ros2_case(case: str, server: Server, params: int) -> Figures:
    bystander = Bystander(server.port)
    node = None
    await bystander.start()
    before = server.stats().cpu_s
    started = time.monotonic()
    copied_after = None
    try:
        if case == "ros2":
            node = await asyncio.create_subprocess_exec(
                sys.executable,
                "-c",
                NODE,
                str(params),
                env=_ros_env(),
                stdout=subprocess.PIPE,
                stdin=subprocess.DEVNULL,
            )
            assert node.stdout is not None
            line = await node.stdout.readline()
            assert line.strip() == b"ready", line
        while time.monotonic() - started < ROS2_WINDOW_S:
            await asyncio.sleep(1.0)
            if (
                case == "ros2"
                and copied_after is None
                and await _names_of(server.port, "/param_bench:p")
            ):
                copied_after = time.monotonic() - started
        cpu = server.stats().cpu_s - before
        rtts = await bystander.stop()
        copied = await _names_of(server.port, "/param_bench:") if case == "ros2" else 0
    finally:
        if node is not None:
            node.terminate()
            await asyncio.wait_for(node.wait(), 10)
    note = "" if case != "ros2" else f"first copied after {copied_after or float('nan'):.0f} s"
    figures = _figures(case, server, cpu, rtts, note)
    if case == "ros2":
        figures.extra["copied"] = copied
    return figures


def _start(kind: str, src: Path | None, ros2: bool) -> Server:
    extra = ["--ros2", "--no-tf"] if ros2 else []
    if ros2:
        os.environ.update(_ros_env())
    server = start_server(kind, extra=extra, src=src)
    server.kind = "base" if src is not None else "rwt"
    return server


async def _round(case: str, src: Path | None, args: argparse.Namespace) -> list[Figures]:
    ros2 = case == "ros2"
    server = _start("rwt", src, ros2)
    try:
        await asyncio.sleep(3.0 if ros2 else 0.5)  # the link's first sweeps
        if ros2:
            return [
                await _ros2_case("ros2-control", server, args.ros2_params),
                await _ros2_case("ros2", server, args.ros2_params),
            ]
        return [await _value_case(case, server, args.ints)]
    finally:
        server.stop()


def _table(rows: list[Figures]) -> str:
    lines = [
        "| case | server | server CPU s | bystander calls | p50 ms | p99 ms | max ms | note |",
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row.case} | {row.server} | {row.cpu_s:.2f} | {row.calls} | {row.p50_ms:.1f} "
            f"| {row.p99_ms:.1f} | {row.max_ms:.0f} | {row.note} {row.extra or ''} |"
        )
    return "\n".join(lines)


def _medians(rows: list[Figures]) -> str:
    """Each case's medians by server, and rwt over base where both ran."""
    keys = sorted({(row.case, row.server) for row in rows})
    out = [
        "| case | server | CPU s | p99 ms | max ms | rwt/base CPU | rwt/base p99 | rwt/base max |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    med: dict[tuple[str, str], tuple[float, float, float]] = {}
    for key in keys:
        mine = [row for row in rows if (row.case, row.server) == key]
        med[key] = (
            statistics.median(r.cpu_s for r in mine),
            statistics.median(r.p99_ms for r in mine),
            statistics.median(r.max_ms for r in mine),
        )
    for case, server in keys:
        figures = med[(case, server)]
        base = med.get((case, "base"))
        ratios = ["", "", ""]
        if server == "rwt" and base is not None:
            ratios = [f"{mine / theirs:.3f}" for mine, theirs in zip(figures, base, strict=True)]
        cpu, p99, top = figures
        out.append(
            f"| {case} | {server} | {cpu:.2f} | {p99:.1f} | {top:.0f} | {' | '.join(ratios)} |"
        )
    return "\n".join(out)


async def run(args: argparse.Namespace) -> list[Figures]:
    """Every selected case, ``--rounds`` times, alternating base and rwt."""
    srcs: list[Path | None] = [None] if args.base_src is None else [args.base_src, None]
    rows: list[Figures] = []
    for case in args.only or CASES:
        if case == "ros2" and not _rclpy():
            print("ros2: skipped (rclpy does not import)", file=sys.stderr)
            continue
        for n in range(args.rounds):
            order = srcs if n % 2 == 0 else srcs[::-1]
            for src in order:
                got = await _round(case, src, args)
                for row in got:
                    print(_table([row]).splitlines()[-1], file=sys.stderr, flush=True)
                rows += got
    return rows


def _rclpy() -> bool:
    from .ros2_bridge import rclpy_available  # noqa: PLC0415

    return rclpy_available()


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, run, print and save the table."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["bystander"]:
        asyncio.run(_bystander(int(argv[1])))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base-src", help="another checkout's src directory, measured too")
    parser.add_argument("--only", nargs="*", choices=CASES)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--ints", type=int, default=1_000_000)
    parser.add_argument("--ros2-params", type=int, default=20_000)
    parser.add_argument("--quick", action="store_true", help="tiny counts (a smoke test)")
    parser.add_argument("--table", help="print the medians of a saved run (results/params.json)")
    args = parser.parse_args(argv)
    if args.quick:
        args.ints, args.ros2_params, args.rounds = 10_000, 500, 1
    if args.base_src:
        args.base_src = Path(args.base_src).resolve()
    if args.table:  # the medians of a saved run
        rows = [Figures(**row) for row in json.loads(Path(args.table).read_text())]
        print(_medians(rows))
        return 0
    rows = asyncio.run(run(args))
    print(_table(rows))
    print()
    print(_medians(rows))
    if not args.quick:
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / "params.json").write_text(json.dumps([asdict(row) for row in rows], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
