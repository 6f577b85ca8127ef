"""Requests read before they are admitted, replayed: held bodies and 1-byte chunks (D58).

Two classes of the sixth hardening campaign, replayed with the attack replays' kit
(``benchmarks/attack_kit.py``: a fresh ``rwt serve``, a rosbridge WebSocket bystander
in its own process on 127.0.0.2 calling ``/rosapi/get_time`` every 50 ms, 2 s of
baseline, then the attack; the server's CPU and RSS from ``/proc``):

- ``held``: one address (127.0.0.1) opens ``--sockets`` sockets (250), each posting a
  10 MiB body to the HTTP API short of its last byte, holds them ``HOLD_S``, then
  closes them. Before, the server read every body (RSS 49 -> 3,121 MB) and kept 1.5 GB
  after they closed. Measured: the server's RSS at its peak against the bound on what
  one host's requests may hold (a quarter of ``--max-fragment-memory``, inside
  ``--memory-budget``), its RSS after they closed, what the sockets got (429 with
  ``Retry-After``), and a 1 MiB post from another host (127.0.0.2) meanwhile.
- ``chunks-api``, ``chunks-mcp``, ``chunks-webrtc``: four sockets of one address send
  ``Transfer-Encoding: chunked`` bodies of one byte a chunk to ``/api/...``, ``/mcp``
  or ``/webrtc`` as fast as the server reads them (a socket refused, a body over its
  endpoint's limit, starts again). Before, the reader drove h11 through a whole read's
  chunks without yielding: the bystander's round trip went from 1 ms to 530 ms at the
  median. Measured: the bystander's p50 / p99 / max (target: p99 under 150 ms), the
  time a newcomer of another host waits for ``GET /version``, and the bytes the
  attackers got read.

Run: ``python -m benchmarks.http_admission [--attack held --attack chunks-api ...]
[--scale 1] [--sockets 250]``; ``RWT_BENCH_SRC=/path/to/before/src`` for the figures
before. Results: ``results/http_admission.json`` (the latest run of each source).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections import Counter
from dataclasses import asdict, replace
from functools import partial
from pathlib import Path
from typing import Any

import anyio
import httpx
from anyio.abc import SocketStream

from .attack_kit import OTHER_HOST, Attack, Context, Outcome, Replay, replay
from .servers import proc_stats

__all__ = ["ATTACKS", "held_attack", "main"]

RESULTS = Path(__file__).resolve().parent / "results" / "http_admission.json"
MiB = 1024 * 1024
ATTACKER = "127.0.0.1"
TIMEOUT_S = 60.0

# ---- held bodies ---------------------------------------------------------------------

BODY = 10 * MiB
SOCKETS = 250
HOLD_S = 5.0
SETTLE_S = 3.0  # after they closed: the refused sockets' drain (2 s) and the allocator
PIECE = 256 * 1024
FRAGMENT_MEMORY = 256 * MiB  # --max-fragment-memory's default
HOST_SHARE = FRAGMENT_MEMORY // 4  # rwt_transports.admission.pending.HOST_INPUT_SHARE
SLACK = 48 * MiB  # the sockets' own buffers and the allocator's (attack_kit's bounds, too)
HEAP_KEEP_MIB = 64  # --heap-keep's default (rwt_transports.process.allocator.HEAP_KEEP_MIB)
HEAD = (
    "POST /api/topics/held?type=std_msgs/msg/String HTTP/1.1\r\nHost: x\r\n"
    "Content-Type: application/json\r\nContent-Length: {length}\r\n\r\n"
)


async def _status(stream: SocketStream) -> str:
    """The status line the server answered with, or how the socket ended."""
    received = b""
    try:
        while b"\r\n" not in received:
            data = await stream.receive(4096)
            received += data
    except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
        return "closed" if not received else received.split(b"\r\n")[0].decode(errors="replace")
    return received.split(b"\r\n", 1)[0].decode(errors="replace")


async def _held_socket(port: int, answers: Counter[str], held: list[SocketStream]) -> None:
    """Post a body short of its last byte; count the answer, or keep the socket held."""
    try:
        stream = await anyio.connect_tcp("127.0.0.1", port, local_host=ATTACKER)
    except OSError as error:
        answers[f"connect failed: {error.strerror}"] += 1
        return
    answer: list[str] = []

    async def listen(scope: anyio.CancelScope) -> None:
        answer.append(await _status(stream))
        scope.cancel()

    piece = b"x" * PIECE
    async with anyio.create_task_group() as tg:
        tg.start_soon(listen, tg.cancel_scope)
        try:
            await stream.send(HEAD.format(length=BODY).encode())
            for start in range(0, BODY - 1, PIECE):
                await stream.send(piece[: min(PIECE, BODY - 1 - start)])
        except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            pass
        with anyio.move_on_after(0.5):  # an answer on its way
            await anyio.sleep_forever()
        tg.cancel_scope.cancel()
    if answer:
        answers[answer[0]] += 1
        await stream.aclose()
    else:
        answers["held (no answer)"] += 1
        held.append(stream)


async def _other_host_post(http: str) -> str:
    """A 1 MiB post from another host while the attacker holds its bodies."""
    transport = httpx.AsyncHTTPTransport(local_address=OTHER_HOST)
    async with httpx.AsyncClient(transport=transport, timeout=TIMEOUT_S) as client:
        reply = await client.post(
            f"{http}/api/topics/other?type=std_msgs/msg/String", json={"data": "y" * MiB}
        )
    return f"{reply.status_code} {reply.text[:120]}"


async def _held_bodies(
    context: Context, sockets: int = SOCKETS, heap_keep_mib: int | None = None
) -> Outcome:
    port = int(context.ws_url.rsplit(":", 1)[1])
    answers: Counter[str] = Counter()
    held: list[SocketStream] = []
    start_rss = proc_stats(context.pid).rss_bytes
    async with anyio.create_task_group() as tg:
        for _ in range(sockets):
            tg.start_soon(_held_socket, port, answers, held)
    await anyio.sleep(HOLD_S * min(1.0, context.seconds / 20))
    holding_rss = proc_stats(context.pid).rss_bytes
    other = await _other_host_post(context.http)
    for stream in held:
        await stream.aclose()
    await anyio.sleep(SETTLE_S)
    end_rss = proc_stats(context.pid).rss_bytes
    kept = (HEAP_KEEP_MIB if heap_keep_mib is None else heap_keep_mib) * MiB
    given_back = end_rss - start_rss <= kept + SLACK
    ok = other.startswith("200") and given_back
    return Outcome(
        {
            "answers": dict(answers),
            "rss_start_mb": round(start_rss / MiB, 1),
            "rss_holding_mb": round(holding_rss / MiB, 1),
            "rss_after_close_mb": round(end_rss / MiB, 1),
            "another host's 1 MiB post": other,
        },
        ok,
        "another host's post answered 200, and the RSS back within --heap-keep (the freed "
        f"heap the allocator keeps) + {SLACK // MiB} MB of its start once the sockets closed",
    )


# ---- 1-byte chunks ------------------------------------------------------------------

CHUNKERS = 4
CHUNKS = b"1\r\nx\r\n" * 16384  # 96 KiB of wire, 16 KiB of body
NEWCOMER_PERIOD_S = 0.25
TARGETS = {
    "chunks-api": (
        "POST /api/topics/chunks?type=std_msgs/msg/String HTTP/1.1\r\nHost: x\r\n"
        "Content-Type: application/json\r\n"
    ),
    "chunks-mcp": (
        "POST /mcp HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
        "Accept: application/json, text/event-stream\r\n"
    ),
    "chunks-webrtc": "POST /webrtc HTTP/1.1\r\nHost: x\r\nContent-Type: application/sdp\r\n",
}


async def _chunker(port: int, head: bytes, until: float, counts: Counter[str]) -> None:
    """Send 1-byte chunks as fast as the server reads them; start again when cut off."""
    while time.monotonic() < until:
        try:
            stream = await anyio.connect_tcp("127.0.0.1", port, local_host=ATTACKER)
        except OSError:
            counts["connect failed"] += 1
            await anyio.sleep(0.05)
            continue
        counts["requests"] += 1
        try:
            await stream.send(head + b"Transfer-Encoding: chunked\r\n\r\n")
            with anyio.move_on_after(max(0.0, until - time.monotonic())):
                while True:
                    await stream.send(CHUNKS)
                    counts["wire bytes sent"] += len(CHUNKS)
        except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            counts["cut off (refused or over the limit)"] += 1
        finally:
            await anyio.aclose_forcefully(stream)


async def _newcomers(http: str, until: float, waits: list[float], failed: Counter[str]) -> None:
    """``GET /version`` on a new connection from another host every ``NEWCOMER_PERIOD_S``."""
    transport = httpx.AsyncHTTPTransport(local_address=OTHER_HOST)
    limits = httpx.Limits(max_keepalive_connections=0)
    async with httpx.AsyncClient(transport=transport, limits=limits, timeout=TIMEOUT_S) as c:
        while time.monotonic() < until:
            began = time.monotonic()
            try:
                reply = await c.get(f"{http}/version")
                if reply.status_code == 200:
                    waits.append(time.monotonic() - began)
                else:
                    failed[str(reply.status_code)] += 1
            except httpx.HTTPError as error:
                failed[type(error).__name__] += 1
            await anyio.sleep(max(0.0, began + NEWCOMER_PERIOD_S - time.monotonic()))


async def _chunks(name: str, context: Context) -> Outcome:
    port = int(context.ws_url.rsplit(":", 1)[1])
    until = time.monotonic() + context.seconds
    counts: Counter[str] = Counter()
    waits: list[float] = []
    failed: Counter[str] = Counter()
    head = TARGETS[name].encode()
    async with anyio.create_task_group() as tg:
        for _ in range(CHUNKERS):
            tg.start_soon(_chunker, port, head, until, counts)
        tg.start_soon(_newcomers, context.http, until, waits, failed)
    ordered = sorted(waits)
    facts: dict[str, Any] = {
        **counts,
        "newcomers answered": len(waits),
        "newcomers failed": dict(failed),
    }
    if ordered:
        facts["newcomer wait p50 / max ms"] = (
            round(statistics.median(ordered) * 1000, 1),
            round(ordered[-1] * 1000, 1),
        )
    return Outcome(
        facts,
        bool(waits) and not failed,
        "every newcomer of another host answered (GET /version, 200)",
    )


def _serve_chunks(_: Path) -> list[str]:
    return ["--no-tf", "--mcp", "--webrtc"]


def _serve_held(_: Path, heap_keep_mib: int | None = None) -> list[str]:
    keep = [] if heap_keep_mib is None else ["--heap-keep", str(heap_keep_mib)]
    return ["--no-tf", *keep]


ATTACKS = [
    Attack(
        "held",
        f"{SOCKETS} sockets of one host, each a 10 MiB body short of its last byte",
        _serve_held,
        _held_bodies,
        f"{SOCKETS} sockets as the campaign (--sockets), held {HOLD_S:.0f} s",
        bound=(HOST_SHARE + SLACK, "docs/limits.md: a host's requests being read (D58)"),
        seconds=20.0,
    ),
    *(
        Attack(
            name,
            f"{CHUNKERS} sockets of one host sending 1-byte chunks to {TARGETS[name].split()[1]}",
            _serve_chunks,
            partial(_chunks, name),
            f"{CHUNKERS} sockets as the campaign, 10 s instead of 20",
            seconds=10.0,
        )
        for name in TARGETS
    ),
]


def held_attack(sockets: int = SOCKETS, heap_keep_mib: int | None = None) -> Attack:
    """The ``held`` class with ``sockets`` sockets, on ``rwt serve --heap-keep`` (MiB)."""
    (held,) = [a for a in ATTACKS if a.number == "held"]
    return replace(
        held,
        serve=partial(_serve_held, heap_keep_mib=heap_keep_mib),
        attack=partial(_held_bodies, sockets=sockets, heap_keep_mib=heap_keep_mib),
        scaled=f"{sockets} sockets (--sockets), held {HOLD_S:.0f} s",
    )


def _source() -> str:
    src = os.environ.get("RWT_BENCH_SRC")
    if not src:
        return "this checkout"
    commit = subprocess.run(
        ["git", "-C", src, "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    return f"{src} ({commit or 'not a git checkout'})"


def _row(r: Replay) -> str:
    verdict = "p99 under 150 ms" if r.attack.p99_ms < 150 else "p99 NOT under 150 ms"
    return (
        f"  {r.number:>13} rtt ms p50/p99/max {r.baseline.p50_ms:.1f}/{r.baseline.p99_ms:.1f}/"
        f"{r.baseline.max_ms:.0f} -> {r.attack.p50_ms:.1f}/{r.attack.p99_ms:.1f}/"
        f"{r.attack.max_ms:.0f} ({verdict}); cpu {r.cpu_s:.1f} s in {r.attack_s:.1f} s; "
        f"rss {r.rss_start_mb:.0f} -> peak {r.rss_peak_mb:.0f} -> end {r.rss_end_mb:.0f} MB; "
        f"{r.verdict}{' (' + '; '.join(r.reasons) + ')' if r.reasons else ''}\n"
        f"      {json.dumps(r.outcome)}"
    )


def main(argv: list[str] | None = None) -> int:
    """Replay the chosen classes (all by default); print and save the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--attack", action="append", choices=[a.number for a in ATTACKS])
    parser.add_argument("--scale", type=float, default=1.0)
    parser.add_argument("--sockets", type=int, default=SOCKETS)
    parser.add_argument(
        "--heap-keep", type=int, help="rwt serve --heap-keep (MiB) for held; its default else"
    )
    args = parser.parse_args(argv)
    chosen = [a for a in ATTACKS if args.attack is None or a.number in args.attack]
    saved: dict[str, Any] = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    runs = saved.setdefault(_source(), {})
    for attack in chosen:
        name = attack.number
        if attack.number == "held":
            attack = held_attack(args.sockets, args.heap_keep)  # noqa: PLW2901 (as asked)
            name += "" if args.heap_keep is None else f" --heap-keep {args.heap_keep}"
        load = [round(x, 1) for x in os.getloadavg()]
        result = anyio.run(partial(replay, attack, scale=args.scale))
        print(f"load average {load}\n{_row(result)}", file=sys.stderr, flush=True)
        runs[name] = {  # the latest run of each class, per source
            "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "load_average_before": load,
            "replay": asdict(result),
        }
        RESULTS.parent.mkdir(exist_ok=True)
        RESULTS.write_text(json.dumps(saved, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
