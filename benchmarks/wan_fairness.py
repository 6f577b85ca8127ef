"""A data channel beside a TCP download through a 2 Mbit/s bottleneck: does TCP keep its share?

The reactor stack tunes dcsctp's congestion control (``webrtc.reactor.SCTP_TUNING``:
a window never below 16 packets after a loss, D70). A floor that does not back off
could starve a TCP flow on a narrow link. Here the robot sends two bulk flows to
the browser through benchmarks/wanlink.py's link (2 Mbit/s, 30 ms each way, no
random loss: losses come from its drop-tail queue, ``queue_s``):

- a TCP download (the robot writes as fast as the socket takes, the browser reads);
- a reliable data channel, the robot's side on ``--stack`` (``reactor``: the tuned
  factory; ``reactor-untuned``: libwebrtc's defaults; ``aiortc``), the browser's an
  aiortc peer reading it; the robot keeps 256 KiB buffered at most.

Three phases of ``--seconds`` each: TCP alone, the data channel alone, both at once.
Per phase, each flow's goodput (kbit/s, bytes read by the browser), and in the last
TCP's share of what both got. Run (root)::

    python -m benchmarks.wan_fairness [--stack reactor] [--seconds 15]

Results: stdout and ``benchmarks/results/wan_fairness.json``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from benchmarks.wan_topic import BROWSER_ADDR, ROBOT_ADDR, _namespaces
from benchmarks.wanlink import LinkProfile, WanLink

TCP_PORT = 9500
CHUNK = 16 * 1024
HIGH_WATER = 256 * 1024
RESULTS = Path(__file__).parent / "results" / "wan_fairness.json"
REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": f"{REPO / 'src'}:{REPO}", "PYTHONUNBUFFERED": "1"}


# ---- the robot: a TCP sender and a data channel sender ---------------------------------


def _tcp_sender(gate: threading.Event) -> None:
    """Accept one download; send while ``gate`` is set (the phases that have TCP)."""
    server = socket.create_server((ROBOT_ADDR, TCP_PORT))
    conn, _ = server.accept()
    block = b"t" * CHUNK
    while True:
        gate.wait()
        conn.sendall(block)


async def _dc_sender(stack: str, offer: str, gate: threading.Event) -> str:
    """Answer ``offer`` on ``stack``; send on its first channel while ``gate`` is set."""
    block = b"d" * CHUNK
    if stack == "aiortc":
        from aiortc import RTCPeerConnection, RTCSessionDescription  # noqa: PLC0415

        pc = RTCPeerConnection()

        def on_channel(channel: Any) -> None:
            pump = _pump(gate, lambda: channel.bufferedAmount, channel.send, block)
            _KEEP.append(asyncio.ensure_future(pump))

        pc.on("datachannel", on_channel)
        await pc.setRemoteDescription(RTCSessionDescription(offer, "offer"))
        await pc.setLocalDescription(await pc.createAnswer())
        _KEEP.append(pc)
        return str(pc.localDescription.sdp)
    import reactor_webrtc as rw  # noqa: PLC0415

    from rwt_transports.webrtc.reactor import SCTP_TUNING, add_candidates  # noqa: PLC0415

    builder = rw.PeerConnectionFactoryBuilder()
    if stack == "reactor":
        builder.with_sctp_tuning(**SCTP_TUNING)
    factory = builder.build()
    loop = asyncio.get_running_loop()
    candidates: list[tuple[str | None, str]] = []
    gathered = asyncio.Event()
    observer = rw.PeerConnectionObserver()
    observer.on_ice_candidate = lambda c: candidates.append((c.sdp_mid, c.candidate))
    observer.on_ice_gathering_change = lambda s: (
        loop.call_soon_threadsafe(gathered.set) if str(s).endswith("Complete") else None
    )

    def on_channel(channel: Any) -> None:
        _KEEP.append(channel)
        send = lambda data: channel.send(data, True)  # noqa: E731
        loop.call_soon_threadsafe(
            lambda: _KEEP.append(
                asyncio.ensure_future(_pump(gate, channel.buffered_amount, send, block))
            )
        )

    observer.on_data_channel = on_channel
    pc = factory.create_peer_connection(rw.RtcConfiguration(frame_metadata=False), observer)
    await pc.set_remote_description(rw.SessionDescription("offer", offer))
    answer = await pc.create_answer()
    await pc.set_local_description(answer)
    await asyncio.wait_for(gathered.wait(), 5)
    _KEEP.extend([factory, pc])
    return add_candidates(str(answer.sdp), candidates)


_KEEP: list[Any] = []


async def _pump(gate: threading.Event, buffered: Any, send: Any, block: bytes) -> None:
    while True:
        if gate.is_set() and buffered() < HIGH_WATER:
            try:
                send(block)
            except Exception:  # not open yet
                await asyncio.sleep(0.01)
                continue
        else:
            await asyncio.sleep(0.002)
        await asyncio.sleep(0)


async def robot(stack: str) -> None:
    """Read the offer on stdin, print the answer, then gate the flows by stdin commands."""
    tcp, dc = threading.Event(), threading.Event()
    threading.Thread(target=_tcp_sender, args=(tcp,), daemon=True).start()
    loop = asyncio.get_running_loop()
    offer = json.loads(await loop.run_in_executor(None, sys.stdin.readline))
    print(json.dumps(await _dc_sender(stack, offer, dc)), flush=True)
    while line := await loop.run_in_executor(None, sys.stdin.readline):
        flows = line.split()
        for name, gate in (("tcp", tcp), ("dc", dc)):
            gate.set() if name in flows else gate.clear()


# ---- the browser: a TCP reader and an aiortc data channel reader ----------------------


async def browser() -> None:
    """Print an offer; read the answer; count bytes of both flows; print them on request."""
    from aiortc import RTCPeerConnection, RTCSessionDescription  # noqa: PLC0415

    counts = {"tcp": 0, "dc": 0}
    pc = RTCPeerConnection()
    channel = pc.createDataChannel("bulk")
    channel.on("message", lambda m: counts.__setitem__("dc", counts["dc"] + len(m)))
    await pc.setLocalDescription(await pc.createOffer())
    print(json.dumps(pc.localDescription.sdp), flush=True)
    loop = asyncio.get_running_loop()
    answer = json.loads(await loop.run_in_executor(None, sys.stdin.readline))
    await pc.setRemoteDescription(RTCSessionDescription(answer, "answer"))
    reader, _ = await asyncio.open_connection(ROBOT_ADDR, TCP_PORT)

    async def read_tcp() -> None:
        while data := await reader.read(65536):
            counts["tcp"] += len(data)

    task = asyncio.ensure_future(read_tcp())
    while await loop.run_in_executor(None, sys.stdin.readline):
        print(json.dumps(counts), flush=True)
    task.cancel()


# ---- the orchestration ----------------------------------------------------------------


def run(stack: str, seconds: float, profile: LinkProfile) -> list[dict[str, Any]]:
    """The three phases through the link: each flow's goodput, kbit/s."""
    robot_ns, browser_ns = f"wfrobot{os.getpid()}", f"wfbrowser{os.getpid()}"
    phases = [("tcp alone", "tcp"), ("data channel alone", "dc"), ("both", "tcp dc")]
    rows = []
    with _namespaces(robot_ns, browser_ns):
        link = WanLink(browser_ns, BROWSER_ADDR, robot_ns, ROBOT_ADDR, profile, seed=1)
        link.start()
        me = [sys.executable, "-m", "benchmarks.wan_fairness"]
        pipes = {"stdin": subprocess.PIPE, "stdout": subprocess.PIPE, "text": True, "env": ENV}
        robot_p = subprocess.Popen(["ip", "netns", "exec", robot_ns, *me, "robot", stack], **pipes)  # type: ignore[call-overload]
        browser_p = subprocess.Popen(["ip", "netns", "exec", browser_ns, *me, "browser"], **pipes)  # type: ignore[call-overload]
        try:
            robot_p.stdin.write(browser_p.stdout.readline())
            robot_p.stdin.flush()
            browser_p.stdin.write(robot_p.stdout.readline())
            browser_p.stdin.flush()
            time.sleep(3)  # connected, the TCP download accepted
            for name, flows in phases:
                robot_p.stdin.write(flows + "\n")
                robot_p.stdin.flush()
                time.sleep(2)  # settled
                browser_p.stdin.write("\n")
                browser_p.stdin.flush()
                before = json.loads(browser_p.stdout.readline())
                time.sleep(seconds)
                browser_p.stdin.write("\n")
                browser_p.stdin.flush()
                after = json.loads(browser_p.stdout.readline())
                kbps = {k: round((after[k] - before[k]) * 8 / seconds / 1000) for k in after}
                rows.append({"phase": name, "tcp_kbit_s": kbps["tcp"], "dc_kbit_s": kbps["dc"]})
                robot_p.stdin.write("\n")
                robot_p.stdin.flush()
                time.sleep(2)  # drained
        finally:
            for process in (robot_p, browser_p):
                process.kill()
                process.wait(10)
            link.stop()
    both = rows[-1]
    total = both["tcp_kbit_s"] + both["dc_kbit_s"]
    both["tcp_share"] = round(both["tcp_kbit_s"] / total, 2) if total else None
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("role", nargs="?", default="run", choices=["run", "robot", "browser"])
    parser.add_argument("stack_name", nargs="?", default="reactor")
    parser.add_argument(
        "--stack", default="reactor", choices=["reactor", "reactor-untuned", "aiortc"]
    )
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--rate-mbit", type=float, default=2.0)
    parser.add_argument("--delay-ms", type=float, default=30.0)
    args = parser.parse_args()
    if args.role == "robot":
        asyncio.run(robot(args.stack_name))
        return
    if args.role == "browser":
        asyncio.run(browser())
        return
    profile = LinkProfile(args.delay_ms / 1000, 0.0, 0.0, args.rate_mbit * 1e6)
    load = os.getloadavg()[0]
    rows = run(args.stack, args.seconds, profile)
    print(
        f"{args.rate_mbit:g} Mbit/s bottleneck, {args.delay_ms:g} ms each way; data channel on"
        f" {args.stack}; load average {load:.2f}"
    )
    print("| phase | TCP kbit/s | data channel kbit/s | TCP's share |")
    print("|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['phase']} | {row['tcp_kbit_s']} | {row['dc_kbit_s']}"
            f" | {row.get('tcp_share', '')} |"
        )
    RESULTS.parent.mkdir(exist_ok=True)
    saved = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    saved[args.stack] = {"rate_mbit": args.rate_mbit, "load": load, "rows": rows}
    RESULTS.write_text(json.dumps(saved, indent=1))


if __name__ == "__main__":
    main()
