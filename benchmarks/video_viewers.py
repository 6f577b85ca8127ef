"""Many MJPEG viewers of a 4K camera, and a rosbridge client's round trips meanwhile.

A server process (``python -m benchmarks.video_viewers robot``: an embedded rwt with
its video server, a 3840x2160 ``rgb8`` camera at ``--hz``, the paper's synthetic scene
scaled up) is watched by ``--viewers`` MJPEG viewers (raw sockets, in a process of
their own, reading as fast as they can) while a bystander, a rosbridge WebSocket client,
publishes ``std_msgs/String`` on ``/echo`` and waits for its own message back, again
and again (one round trip at a time, 10 ms apart). Three cases:

- ``idle``: no viewer, the reference;
- ``one stream``: every viewer asks for the same stream (quality 95), one encoder;
- ``N streams``: each viewer its own quality (80, 81, ...), N encoders.

Reported per case: the bystander's round trip p50 and p99 (ms), the frames a second
each viewer got (median over viewers), and the server's CPU (% of a core). With
``--base REF`` the same cases run against ``rwt`` from a detached worktree of ``REF``
(``base``) and from this checkout (``rwt``), alternating server by server in each
round, so both see the same machine state; the table gives the medians over rounds and
rwt/base. Results: ``results/video_viewers.json``.

Run: ``python -m benchmarks.video_viewers --base main [--runs 3] [--seconds 8]``
(``--smoke``: a 640x480 camera, 3 viewers, 2 s a case, this checkout only).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from websockets.asyncio.client import connect

from .servers import ROOT, proc_stats, rwt_pythonpath

__all__ = ["CaseResult", "main", "measure", "run_case"]

RESULTS = Path(__file__).resolve().parent / "results" / "video_viewers.json"
CAMERA = "/bench/camera4k"
BOUNDARY = b"--boundarydonotcross"
ROUND_TRIP_GAP_S = 0.01
SETTLE_S = 2.0
"""Seconds the viewers watch before the bystander starts: every stream has started."""


@dataclass
class CaseResult:
    """One case on one server: the bystander's round trips, the viewers' frames, the CPU."""

    server: str
    case: str
    round_trips: int
    p50_ms: float
    p99_ms: float
    frames_per_s: float
    cpu_percent: float


# ---- the robot (the server process) ------------------------------------------------


async def _robot(width: int, height: int, hz: float) -> None:
    import anyio  # noqa: PLC0415  (the robot's imports come from the src under test)
    import numpy as np  # noqa: PLC0415
    from PIL import Image  # noqa: PLC0415

    from rwt import Graph, RosbridgeServer, ServerConfig  # noqa: PLC0415
    from rwt_graph.media import array_to_image  # noqa: PLC0415
    from rwt_video import VideoConfig, serve_video  # noqa: PLC0415

    from .paper.video import camera_frames  # noqa: PLC0415

    frames = [
        array_to_image(
            np.asarray(Image.fromarray(f).resize((width, height), Image.Resampling.BILINEAR)),
            "rgb8",
        )
        for f in camera_frames(4)
    ]
    graph = Graph()
    server = RosbridgeServer(graph, ServerConfig(host="127.0.0.1", port=0))
    publisher = graph.create_publisher(CAMERA, "sensor_msgs/msg/Image")

    async def camera() -> None:
        due, index = time.monotonic(), 0
        while True:
            publisher.publish(frames[index % len(frames)])
            index += 1
            due = max(due + 1 / hz, time.monotonic())  # a late frame is not made up
            await anyio.sleep(max(0.0, due - time.monotonic()))

    async with anyio.create_task_group() as tg:
        video = await tg.start(serve_video, graph, VideoConfig(port=0))
        tg.start_soon(camera)
        url = await tg.start(server.serve)
        print(f"listening on {url}\nvideo on {video}", flush=True)
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                tg.cancel_scope.cancel()
                return


# ---- the viewers (a process of their own) -------------------------------------------


def _viewers(port: int, count: int, distinct: bool, seconds: float) -> None:
    """Watch ``count`` streams for ``seconds``; print the parts each got as JSON."""
    got = [0] * count
    stop = threading.Event()

    def watch(index: int) -> None:
        quality = 80 + index if distinct else 95
        query = f"topic={CAMERA}&type=mjpeg&quality={quality}"
        with socket.create_connection(("127.0.0.1", port)) as sock:
            sock.sendall(f"GET /stream?{query} HTTP/1.0\r\n\r\n".encode())
            sock.settimeout(1.0)
            tail = b""
            while not stop.is_set():
                try:
                    data = sock.recv(1 << 20)
                except TimeoutError:
                    continue
                if not data:
                    return
                got[index] += (tail + data).count(BOUNDARY)
                tail = data[-len(BOUNDARY) :]  # a boundary cut between two reads

    threads = [threading.Thread(target=watch, args=(i,), daemon=True) for i in range(count)]
    for thread in threads:
        thread.start()
    time.sleep(seconds)
    stop.set()
    for thread in threads:
        thread.join(5)
    print(json.dumps(got), flush=True)


# ---- one case ---------------------------------------------------------------------


async def _round_trips(url: str, seconds: float) -> list[float]:
    """The bystander: publish on /echo, wait for its own message back; the round trips, s."""
    times: list[float] = []
    async with connect(url, max_size=None) as ws:
        for op in ("advertise", "subscribe"):
            await ws.send(json.dumps({"op": op, "topic": "/echo", "type": "std_msgs/msg/String"}))
        await asyncio.sleep(0.2)
        end = time.monotonic() + seconds
        index = 0
        while time.monotonic() < end:
            text = f"ping {index}"
            start = time.monotonic()
            await ws.send(json.dumps({"op": "publish", "topic": "/echo", "msg": {"data": text}}))
            while True:
                message = json.loads(await ws.recv())
                if message.get("op") == "publish" and message["msg"]["data"] == text:
                    break
            times.append(time.monotonic() - start)
            index += 1
            await asyncio.sleep(ROUND_TRIP_GAP_S)
    return times


def _percentile(values: list[float], fraction: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(len(ordered) * fraction))]


def _start_robot(src: Path | None, width: int, height: int, hz: float) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "benchmarks.video_viewers", "robot"]
    command += ["--width", str(width), "--height", str(height), "--hz", str(hz)]
    env = dict(os.environ, PYTHONPATH=rwt_pythonpath(src))
    return subprocess.Popen(command, stdout=subprocess.PIPE, env=env, text=True, cwd=ROOT)


def run_case(
    server: str,
    src: Path | None,
    case: str,
    viewers: int,
    seconds: float,
    camera: tuple[int, int, float],
) -> CaseResult:
    """One case on a fresh robot from ``src`` (None: this checkout).

    Args:
        server: the name the results give it (``base``, ``rwt``).
        src: the ``src`` folder the robot runs from.
        case: ``idle``, ``one stream`` (every viewer the same quality), or another
            name (each viewer its own quality).
        viewers: how many watch.
        seconds: how long the bystander makes round trips.
        camera: width, height (pixels) and frames a second of the robot's camera.
    """
    robot = _start_robot(src, *camera)
    watching: subprocess.Popen[str] | None = None
    try:
        assert robot.stdout is not None
        url = robot.stdout.readline().split()[-1]
        video_port = int(robot.stdout.readline().strip().rsplit(":", 1)[1])
        if viewers:
            distinct = case != "one stream"
            command = [sys.executable, "-m", "benchmarks.video_viewers", "viewers"]
            command += [str(video_port), str(viewers), str(int(distinct))]
            command += [str(SETTLE_S + seconds + 1.0)]
            watching = subprocess.Popen(command, stdout=subprocess.PIPE, text=True, cwd=ROOT)
        time.sleep(SETTLE_S)
        cpu_before, started = proc_stats(robot.pid).cpu_s, time.monotonic()
        times = asyncio.run(_round_trips(url, seconds))
        cpu = (proc_stats(robot.pid).cpu_s - cpu_before) / (time.monotonic() - started)
        frames = 0.0
        if watching is not None:
            out, _ = watching.communicate(timeout=seconds + 30)
            counts = json.loads(out.strip().splitlines()[-1])
            parts = [max(0, count - 1) for count in counts]  # the first boundary opens
            frames = statistics.median(parts) / (SETTLE_S + seconds + 1.0)
    finally:
        if watching is not None and watching.poll() is None:
            watching.kill()
            watching.communicate()
        robot.send_signal(signal.SIGTERM)
        try:
            robot.wait(10)
        except subprocess.TimeoutExpired:
            robot.kill()
            robot.wait(5)
        if robot.stdout is not None:
            robot.stdout.close()
    return CaseResult(
        server,
        case,
        len(times),
        _percentile(times, 0.5) * 1e3,
        _percentile(times, 0.99) * 1e3,
        frames,
        cpu * 100,
    )


# ---- the run ----------------------------------------------------------------------


def _worktree(ref: str, where: Path) -> str:
    sha = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--verify", f"{ref}^{{commit}}"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(where), sha], check=True
    )
    return sha


def _table(results: list[CaseResult], servers: list[str], cases: list[str]) -> str:
    def median(server: str, case: str, field: str) -> float:
        values = [getattr(r, field) for r in results if (r.server, r.case) == (server, case)]
        return statistics.median(values)

    head = "| case | figure | " + " | ".join(servers)
    head += " | rwt/base |" if len(servers) == 2 else " |"
    lines = [head, "|---" * (len(servers) + 2 + (len(servers) == 2)) + "|"]
    for case in cases:
        for field, label in (
            ("p50_ms", "bystander round trip p50 ms"),
            ("p99_ms", "bystander round trip p99 ms"),
            ("frames_per_s", "frames/s per viewer (median)"),
            ("cpu_percent", "server CPU %"),
        ):
            values = [median(server, case, field) for server in servers]
            cells = " | ".join(f"{v:.1f}" for v in values)
            ratio = ""
            if len(servers) == 2:
                ratio = f" | {values[1] / values[0]:.2f}" if values[0] else " | -"
            lines.append(f"| {case} | {label} | {cells}{ratio} |")
    return "\n".join(lines)


def measure(
    sources: list[tuple[str, Path | None]],
    cases: list[tuple[str, int]],
    *,
    runs: int,
    seconds: float,
    camera: tuple[int, int, float],
) -> list[CaseResult]:
    """Every case on every server (``(name, src)``; src None: this checkout), ``runs`` rounds.

    In each round each case runs on every server in turn, the order reversed every
    other round, so the servers share the machine's state.
    """
    results: list[CaseResult] = []
    for run in range(runs):
        for case, count in cases:
            for server, src in sources if run % 2 == 0 else sources[::-1]:
                result = run_case(server, src, case, count, seconds, camera)
                print(asdict(result), file=sys.stderr, flush=True)
                results.append(result)
    return results


def _measure(args: argparse.Namespace) -> int:
    camera = (640, 480, args.hz) if args.smoke else (args.width, args.height, args.hz)
    viewers, seconds = (3, 2.0) if args.smoke else (args.viewers, args.seconds)
    cases = [("idle", 0), ("one stream", viewers), (f"{viewers} streams", viewers)]
    runs = 1 if args.smoke else args.runs
    with tempfile.TemporaryDirectory(prefix="rwt-video-base-") as tmp:
        where = Path(tmp) / "base"
        sources: list[tuple[str, Path | None]] = [("rwt", None)]
        base_sha = None
        if args.base and not args.smoke:
            base_sha = _worktree(args.base, where)
            sources.insert(0, ("base", where / "src"))
        try:
            results = measure(sources, cases, runs=runs, seconds=seconds, camera=camera)
        finally:
            if base_sha is not None:
                remove = ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(where)]
                subprocess.run(remove, check=False)
    print(_table(results, [name for name, _ in sources], [case for case, _ in cases]))
    if not args.smoke:
        RESULTS.parent.mkdir(exist_ok=True)
        record = {"base": base_sha, "camera": camera, "viewers": viewers, "seconds": seconds}
        RESULTS.write_text(json.dumps({**record, "runs": [asdict(r) for r in results]}, indent=1))
    return 0


def main(argv: list[str] | None = None) -> int:
    """``robot`` and ``viewers`` are the two helper processes; otherwise measure."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["robot"]:
        robot = argparse.ArgumentParser()
        for name, default in (("--width", 3840), ("--height", 2160)):
            robot.add_argument(name, type=int, default=default)
        robot.add_argument("--hz", type=float, default=15.0)
        opts = robot.parse_args(argv[1:])
        import anyio  # noqa: PLC0415

        anyio.run(_robot, opts.width, opts.height, opts.hz)
        return 0
    if argv[:1] == ["viewers"]:
        port, count, distinct, seconds = argv[1:5]
        _viewers(int(port), int(count), distinct == "1", float(seconds))
        return 0
    parser = argparse.ArgumentParser(prog="python -m benchmarks.video_viewers", description=__doc__)
    parser.add_argument("--base", help="also measure this commit (a detached worktree)")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=8.0, help="round trips per case")
    parser.add_argument("--viewers", type=int, default=16)
    parser.add_argument("--width", type=int, default=3840)
    parser.add_argument("--height", type=int, default=2160)
    parser.add_argument("--hz", type=float, default=15.0, help="camera frames per second")
    parser.add_argument("--smoke", action="store_true")
    return _measure(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
