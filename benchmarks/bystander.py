"""A rosbridge (or Foxglove) WebSocket client timing one round trip every 50 ms, in a process.

``python -m benchmarks.bystander URL [--host 127.0.0.2] [--secret S] [--foxglove]``
connects to ``URL`` from ``--host`` (another host than the attackers' 127.0.0.1),
authenticates with rosauth when given the server's secret, then calls
``/rosapi/get_time`` (``--foxglove``: a Foxglove client's ``getParameters``, answered
by ``parameterValues`` with its id) one call at a time, a call due every ``PERIOD_S``
(a late answer delays the next call; a missed period is not made up). Each answer is a
line on stdout: the call's send time and its round trip, both in seconds, the send time
on the system's monotonic clock (``time.monotonic``, the same in every process of the
machine), so the parent splits the round trips by the phases it timed. ``ready`` is
printed once connected; a call still unanswered when the process is told to stop
(SIGTERM) is printed with the time it waited so far and ``open`` (its round trip is at
least that).

Used by ``benchmarks/attacks.py`` and ``benchmarks/mcp_flood.py``; it never imports rwt, so
any server's version works.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import hashlib
import json
import math
import signal
import sys
import time

from websockets.asyncio.client import connect
from websockets.typing import Subprotocol

__all__ = ["PERIOD_S", "auth_op", "main"]

PERIOD_S = 0.05
"""Seconds between the starts of two calls."""
SERVICE = "/rosapi/get_time"
FOXGLOVE = "foxglove.websocket.v1"
"""The subprotocol of a ``--foxglove`` bystander (Foxglove's WebSocket protocol)."""


def auth_op(secret: str, client: str, dest: str, rand: str) -> dict[str, object]:
    """A rosauth ``auth`` op (MAC: SHA-512 of the fields, times in whole seconds), valid 1 h."""
    t, end = math.floor(time.time()) - 1, math.floor(time.time()) + 3600
    text = f"{secret}{client}{dest}{rand}{t}user{end}"
    mac = hashlib.sha512(text.encode()).hexdigest()
    return {
        "op": "auth",
        "mac": mac,
        "client": client,
        "dest": dest,
        "rand": rand,
        "t": t,
        "level": "user",
        "end": end,
    }


async def _run(url: str, host: str, secret: str | None, foxglove: bool = False) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    protocols = [Subprotocol(FOXGLOVE)] if foxglove else None
    async with connect(
        url, local_addr=(host, 0), open_timeout=60, max_size=None, subprotocols=protocols
    ) as ws:
        if secret is not None:
            await ws.send(json.dumps(auth_op(secret, host, "127.0.0.1", "bystander")))
        print("ready", flush=True)
        due = time.monotonic()
        n = 0
        while not stop.is_set():
            n += 1
            sent = time.monotonic()
            call: dict[str, object] = {"op": "call_service", "service": SERVICE, "id": f"b{n}"}
            if foxglove:
                call = {"op": "getParameters", "parameterNames": [], "id": f"b{n}"}
            await ws.send(json.dumps(call))
            answer = asyncio.ensure_future(_answer(ws, f"b{n}"))
            halt = asyncio.ensure_future(stop.wait())
            await asyncio.wait({answer, halt}, return_when=asyncio.FIRST_COMPLETED)
            if not answer.done():
                answer.cancel()
                print(f"{sent:.6f} {time.monotonic() - sent:.6f} open", flush=True)
                return
            halt.cancel()
            print(f"{sent:.6f} {time.monotonic() - sent:.6f}", flush=True)
            due = max(due + PERIOD_S, time.monotonic())
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), due - time.monotonic())


async def _answer(ws: object, call_id: str) -> None:
    while True:
        frame = await ws.recv()  # type: ignore[attr-defined]
        if isinstance(frame, str) and f'"{call_id}"' in frame:  # Foxglove's binary: not it
            return


def main(argv: list[str] | None = None) -> int:
    """Run until SIGTERM; round trips on stdout (see the module's docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url")
    parser.add_argument("--host", default="127.0.0.2")
    parser.add_argument("--secret")
    parser.add_argument("--foxglove", action="store_true")
    args = parser.parse_args(argv)
    try:
        asyncio.run(_run(args.url, args.host, args.secret, args.foxglove))
    except (OSError, EOFError) as error:
        print(f"error {error}", file=sys.stderr, flush=True)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
