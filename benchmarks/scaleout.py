"""``python -m benchmarks scaleout``: rwt over Zenoh, measured against itself and bare Zenoh.

Three measurements, each in one run on one machine state (ratios, not absolutes,
are what carry over to another machine):

- Z1 latency: a 100 B ``std_msgs/String`` publish from a WebSocket client on
  server A to a subscriber on server B (two ``rwt serve --zenoh`` processes on
  loopback), p50/p99, next to both clients on one server (in-process).
- Z2 fan-out: 1 publisher and 100 subscribers on the port of ``rwt serve
  --workers 2``, aggregate deliveries/s, against a plain single ``rwt serve``;
  once with a ``websockets`` generator (one message at a time) and once with the
  suite's raw-socket generator (``fanout_raw``: a window-paced stream, a few us
  of generator CPU per delivery).
- Z3 throughput A->B, 100 B and 1 MB messages, msg/s and MB/s. At the link
  (``zenoh_link``): a graph publishing in process A, a graph subscription counting
  in process B, each graph with its Zenoh link, against a bare Zenoh
  publisher/subscriber pair in two processes carrying payloads of the same CDR
  sizes, interleaved round by round (the target is on this one). End to end: a
  WebSocket client on server A to one on server B, next to both clients on A
  (what the link adds to a rosbridge server).

The load generator is this one Python process (``websockets``), whose own CPU
bounds what it can measure on a small machine; ``results/scaleout.json`` keeps
every figure.

Two more modes, each alone: ``--workers 1,2,4 --fanouts K [--subscribers S]``, the
scale table (``scale_workers``: K parallel fan-outs per worker count, deliveries/s,
server and generator CPU per delivery, dropped, the server's memory; with
``--topics-per-fanout T`` many topics, with ``--idle N`` many idle clients beside),
and ``--cost-model``, the constants of docs/scaling.md's cost model (``scale_costs``).
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
from collections import Counter
from pathlib import Path
from typing import Any

import websockets

from .fanout_raw import FanOut, fan_out_raw
from .proctree import by_role, tree_cpu_ns, tree_threads
from .servers import rwt_pythonpath
from .zenoh_link import rclpy_available, run_pair

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results" / "scaleout.json"
COSTS = REPO / "benchmarks" / "results" / "scaleout_costs.json"
TIMEOUT_S = 120.0


def _free_port() -> int:
    import socket  # noqa: PLC0415

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": rwt_pythonpath(), "PYTHONUNBUFFERED": "1"}


@contextlib.asynccontextmanager
async def server(*args: str) -> Any:
    """``rwt serve --port 0 --no-tf ARGS``; yields its ws:// URL; stopped at the end.

    The server's process id is ``SERVER_PIDS[url]`` while it runs.
    """
    cmd = [sys.executable, "-m", "rwt", "serve", "--port", "0", "--no-tf"]
    cmd += ["--log-level", "warning", *args]
    proc = await asyncio.create_subprocess_exec(
        *cmd, stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, env=_env()
    )
    try:
        assert proc.stdout is not None
        line = await asyncio.wait_for(proc.stdout.readline(), TIMEOUT_S)
        url = line.decode().strip().removeprefix("listening on ")
        SERVER_PIDS[url] = proc.pid
        yield url
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.terminate()
        try:
            await asyncio.wait_for(proc.wait(), 15)
        except TimeoutError:
            proc.kill()
            await proc.wait()


PACED_HZ = 1000
"""Messages a second of Z2's paced CPU bursts: 100,000 deliveries a second, about
a third of what one worker delivers saturated here, yet the whole of its core:
unbatched, a delivery costs it about 3.7x as much (benchmarks/JOURNAL.md, "Where a
message crossing workers spends its CPU, by load")."""


SERVER_PIDS: dict[str, int] = {}


async def paired_bursts(
    rounds: int, burst_s: float = 1.0, rate_hz: float | None = None
) -> dict[str, Any]:
    """Z2 servers' CPU per delivery, ``--workers 2`` against one worker, in paired bursts.

    The CPU time of the same Python work drifts on a shared virtual machine by up
    to a factor of two from one minute to the next (benchmarks/JOURNAL.md, "Workers'
    CPU per delivery"), so two figures taken a minute apart say little about a 15 %
    difference. Both servers run side by side for the whole measurement instead,
    each with 100 subscribers of ``/fan`` and a publisher connected once and probed
    until every subscriber is reached (``fanout_raw.FanOut``). Bursts of
    ``burst_s`` then alternate between them in the order 1, 2, 2, 1 worker(s) per
    round, so a drift within a round weighs on both alike; the server not under
    test is idle meanwhile. Bursts go as fast as the window allows (a saturated
    server: its batches are large), or at ``rate_hz`` messages a second (a paced
    load: messages arrive one at a time, so a delivery costs more, and a worker
    that sleeps between them is woken for each). A
    burst's figure is the CPU time of every thread of every process of the
    server under test (``tree_cpu_ns``) from its first send to
    its last delivery, over the deliveries (none may be dropped). A round's ratio
    is the mean of its two 2-worker bursts over the mean of its two 1-worker ones.

    Returns:
        ``rounds``: per round the us per delivery of each burst (``one``, ``two``,
        lists of two) and ``ratio``; ``median_one``, ``median_two`` (us per
        delivery over all bursts) and ``median_ratio`` (of the rounds' ratios);
        ``threads``: per server, its threads' CPU ns and runs per message by role
        (``proctree.by_role``, from just before each burst to just after it).
    """
    async with server() as one_url, server("--workers", "2") as two_url:
        await asyncio.sleep(2)  # every worker listening
        setups: dict[str, tuple[FanOut, int]] = {}
        for name, url in (("one", one_url), ("two", two_url)):
            port = int(url.rsplit(":", 1)[1].split("/")[0])
            setups[name] = (await asyncio.to_thread(FanOut, port), SERVER_PIDS[url])
        done: list[dict[str, Any]] = []
        threads: dict[str, Counter[str]] = {"one": Counter(), "two": Counter()}
        messages = {"one": 0.0, "two": 0.0}
        try:
            for _ in range(rounds):
                found: dict[str, list[float]] = {"one": [], "two": []}
                for name in ("one", "two", "two", "one"):
                    fan, pid = setups[name]
                    before = tree_threads(pid)
                    got = await asyncio.to_thread(fan.burst, burst_s, pid, tree_cpu_ns, rate_hz)
                    threads[name] += by_role(before, tree_threads(pid), pid)
                    messages[name] += got[0] / len(fan.subs)
                    found[name].append(got[1] / 1e3 / max(got[0], 1))
                ratio = statistics.mean(found["two"]) / statistics.mean(found["one"])
                done.append({**found, "ratio": ratio})
        finally:
            for fan, _ in setups.values():
                fan.close()
    return {
        "rounds": done,
        "median_one": statistics.median(x for r in done for x in r["one"]),
        "median_two": statistics.median(x for r in done for x in r["two"]),
        "median_ratio": statistics.median(r["ratio"] for r in done),
        "threads": {
            name: {key: value / max(messages[name], 1) for key, value in sorted(counts.items())}
            for name, counts in threads.items()
        },
    }


def paired_table(found: dict[str, Any]) -> str:
    """The rounds of ``paired_bursts`` and their medians, as Markdown lines."""
    lines = [
        "| round | 1 worker, us/delivery (bursts 1 and 4) | 2 workers (bursts 2 and 3) | ratio |",
        "|---|---|---|---|",
    ]
    for number, pair in enumerate(found["rounds"], 1):
        one = "; ".join(f"{x:.2f}" for x in pair["one"])
        two = "; ".join(f"{x:.2f}" for x in pair["two"])
        lines.append(f"| {number} | {one} | {two} | {pair['ratio']:.2f} |")
    ratios = sorted(r["ratio"] for r in found["rounds"])
    lines.append(
        f"| median | {found['median_one']:.2f} | {found['median_two']:.2f} | "
        f"{found['median_ratio']:.2f} (rounds {ratios[0]:.2f}-{ratios[-1]:.2f}) |"
    )
    return "\n".join([*lines, "", *threads_table(found["threads"])])


def threads_table(threads: dict[str, dict[str, float]]) -> list[str]:
    """Per message, each role's CPU (us) and runs in each server, as Markdown lines."""
    lines = [
        "| threads (every worker's) | 1 worker: us/msg; runs/msg | 2 workers: us/msg; runs/msg |",
        "|---|---|---|",
    ]
    roles = sorted({key.rsplit(" ", 1)[0] for found in threads.values() for key in found})
    for role in [*roles, "all"]:
        cells = []
        for name in ("one", "two"):
            found = threads.get(name, {})
            pick = roles if role == "all" else [role]
            ns = sum(found.get(f"{r} ns", 0.0) for r in pick)
            runs = sum(found.get(f"{r} runs", 0.0) for r in pick)
            cells.append(f"{ns / 1e3:.1f}; {runs:.2f}")
        lines.append(f"| {role} | {cells[0]} | {cells[1]} |")
    return lines


async def connect(url: str) -> Any:
    return await websockets.connect(url, max_size=None, compression=None, ping_interval=None)


def publish_frame(topic: str, data: str) -> str:
    return json.dumps({"op": "publish", "topic": topic, "msg": {"data": data}})


async def subscribe(ws: Any, topic: str) -> None:
    await ws.send(json.dumps({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"}))


async def advertise(ws: Any, topic: str) -> None:
    await ws.send(json.dumps({"op": "advertise", "topic": topic, "type": "std_msgs/msg/String"}))


async def until_flowing(pub: Any, subs: list[Any], topic: str) -> None:
    """Publish probes until every subscriber got one (discovery across processes is eventual)."""
    pending = set(range(len(subs)))
    deadline = time.monotonic() + TIMEOUT_S
    while pending and time.monotonic() < deadline:
        await pub.send(publish_frame(topic, "probe"))
        for index in list(pending):
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(subs[index].recv(), 0.05)
                pending.discard(index)
    if pending:
        raise RuntimeError(f"{len(pending)} subscribers never got a message")
    await asyncio.sleep(0.5)
    for ws in subs:  # drop the probes still in flight
        with contextlib.suppress(TimeoutError):
            while True:
                await asyncio.wait_for(ws.recv(), 0.05)


async def latency(pub_url: str, sub_url: str, count: int) -> dict[str, float]:
    """p50/p99 of one 100 B publish at a time, milliseconds."""
    pub, sub = await connect(pub_url), await connect(sub_url)
    try:
        await subscribe(sub, "/lat")
        await advertise(pub, "/lat")
        await until_flowing(pub, [sub], "/lat")
        times = []
        for number in range(count):
            data = f"{number:010d}".ljust(100, "x")
            start = time.perf_counter()
            await pub.send(publish_frame("/lat", data))
            while data not in await asyncio.wait_for(sub.recv(), TIMEOUT_S):
                pass
            times.append((time.perf_counter() - start) * 1000)
        times.sort()
        return {"p50_ms": times[len(times) // 2], "p99_ms": times[int(len(times) * 0.99) - 1]}
    finally:
        await pub.close()
        await sub.close()


async def fan_out(url: str, subscribers: int, count: int) -> dict[str, float]:
    """Deliveries/s of ``count`` 100 B messages to ``subscribers`` clients on ``url``."""
    subs = [await connect(url) for _ in range(subscribers)]
    pub = await connect(url)
    try:
        for ws in subs:
            await subscribe(ws, "/fan")
        await advertise(pub, "/fan")
        await until_flowing(pub, subs, "/fan")
        data = "y" * 100
        start = time.perf_counter()

        last = [start]

        async def drain(ws: Any) -> int:
            got = 0
            with contextlib.suppress(TimeoutError):
                while got < count:
                    await asyncio.wait_for(ws.recv(), 3)
                    got += 1
                    last[0] = max(last[0], time.perf_counter())
            return got

        cpu = time.process_time()
        receivers = [asyncio.create_task(drain(ws)) for ws in subs]
        for _ in range(count):
            await pub.send(publish_frame("/fan", data))
        delivered = sum(await asyncio.gather(*receivers))
        elapsed = last[0] - start
        # The generator's own CPU until the last delivery (the idle wait after it, 3 s
        # of nothing, costs next to none): near 1.0 means one core is all it had,
        # and then it, not the server, bounds the figure.
        generator_cpu = time.process_time() - cpu
        return {
            "deliveries_per_s": delivered / elapsed,
            "delivered": delivered,
            "expected": count * len(subs),
            "generator_cpu_share": generator_cpu / elapsed,
            "generator_cpu_us_per_delivery": generator_cpu / max(delivered, 1) * 1e6,
        }
    finally:
        for ws in [*subs, pub]:
            await ws.close()


async def throughput(pub_url: str, sub_url: str, size: int, count: int) -> dict[str, float]:
    """msg/s and MB/s of ``count`` messages of ``size`` bytes from A to B."""
    pub, sub = await connect(pub_url), await connect(sub_url)
    try:
        await subscribe(sub, "/tp")
        await advertise(pub, "/tp")
        await until_flowing(pub, [sub], "/tp")
        frame = publish_frame("/tp", "z" * size)
        start = time.perf_counter()

        last = [start]

        async def drain() -> int:
            """Count until all came or 3 s pass without one (a lost message)."""
            got = 0
            with contextlib.suppress(TimeoutError):
                while got < count:
                    await asyncio.wait_for(sub.recv(), 3)
                    got += 1
                    last[0] = time.perf_counter()
            return got

        receiver = asyncio.create_task(drain())
        for _ in range(count):
            await pub.send(frame)
        got = await receiver
        elapsed = last[0] - start
        rate = got / elapsed
        return {"msg_per_s": rate, "mb_per_s": rate * size / 1e6, "got": got, "sent": count}
    finally:
        await pub.close()
        await sub.close()


async def link_level(size: int, count: int, rounds: int) -> dict[str, Any]:
    """Z3 at the link (``zenoh_link``): graph A -> graph B against bare Zenoh and rclpy.

    The three kinds alternate within each round (rclpy only where it imports).

    Returns:
        ``link``, ``bare`` and ``rclpy``: the round with the median rate of each, and
        every round's rate under ``rounds``.
    """
    runs: dict[str, list[dict[str, float]]] = {"link": [], "bare": []}
    if rclpy_available():
        runs["rclpy"] = []
    for _ in range(rounds):
        for kind, done in runs.items():
            done.append(await run_pair(kind, size, count, f"tcp/127.0.0.1:{_free_port()}"))
    out: dict[str, Any] = {}
    for kind, results in runs.items():
        ranked = sorted(results, key=lambda r: r["msg_per_s"])
        out[kind] = {**ranked[len(ranked) // 2], "rounds": [r["msg_per_s"] for r in results]}
    return out


async def measure(quick: bool) -> dict[str, Any]:
    scale = 0.1 if quick else 1.0
    results: dict[str, Any] = {}
    hub = f"tcp/127.0.0.1:{_free_port()}"
    async with (
        server("--zenoh", "--zenoh-listen", hub) as a,
        server("--zenoh", "--zenoh-connect", hub) as b,
    ):
        n = max(20, int(1000 * scale))
        results["Z1 in-process"] = await latency(a, a, n)
        results["Z1 A->B"] = await latency(a, b, n)
        for size, count in (
            (100, max(200, int(5000 * scale))),
            (1_000_000, max(5, int(40 * scale))),
        ):
            results[f"Z3 rwt in-process {size} B"] = await throughput(a, a, size, count)
            results[f"Z3 rwt {size} B"] = await throughput(a, b, size, count)
    for size, count in (
        (100, max(2000, int(20_000 * scale))),
        (1_000_000, max(10, int(100 * scale))),
    ):
        # 1 MB rounds last 50-100 ms: one stall moves a round a lot, so more of them
        pair = await link_level(size, count, 1 if quick else (3 if size == 100 else 7))
        results[f"Z3 link {size} B"] = pair["link"]
        results[f"Z3 bare zenoh {size} B"] = pair["bare"]
        if "rclpy" in pair:
            results[f"Z3 rclpy {size} B"] = pair["rclpy"]
    count = max(20, int(300 * scale))
    async with server() as single:
        results["Z2 1 worker"] = await fan_out(single, 100, count)
    async with server("--workers", "2") as pair:
        await asyncio.sleep(2)  # both workers listening (the first prints the line)
        results["Z2 2 workers"] = await fan_out(pair, 100, count)
    duration = max(0.5, 3.0 * scale)
    for label, args in (("1 worker", ()), ("2 workers", ("--workers", "2"))):
        async with server(*args) as url:
            await asyncio.sleep(2)
            port = int(url.rsplit(":", 1)[1].split("/")[0])
            results[f"Z2 raw {label}"] = await asyncio.to_thread(fan_out_raw, port, 100, duration)
    results["Z2 server CPU"] = await paired_bursts(2 if quick else 8, 0.5 if quick else 1.0)
    results["Z2 server CPU paced"] = await paired_bursts(
        2 if quick else 4, 1.0 if quick else 2.0, PACED_HZ
    )
    return results


def table(results: dict[str, Any]) -> str:
    lat_in, lat_ab = results["Z1 in-process"], results["Z1 A->B"]
    one, two = results["Z2 1 worker"], results["Z2 2 workers"]
    rows = [
        "| measure | rwt | reference | ratio | target |",
        "|---|---|---|---|---|",
        f"| Z1 latency 100 B, p50 ms (A->B vs in-process) | {lat_ab['p50_ms']:.2f} | "
        f"{lat_in['p50_ms']:.2f} | {lat_ab['p50_ms'] / lat_in['p50_ms']:.2f} | - |",
        f"| Z1 latency 100 B, p99 ms (A->B vs in-process) | {lat_ab['p99_ms']:.2f} | "
        f"{lat_in['p99_ms']:.2f} | {lat_ab['p99_ms'] / lat_in['p99_ms']:.2f} | - |",
        f"| Z2 deliveries/s, 1 pub -> 100 subs (--workers 2 vs 1); delivered | "
        f"{two['deliveries_per_s']:,.0f}; {two['delivered']}/{two['expected']} | "
        f"{one['deliveries_per_s']:,.0f}; {one['delivered']}/{one['expected']} | "
        f"{two['deliveries_per_s'] / one['deliveries_per_s']:.2f} | >= 1.6 |",
        f"| Z2 load generator CPU (one process): share of a core; us/delivery "
        f"(--workers 2 vs 1) | {two['generator_cpu_share']:.2f}; "
        f"{two['generator_cpu_us_per_delivery']:.1f} | {one['generator_cpu_share']:.2f}; "
        f"{one['generator_cpu_us_per_delivery']:.1f} | - | - |",
    ]
    raw_one, raw_two = results["Z2 raw 1 worker"], results["Z2 raw 2 workers"]
    rows += [
        f"| Z2 raw-socket generator: deliveries/s (--workers 2 vs 1); delivered | "
        f"{raw_two['deliveries_per_s']:,.0f}; {raw_two['delivered']}/{raw_two['expected']} | "
        f"{raw_one['deliveries_per_s']:,.0f}; {raw_one['delivered']}/{raw_one['expected']} | "
        f"{raw_two['deliveries_per_s'] / raw_one['deliveries_per_s']:.2f} | >= 1.6 |",
        f"| Z2 raw-socket generator CPU: share of a core; us/delivery (--workers 2 vs 1) | "
        f"{raw_two['generator_cpu_share']:.2f}; {raw_two['generator_cpu_us_per_delivery']:.1f} | "
        f"{raw_one['generator_cpu_share']:.2f}; {raw_one['generator_cpu_us_per_delivery']:.1f} "
        f"| - | - |",
    ]
    for key, load in (
        ("Z2 server CPU", "as fast as the window allows"),
        ("Z2 server CPU paced", f"paced at {PACED_HZ:,} msg/s"),
    ):
        cpu = results[key]
        ratios = sorted(r["ratio"] for r in cpu["rounds"])
        rows.append(
            f"| Z2 servers' CPU us/delivery, all processes (--workers 2 vs 1, raw-socket "
            f"generator, paired bursts, {load}) | {cpu['median_two']:.2f} | "
            f"{cpu['median_one']:.2f} | "
            f"{cpu['median_ratio']:.2f} ({ratios[0]:.2f}-{ratios[-1]:.2f}) | <= 1.15 |"
        )
    for size in (100, 1_000_000):
        label = "100 B" if size == 100 else "1 MB"
        link, ref = results[f"Z3 link {size} B"], results[f"Z3 bare zenoh {size} B"]
        rows.append(
            f"| Z3 link A->B {label} (graph to graph), msg/s (MB/s) vs bare Zenoh; delivered | "
            f"{link['msg_per_s']:,.0f} ({link['mb_per_s']:.1f}); {link['got']}/{link['sent']} | "
            f"{ref['msg_per_s']:,.0f} ({ref['mb_per_s']:.1f}); {ref['got']}/{ref['sent']} | "
            f"{link['msg_per_s'] / ref['msg_per_s']:.2f} | "
            f"{'>= 0.7' if size > 100 else '- (rclpy is the goal)'} |"
        )
        rclpy = results.get(f"Z3 rclpy {size} B")
        if rclpy is not None:
            rows.append(
                f"| Z3 link A->B {label} vs rclpy (Fast DDS, reliable, keep all), msg/s; "
                f"delivered | {link['msg_per_s']:,.0f}; {link['got']}/{link['sent']} | "
                f"{rclpy['msg_per_s']:,.0f}; {rclpy['got']}/{rclpy['sent']} | "
                f"{link['msg_per_s'] / rclpy['msg_per_s']:.2f} | "
                f"{'>= 1.0' if size == 100 else '-'} |"
            )
            rows.append(
                f"| Z3 {label}: CPU us/msg of A; of B, link vs rclpy | "
                f"{link['sender_cpu_us']:,.0f}; {link['receiver_cpu_us']:,.0f} | "
                f"{rclpy['sender_cpu_us']:,.0f}; {rclpy['receiver_cpu_us']:,.0f} | - | - |"
            )
        rows.append(
            f"| Z3 link {label}: CPU us/msg of A; of B (all threads) vs bare Zenoh | "
            f"{link['sender_cpu_us']:,.0f}; {link['receiver_cpu_us']:,.0f} | "
            f"{ref['sender_cpu_us']:,.0f}; {ref['receiver_cpu_us']:,.0f} | - | - |"
        )
    for size in (100, 1_000_000):
        label = "100 B" if size == 100 else "1 MB"
        ours, local = results[f"Z3 rwt {size} B"], results[f"Z3 rwt in-process {size} B"]
        ref = results[f"Z3 bare zenoh {size} B"]
        rows.append(
            f"| Z3 end to end A->B {label} (WebSocket client -> A -> B -> client), msg/s "
            f"vs both clients on A; delivered | "
            f"{ours['msg_per_s']:,.0f}; {ours['got']}/{ours['sent']} | "
            f"{local['msg_per_s']:,.0f}; {local['got']}/{local['sent']} | "
            f"{ours['msg_per_s'] / local['msg_per_s']:.2f} | - |"
        )
        rows.append(
            f"| Z3 end to end A->B {label}, msg/s vs bare Zenoh (not the link alone) | "
            f"{ours['msg_per_s']:,.0f} | {ref['msg_per_s']:,.0f} | "
            f"{ours['msg_per_s'] / ref['msg_per_s']:.2f} | - |"
        )
    return "\n".join(rows)


def _counts(text: str) -> list[int]:
    """``1,2,4`` as ``[1, 2, 4]``; each at least 1."""
    counts = [int(part) for part in text.split(",") if part.strip()]
    if not counts or min(counts) < 1:
        raise argparse.ArgumentTypeError(f"worker counts of 1 or more, e.g. 1,2,4: {text!r}")
    return counts


def main(argv: list[str] | None = None) -> int:
    """Run the three measurements (or, with ``--workers``, the scale table) and print them."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks scaleout", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="a tenth of the counts (smoke)")
    parser.add_argument("--out", type=Path, help="where the figures go (results/*.json)")
    parser.add_argument(
        "--workers-cpu",
        type=int,
        metavar="ROUNDS",
        help="only the Z2 servers' CPU per delivery: ROUNDS rounds of paired bursts",
    )
    parser.add_argument(
        "--rate",
        type=float,
        metavar="HZ",
        help="with --workers-cpu: bursts paced at HZ messages a second (2 s each)",
    )
    parser.add_argument(
        "--workers",
        type=_counts,
        metavar="N,N,...",
        help="only the scale table: one server per worker count (benchmarks/scale_workers.py)",
    )
    parser.add_argument("--fanouts", type=int, default=1, help="with --workers: parallel fan-outs")
    parser.add_argument(
        "--subscribers", type=int, default=50, help="with --workers: subscribers per fan-out"
    )
    parser.add_argument(
        "--duration", type=float, default=3.0, help="with --workers: each burst, seconds"
    )
    parser.add_argument(
        "--topics-per-fanout",
        type=int,
        default=1,
        metavar="T",
        help="with --workers: each generator drives T fan-outs, a topic each (many topics)",
    )
    parser.add_argument(
        "--idle",
        type=int,
        default=0,
        metavar="N",
        help="with --workers: N idle clients beside the fan-outs (a subscription each to a "
        "topic nothing publishes)",
    )
    parser.add_argument(
        "--smoke", action="store_true", help="with --workers: 0.3 s bursts, nothing saved"
    )
    parser.add_argument(
        "--placement",
        choices=("none", "topic"),
        default="none",
        help="with --workers or --cost-model: the servers' --placement (D57: 'topic', a "
        "topic's connections on one worker)",
    )
    parser.add_argument(
        "--cost-model",
        action="store_true",
        help="the cost model's constants: 1, 2, 4 workers (or --workers) at 10, 50, 100 "
        "subscribers, paired bursts (benchmarks/scale_costs.py)",
    )
    args = parser.parse_args(argv)
    if args.cost_model:
        from .scale_costs import cost_table, measure_costs  # noqa: PLC0415

        workers = args.workers or [1, 2, 4]
        subscribers = [3, 6] if args.smoke else [10, 50, 100]
        rounds, burst = (1, 0.3) if args.smoke else (3, 1.0)
        found = measure_costs(subscribers, workers, rounds, burst, args.placement)
        print(cost_table(found, subscribers, workers))
        if not args.smoke:
            (args.out or COSTS).write_text(json.dumps(found, indent=2) + "\n", "utf-8")
        return 0
    if args.workers:
        from .scale_workers import main as scale_main  # noqa: PLC0415

        return scale_main(
            args.workers,
            args.fanouts,
            args.subscribers,
            args.duration,
            smoke=args.smoke,
            out=args.out,
            topics=args.topics_per_fanout,
            idle=args.idle,
            placement=args.placement,
        )
    if args.workers_cpu:
        burst = (1.0 if args.quick else 2.0) if args.rate else (0.5 if args.quick else 1.0)
        print(paired_table(asyncio.run(paired_bursts(args.workers_cpu, burst, args.rate))))
        return 0
    started = time.perf_counter()
    results = asyncio.run(measure(args.quick))
    print(table(results))
    for key in ("Z2 server CPU", "Z2 server CPU paced"):
        print(f"\n{key}, per message:\n" + "\n".join(threads_table(results[key]["threads"])))
    results["elapsed_s"] = time.perf_counter() - started
    if not args.quick:
        (args.out or RESULTS).write_text(json.dumps(results, indent=2) + "\n", "utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
