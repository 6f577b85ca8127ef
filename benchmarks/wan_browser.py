"""A 1 kHz topic to Chromium behind a WAN link: each WebRTC stack beside the WebSocket.

The browser table of docs/benchmarks.md ("Over a WAN link, a browser") and
docs/webrtc.md ("Which stack"). The robot (in-process ``RosbridgeServer``s on one
graph, one per WebRTC stack that imports here: ``STACK_PORTS``, each with its
WebSocket) publishes ``TOPIC``, a ``std_msgs/msg/Header`` at ``--rate`` Hz whose stamp
is its publish time and whose ``frame_id`` its sequence number. The browser is
Debian's headless Chromium, launched as the browser tests launch it
(tests/browser/cdp.py), running roslib 2.x from tests/js/node_modules on a page of
its own origin. The two are in network namespaces joined by benchmarks/wanlink.py
(30 ms +- 10 ms each way, 2 % loss, 15 Mbit/s by default).

For each stack (``--stack``, default: every one that imports), in turn:

- ``<stack>-reliable`` and ``<stack>-lossy``, at once, as a page with two sessions
  does it: session B subscribes on the ``rosbridge`` channel, session A on
  ``rosbridge-lossy`` (roslib's transport factory served by rwt, with
  ``lossyTopics``; docs/webrtc.md);
- ``<stack>-vp8``, beside them in the same page (unless ``--no-video``): the robot's
  30 Hz 640x480 camera (``wan_topic.CAMERA``, each picture stamped with its publish
  time, ``wan_topic.stamp_picture``) as a VP8 video track from the same server (which
  stack sends a track: docs/webrtc.md, "Which stack"), played in a ``<video>``; each
  frame Chromium presents (``requestVideoFrameCallback``) is drawn on a canvas and its
  stamp read back;
- ``websocket``: then roslib over the WebSocket of the same server, across the same
  link, in the same run.

Per row: messages delivered a second, their age at p50 and p99 (the page's clock at
arrival minus the stamp: one machine, one clock), messages missing (the sequence
numbers between the first and the last that never came), stalls (gaps between two
arrivals over ``STALL_MS``) and the longest gap, and the robot's CPU per message
delivered (its process's CPU over the row's run, divided by the messages every row of
that run delivered). The first ``--warmup`` s of each row are left out. The video row: frames
presented a second, their age at presentation (the frame's presentation time minus the
stamp in its picture), frames missing (publish slots between the first and the last
stamp that no presented frame showed) and stalls (gaps over ``STALL_MS``, 33 ms expected).

Run (root: network namespaces; Chromium installed; ``npm ci --prefix tests/js``)::

    nice -n 10 python -m benchmarks.wan_browser --duration 20 [--stack reactor ...] [--no-video]

With Python 3.12 and libdatachannel-py, the ``native`` stack's rows come too.
Results: a table on stdout and ``benchmarks/results/wan_browser.json``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import anyio

from benchmarks.wan_topic import (
    BROWSER_ADDR,
    CAMERA,
    CAMERA_HZ,
    ROBOT_ADDR,
    _camera,
    _cpu_s,
    _namespaces,
)
from benchmarks.wanlink import LinkProfile, WanLink

TOPIC = "/fast"
STACK_PORTS = {"aiortc": 9090, "native": 9091, "reactor": 9092}
"""The robot's servers, one a WebRTC stack (``--webrtc-stack``), on one graph."""
WARMUP_S = 2.0
STALL_MS = 100.0
"""A gap between two arrivals longer than this counts as a stall (1 ms is expected)."""
CONNECT_BOUND_S = 60.0

RESULTS = Path(__file__).parent / "results" / "wan_browser.json"
REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": f"{REPO / 'src'}:{REPO}", "PYTHONUNBUFFERED": "1"}

IMPORTS = {
    "roslib": "roslib/dist/RosLib.js",
    "eventemitter3": "eventemitter3/dist/eventemitter3.esm.js",
    "uuid": "uuid/dist/index.js",
    "bson": "bson/lib/bson.mjs",
    "cbor2": "cbor2/lib/index.js",
    "fast-png": "fast-png/lib/index.js",
    "fflate": "fflate/esm/browser.js",
    "iobuffer": "iobuffer/lib/iobuffer.js",
    "@cto.af/wtf8": "@cto.af/wtf8/lib/index.js",
}
"""roslib and what it imports, as an import map over tests/js/node_modules."""

PAGE_SCRIPT = """
import { Ros, Topic, AbstractTransport } from "roslib";

const now = () => performance.timeOrigin + performance.now();

async function connect(options) {
  const ros = new Ros(options);
  await new Promise((ok, fail) => {
    ros.on("connection", ok);
    ros.on("error", (e) => fail(new Error(String(e && (e.message || e.type || e)))));
  });
  return ros;
}

function record(ros, name) {
  // [arrival ms, stamp ms, sequence number] flattened: three numbers a message
  const rows = [];
  new Topic({ ros, name, messageType: "std_msgs/Header" }).subscribe((m) => {
    rows.push(now(), m.stamp.sec * 1000 + m.stamp.nanosec / 1e6, Number(m.frame_id));
  });
  return rows;
}

const sleep = (s) => new Promise((ok) => setTimeout(ok, s * 1000));

// The camera's stamp (benchmarks/wan_topic.py, stamp_picture): 40 blocks of 32 px in the
// top two rows, black 0 or white 1: the publish time in ms mod 2**32, then crc32 & 0xff.
const CRC = Array.from({ length: 256 }, (_, n) => {
  for (let k = 0; k < 8; k++) n = n & 1 ? 0xedb88320 ^ (n >>> 1) : n >>> 1;
  return n >>> 0;
});
function crc32(bytes) {
  let c = 0xffffffff;
  for (const b of bytes) c = CRC[(c ^ b) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}
function readStamp(pixels, atMs) {  // pixels: RGBA of the top 64 rows, 640 wide
  const bits = [];
  for (let i = 0; i < 40; i++) {
    const y = Math.floor(i / 20) * 32 + 16, x = (i % 20) * 32 + 16;
    let sum = 0;
    for (let dy = -8; dy < 8; dy += 4) for (let dx = -8; dx < 8; dx += 4) {
      const k = ((y + dy) * 640 + x + dx) * 4;
      sum += 0.299 * pixels[k] + 0.587 * pixels[k + 1] + 0.114 * pixels[k + 2];
    }
    bits.push(sum / 16 > 128 ? 1 : 0);
  }
  const word = (from, to) => bits.slice(from, to).reduce((v, b) => v * 2 + b, 0);
  const value = word(0, 32);
  const check = crc32([value >>> 24, (value >>> 16) & 255, (value >>> 8) & 255, value & 255]);
  if ((check & 0xff) !== word(32, 40)) return null;
  const span = 2 ** 32, now = Math.floor(atMs);
  return now - ((((now - value) % span) + span) % span);  // the stamp, ms since the epoch
}

// A VP8 track of `camera` from `base` (as a WHEP player asks), each presented frame's
// [presentation ms, stamp ms, 0] flattened into the returned rows
async function watch(base, camera) {
  const rows = [];
  const pc = new RTCPeerConnection();
  const transceiver = pc.addTransceiver("video", { direction: "recvonly" });
  transceiver.setCodecPreferences(RTCRtpReceiver.getCapabilities("video").codecs
    .filter((c) => c.mimeType === "video/VP8"));
  const video = document.createElement("video");
  Object.assign(video, { muted: true, autoplay: true, playsInline: true });
  document.body.append(video);
  const canvas = Object.assign(document.createElement("canvas"), { width: 640, height: 480 });
  const context = canvas.getContext("2d", { willReadFrequently: true });
  const presented = (_, meta) => {
    context.drawImage(video, 0, 0, 640, 480);
    const at = performance.timeOrigin + meta.presentationTime;
    const stamp = readStamp(context.getImageData(0, 0, 640, 64).data, at);
    if (stamp !== null) rows.push(at, stamp, 0);
    video.requestVideoFrameCallback(presented);
  };
  pc.ontrack = (e) => {
    video.srcObject = new MediaStream([e.track]);
    video.requestVideoFrameCallback(presented);
  };
  await pc.setLocalDescription(await pc.createOffer());
  await new Promise((done) => {
    if (pc.iceGatheringState === "complete") return done();
    pc.onicegatheringstatechange = () => pc.iceGatheringState === "complete" && done();
  });
  const reply = await fetch(base + "/webrtc?video=" + encodeURIComponent(camera), {
    method: "POST", headers: { "Content-Type": "application/sdp" }, body: pc.localDescription.sdp,
  });
  if (reply.status !== 201) throw new Error("video offer: " + reply.status);
  const answer = await reply.text();
  await pc.setRemoteDescription({ type: "answer", sdp: answer });
  const sender = (answer.match(/\\no=(\\S+)/) || [])[1];  // "rtc": libdatachannel
  let stats = null;
  const stop = async () => {  // then the receiver's counters, for the journal
    for (const report of (await pc.getStats()).values()) {
      if (report.type === "inbound-rtp" && report.kind === "video") {
        const keys = ["framesReceived", "framesDecoded", "framesDropped", "packetsLost",
          "nackCount", "pliCount", "jitterBufferDelay", "jitterBufferEmittedCount",
          "totalDecodeTime", "framesPerSecond"];
        stats = Object.fromEntries(keys.map((k) => [k, report[k]]));
      }
    }
    pc.close();
    await fetch(base + reply.headers.get("Location"), { method: "DELETE" }).catch(() => {});
  };
  return { rows, sender, stop, stats: () => stats };
}

// session A: TOPIC on rosbridge-lossy; session B: TOPIC on rosbridge; both at once, and
// the camera's VP8 track beside them (camera: null, none)
window.webrtcRun = async (base, topic, seconds, camera) => {
  const { webrtcTransportFactory } = await import(base + "/webrtc/roslib-transport.js");
  const track = camera ? await watch(base, camera) : null;
  const lossy = await connect({
    url: base,
    transportFactory: webrtcTransportFactory(AbstractTransport, { lossyTopics: [topic] }),
  });
  const reliable = await connect({
    url: base, transportFactory: webrtcTransportFactory(AbstractTransport, {}),
  });
  const rows = { lossy: record(lossy, topic), reliable: record(reliable, topic) };
  if (track) rows.vp8 = track.rows;
  await sleep(seconds);
  lossy.close();
  reliable.close();
  if (track) {
    await track.stop();
    rows.vp8_sender = track.sender;
    rows.vp8_stats = track.stats();
  }
  return rows;
};

window.websocketRun = async (url, topic, seconds) => {
  const ros = await connect({ url });
  const rows = { websocket: record(ros, topic) };
  await sleep(seconds);
  ros.close();
  return rows;
};
"""


def page_html() -> str:
    """The benchmark's page: roslib from the page's origin, the transport from the robot's."""
    imports = {name: f"/node_modules/{path}" for name, path in IMPORTS.items()}
    return (
        "<!doctype html><html><head>"
        f'<script type="importmap">{json.dumps({"imports": imports})}</script>'
        f'<script type="module">{PAGE_SCRIPT}</script>'
        "</head><body>rwt WAN benchmark</body></html>"
    )


def figures(rows: list[float], warmup_s: float, *, video: bool = False) -> dict[str, Any]:
    """One channel's figures from the page's flattened ``[arrival, stamp, seq]`` rows (ms).

    The first ``warmup_s`` s from the first arrival are left out. ``video``: the rows are
    the camera's presented frames (no sequence number): missing counts the publish
    slots (``CAMERA_HZ``) between the first and the last stamp that no frame showed.
    """
    triples = [rows[i : i + 3] for i in range(0, len(rows), 3)]
    if not triples:
        return {"received": 0}
    start = triples[0][0] + warmup_s * 1000
    kept = [t for t in triples if t[0] >= start]
    if len(kept) < 2:
        return {"received": len(kept)}
    arrivals = [t[0] for t in kept]
    ages = sorted(t[0] - t[1] for t in kept)
    if video:
        stamps = {t[1] for t in kept}
        slots = round((max(stamps) - min(stamps)) * CAMERA_HZ / 1000) + 1
        missing = max(0, slots - len(stamps))
    else:
        seqs = {int(t[2]) for t in kept}
        missing = max(seqs) - min(seqs) + 1 - len(seqs)
    span_s = (arrivals[-1] - arrivals[0]) / 1000
    gaps = [b - a for a, b in itertools.pairwise(arrivals)]
    quantiles = statistics.quantiles(ages, n=100)
    return {
        "received": len(kept),
        "window_s": round(span_s, 2),
        "delivered_hz": round((len(kept) - 1) / span_s),
        "age_p50_ms": round(quantiles[49], 1),
        "age_p99_ms": round(quantiles[98], 1),
        "missing": missing,
        "stalls": sum(gap > STALL_MS for gap in gaps),
        "longest_gap_ms": round(max(gaps), 1),
    }


# ---- the robot ------------------------------------------------------------------------


def available_stacks() -> list[str]:
    """The WebRTC stacks that import here (``webrtc.stacks.stack_refusal``)."""
    from rwt_transports.webrtc.stacks import stack_refusal  # noqa: PLC0415

    return [stack for stack in STACK_PORTS if stack_refusal(stack) is None]


async def robot(rate: float, stacks: list[str], video: bool) -> None:
    """The robot: a server a stack on ``ROBOT_ADDR`` (one graph), publishing ``TOPIC``, and
    with ``video`` the camera (``wan_topic.CAMERA``: encoded only while a track plays it)."""
    from rwt_graph.graph import Graph  # noqa: PLC0415 (the robot process only)
    from rwt_transports.server import RosbridgeServer, ServerConfig  # noqa: PLC0415
    from rwt_transports.webrtc.signalling import WebRtcOptions  # noqa: PLC0415

    logging.basicConfig(stream=sys.stderr, level=logging.WARNING)
    logging.getLogger("rwt").setLevel(logging.INFO)
    graph = Graph()
    servers = [
        RosbridgeServer(
            graph,
            ServerConfig(
                host=ROBOT_ADDR, port=STACK_PORTS[stack], webrtc=WebRtcOptions(stack=stack)
            ),
        )
        for stack in stacks
    ]
    clock = graph.create_publisher(TOPIC, "std_msgs/msg/Header", node="/robot")
    async with anyio.create_task_group() as tg:
        for server in servers:
            await tg.start(server.serve)
        if video:
            tg.start_soon(_camera, graph)
        print("robot up", flush=True)
        start = time.monotonic()
        sent = 0
        while True:  # on schedule: a late tick publishes at once, no drift
            sent += 1
            await anyio.sleep(max(0.0, start + sent / rate - time.monotonic()))
            now = time.time()
            stamp = {"sec": int(now), "nanosec": int(now % 1 * 1e9)}
            clock.publish({"stamp": stamp, "frame_id": str(sent)})


# ---- the browser ----------------------------------------------------------------------


def browser(stacks: list[str], duration: float, video: bool) -> None:
    """Chromium in this namespace: each stack's WebRTC run, then the WebSocket's.

    Prints ``start <run>`` and ``end <run>`` as each run begins and ends (the robot's
    CPU is read between them), then each run's rows as one JSON line.
    """
    from tests.browser.cdp import Browser, chromium_path  # noqa: PLC0415
    from tests.webrtc.pagesite import serve_pages  # noqa: PLC0415

    executable = chromium_path()
    if executable is None:
        raise SystemExit("chromium is not installed")
    chromium = Browser(executable, reachable=(ROBOT_ADDR,))
    try:
        with serve_pages(lambda path, _query: page_html() if path == "/" else None) as site:
            page = chromium.new_page()
            page.goto(site + "/")
            page.wait_for("typeof window.webrtcRun === 'function'", 30, "the page's script")
            for stack in [] if os.environ.get("WB_WS_ONLY") else stacks:
                base = f"http://{ROBOT_ADDR}:{STACK_PORTS[stack]}"
                camera = json.dumps(CAMERA if video else None)
                call = f"webrtcRun({json.dumps(base)}, {json.dumps(TOPIC)}, {duration}, {camera})"
                _run(page, stack, call, duration)
            ws = f"ws://{ROBOT_ADDR}:{STACK_PORTS[stacks[0]]}"
            _run(
                page,
                "websocket",
                f"websocketRun({json.dumps(ws)}, {json.dumps(TOPIC)}, {duration})",
                duration,
            )
    finally:
        chromium.close()


def _run(page: Any, name: str, call: str, duration: float) -> None:
    """One run on the page: its rows printed as JSON, between ``start`` and ``end`` lines."""
    print(f"start {name}", flush=True)
    page.evaluate(
        f"window.result = null; window.failure = null; {call}.then("
        "(r) => { window.result = r; }, (e) => { window.failure = String(e); }); 0"
    )
    deadline = time.monotonic() + duration + CONNECT_BOUND_S
    while True:
        state = page.evaluate("window.failure || (window.result ? 'done' : '')")
        if state or time.monotonic() > deadline:
            break
        time.sleep(0.5)
    print(f"end {name}", flush=True)
    if state != "done":
        print(json.dumps({"run": name, "failure": state or "timed out"}), flush=True)
        return
    rows = page.evaluate("window.result")
    print(json.dumps({"run": name, "rows": rows}), flush=True)


# ---- the orchestration ----------------------------------------------------------------


def _in(ns: str, *argv: str) -> list[str]:
    return ["ip", "netns", "exec", ns, sys.executable, "-m", "benchmarks.wan_browser", *argv]


def run(
    stacks: list[str],
    duration: float,
    rate: float,
    profile: LinkProfile,
    warmup_s: float,
    video: bool = True,
) -> list[dict[str, Any]]:
    """Namespaces, the link, the robot, then Chromium's runs: the rows of the table."""
    robot_ns, browser_ns = f"wbrobot{os.getpid()}", f"wbbrowser{os.getpid()}"
    rows: list[dict[str, Any]] = []
    with _namespaces(robot_ns, browser_ns):
        link = WanLink(browser_ns, BROWSER_ADDR, robot_ns, ROBOT_ADDR, profile, seed=1)
        link.start()
        log = Path(tempfile.mkdtemp(prefix="wan_browser")) / "robot.log"
        print(f"robot log: {log}", flush=True)
        stack_args = [arg for stack in stacks for arg in ("--stack", stack)]
        stack_args += [] if video else ["--no-video"]
        with log.open("w") as robot_log:
            server = subprocess.Popen(
                _in(robot_ns, "robot", "--rate", str(rate), *stack_args),
                env=ENV,
                stdout=subprocess.PIPE,
                stderr=robot_log,
                text=True,
            )
        try:
            assert server.stdout is not None
            assert server.stdout.readline().strip() == "robot up"
            rows = _drive(
                _in(browser_ns, "browser", "--duration", str(duration), *stack_args),
                server.pid,
                warmup_s,
            )
        finally:
            server.terminate()
            server.wait(10)
            if server.stdout is not None:
                server.stdout.close()
            link.stop()
    print(f"link robot->browser {link.b_to_a.stats}, browser->robot {link.a_to_b.stats}")
    return rows


def _drive(argv: list[str], robot_pid: int, warmup_s: float) -> list[dict[str, Any]]:
    """Run the browser's process; read the robot's CPU at each run's start and end."""
    rows: list[dict[str, Any]] = []
    cpu: dict[str, float] = {}
    with subprocess.Popen(argv, env=ENV, stdout=subprocess.PIPE, text=True) as driver:
        assert driver.stdout is not None
        for line in driver.stdout:
            word, _, rest = line.strip().partition(" ")
            if word == "start":
                cpu[rest] = -_cpu_s(robot_pid)
                cpu[rest + "@"] = -time.monotonic()
            elif word == "end":
                cpu[rest] += _cpu_s(robot_pid)
                cpu[rest + "@"] += time.monotonic()
            elif line.startswith("{"):
                rows += _rows_of(json.loads(line), cpu, warmup_s)
    return rows


def _rows_of(
    result: dict[str, Any], cpu: dict[str, float], warmup_s: float
) -> list[dict[str, Any]]:
    """One run's rows of the table: each channel's figures, the robot's CPU beside them.

    CPU a message: the robot's CPU over the whole run (warm-up and, with the camera, its
    encoding included) divided by every topic message the run delivered.
    """
    name = result["run"]
    if "failure" in result:
        return [{"transport": name, "failure": result["failure"]}]
    runs = result["rows"]
    sender = runs.pop("vp8_sender", None)  # the o= of the track's answer: "rtc", libdatachannel
    receiver = runs.pop("vp8_stats", None)  # Chromium's inbound-rtp counters of the track
    channels = {key: figures(value, warmup_s, video=key == "vp8") for key, value in runs.items()}
    delivered = sum(c.get("received", 0) for key, c in channels.items() if key != "vp8")
    total = sum(len(value) // 3 for key, value in runs.items() if key != "vp8")
    rows = []
    for key, figs in channels.items():
        figs["transport"] = name if key == "websocket" else f"{name}-{key}"
        if key == "vp8":
            figs["track_sender"] = "native" if sender == "rtc" else "aiortc"
            figs["receiver_stats"] = receiver
        figs["robot_cpu_pct"] = round(100 * cpu[name] / cpu[name + "@"])
        figs["robot_cpu_us_per_msg"] = round(cpu[name] / max(total, 1) * 1e6)
        figs["messages_in_run"] = delivered
        rows.append(figs)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("role", nargs="?", default="run", choices=["run", "robot", "browser"])
    parser.add_argument("--stack", action="append", choices=list(STACK_PORTS))
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--warmup", type=float, default=WARMUP_S)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--delay-ms", type=float, default=30.0)
    parser.add_argument("--jitter-ms", type=float, default=10.0)
    parser.add_argument("--loss", type=float, default=0.02)
    parser.add_argument("--rate-mbit", type=float, default=15.0)
    parser.add_argument(
        "--no-video", action="store_true", help="without the camera's VP8 track beside the topic"
    )
    args = parser.parse_args()
    stacks = args.stack or available_stacks()
    if args.role == "robot":
        anyio.run(robot, args.rate, stacks, not args.no_video)
        return
    if args.role == "browser":
        browser(stacks, args.duration, not args.no_video)
        return
    missing = [s for s in stacks if s not in available_stacks()]
    if missing:
        raise SystemExit(f"these stacks do not import here: {', '.join(missing)}")
    profile = LinkProfile(
        args.delay_ms / 1000, args.jitter_ms / 1000, args.loss, args.rate_mbit * 1e6
    )
    load = os.getloadavg()[0]
    rows = run(stacks, args.duration, args.rate, profile, args.warmup, not args.no_video)
    link = (
        f"{args.delay_ms:g} ms +- {args.jitter_ms:g} ms, {args.loss:.0%} loss,"
        f" {args.rate_mbit:g} Mbit/s"
    )
    print(
        f"WAN link each way: {link}; {args.rate:g} Hz std_msgs/Header to Chromium"
        f"{'' if args.no_video else ', a 30 Hz VP8 track beside it'};"
        f" load average {load:.2f} at the start, {os.getloadavg()[0]:.2f} at the end"
    )
    print(
        "| transport | delivered a second | age p50 | age p99 | missing | stalls (longest gap)"
        " | robot CPU | robot CPU a message |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        if "failure" in row:
            print(f"| {row['transport']} | failed: {row['failure']} |||||||")
            continue
        sender = f" (sent by {row['track_sender']})" if "track_sender" in row else ""
        print(
            f"| {row['transport']}{sender} | {row.get('delivered_hz')} | {row.get('age_p50_ms')} ms"
            f" | {row.get('age_p99_ms')} ms | {row.get('missing')} | {row.get('stalls')}"
            f" ({row.get('longest_gap_ms')} ms) | {row.get('robot_cpu_pct')} %"
            f" | {row.get('robot_cpu_us_per_msg')} us |"
        )
    for row in rows:
        stats = row.get("receiver_stats")
        if stats and stats.get("jitterBufferEmittedCount"):
            buffered_ms = 1000 * stats["jitterBufferDelay"] / stats["jitterBufferEmittedCount"]
            print(
                f"{row['transport']}: Chromium received {stats['framesReceived']} frames,"
                f" decoded {stats['framesDecoded']}, dropped {stats['framesDropped']};"
                f" {stats['nackCount']} NACKs; jitter buffer {buffered_ms:.0f} ms a frame"
            )
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(
        json.dumps(
            {
                "link": link,
                "rate_hz": args.rate,
                "video": not args.no_video,
                "load": load,
                "load_end": os.getloadavg()[0],
                "rows": rows,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
