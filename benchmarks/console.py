"""``python -m benchmarks console``: the web console under load, in headless Chromium over CDP.

Against ``benchmarks/console_robot.py`` (a 640x480 camera at 30 Hz, 500 idle
topics), with Debian's ``chromium`` driven by ``tests/browser/cdp.py``:

- **list**: the page lists every topic; a MutationObserver on the topics table
  counts the rows a refresh touches when nothing changed (two refreshes) and when
  one topic is added (target: that row only);
- **echo**: the camera topic is echoed; meanwhile a real mouse event is
  dispatched over CDP every 50-150 ms (``Input.dispatchMouseEvent``) and the page
  notes, for each, the time from the event's timestamp to the next animation
  frame after its handler ran: input latency p50/p99 (target p99 <= 100 ms);
  Chromium's CPU share (all its processes, from /proc; target <= 50 % of a core),
  the echo's renders per second (MutationObserver; target <= 10) and the server's
  CPU share;
- **mjpeg** and **vp8**: the Images tab shows the camera as MJPEG, then VP8; the
  server's and Chromium's CPU share, and the frames a second reaching the page
  (MJPEG: parts of the same stream read by ``fetch`` in the page, which shares the
  server's encoder; VP8: frames the ``<video>`` presented, from
  ``getVideoPlaybackQuality``).

Prints a table and writes ``benchmarks/results/console.json``; ``--quick`` (the
smoke test) runs each phase briefly on 50 topics. Figures depend on the machine's
load: note it with the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tests.browser.cdp import Browser, Page, chromium_path
from websockets.sync.client import connect

from .servers import ROOT, proc_stats

RESULTS = Path(__file__).resolve().parent / "results"
ROW = '#topics tbody tr[data-name="{}"]'
REFRESH_S = 2.0  # the console's graph refresh (main.js)
TARGETS = {"input_p99_ms": 100.0, "chromium_cpu_pct": 50.0, "echo_renders_per_s": 10.0}


@dataclass(frozen=True)
class Settings:
    """How long and how big: the full run, or the smoke test's ``--quick`` one."""

    topics: int = 500
    phase_s: float = 20.0
    refreshes: int = 2
    rate_hz: float = 30.0


QUICK = Settings(topics=50, phase_s=1.0, refreshes=1)

# rows of the topics table that any mutation touched since the observer started
_WATCH_ROWS = """(() => {
  const body = document.querySelector('#topics tbody');
  window.rwtRows = new Set();
  window.rwtRowsObserver?.disconnect();
  window.rwtRowsObserver = new MutationObserver((records) => {
    for (const r of records) {
      const nodes = r.target === body ? [...r.addedNodes, ...r.removedNodes] : [r.target];
      for (const n of nodes) {
        const row = n.nodeType === 1 && n.matches('tr') ? n : n.parentElement?.closest('tr');
        if (row) window.rwtRows.add(row.dataset.name);
      }
    }
  });
  window.rwtRowsObserver.observe(body, {subtree: true, childList: true, characterData: true,
    attributes: true});
  return true;
})()"""

# input latency: from the event's timestamp to the animation frame after its handler
_WATCH_INPUT = """(() => {
  window.rwtLatencies = [];
  window.addEventListener('mousemove', (event) => {
    const at = event.timeStamp;
    requestAnimationFrame(() => window.rwtLatencies.push(performance.now() - at));
  }, true);
  window.rwtRenders = [];
  new MutationObserver((records) => {
    for (const r of records) {
      for (const n of r.addedNodes) {
        if (n.classList?.contains('message')) window.rwtRenders.push(performance.now());
      }
    }
  }).observe(document.getElementById('echo-output'), {childList: true});
  return true;
})()"""

# MJPEG parts reaching the page: the same URL as the <img>, read by fetch
_COUNT_PARTS = """((url) => {
  window.rwtParts = 0;
  window.rwtPartsAbort = new AbortController();
  const marker = new TextEncoder().encode('--boundarydonotcross');
  fetch(url, {signal: window.rwtPartsAbort.signal}).then(async (response) => {
    const reader = response.body.getReader();
    let matched = 0;
    for (;;) {
      const {value, done} = await reader.read();
      if (done) return;
      for (const byte of value) {
        matched = byte === marker[matched] ? matched + 1 : (byte === marker[0] ? 1 : 0);
        if (matched === marker.length) { window.rwtParts += 1; matched = 0; }
      }
    }
  }).catch(() => {});
  return true;
})"""


class Robot:
    """``benchmarks/console_robot.py`` in its own process."""

    def __init__(self, settings: Settings) -> None:
        env = dict(os.environ, PYTHONPATH=f"{ROOT / 'src'}{os.pathsep}{ROOT}")
        self.process = subprocess.Popen(
            [
                *(sys.executable, "-m", "benchmarks.console_robot"),
                *("--topics", str(settings.topics), "--rate", str(settings.rate_hz)),
            ],
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
        )
        assert self.process.stdout is not None
        self.ws_url = self.process.stdout.readline().strip().removeprefix("listening on ")
        self.video_url = self.process.stdout.readline().strip().removeprefix("video on ")
        if not self.ws_url.startswith("ws://") or not self.video_url.startswith("http://"):
            self.close()
            raise RuntimeError("benchmarks.console_robot did not start")

    def cpu_s(self) -> float:
        """CPU seconds the server used so far."""
        return proc_stats(self.process.pid).cpu_s

    def close(self) -> None:
        """Stop the server (SIGTERM, then SIGKILL after 10 s)."""
        self.process.terminate()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(10)
        if self.process.stdout is not None:
            self.process.stdout.close()


def chromium_cpu_s(root_pid: int) -> float:
    """CPU seconds of Chromium: the browser process and every descendant, from /proc."""
    parents: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as f:
                    parents[int(entry)] = int(f.read().rpartition(")")[2].split()[1])
            except OSError:
                continue  # gone meanwhile
    family, grew = {root_pid}, True
    while grew:
        more = {pid for pid, parent in parents.items() if parent in family} - family
        family |= more
        grew = bool(more)
    total = 0.0
    for pid in family:
        try:
            total += proc_stats(pid).cpu_s
        except OSError:
            continue
    return total


class Meter:
    """CPU shares of the server and of Chromium over a window, in % of one core."""

    def __init__(self, robot: Robot, browser: Browser) -> None:
        self.robot, self.browser = robot, browser
        self.start = (time.monotonic(), robot.cpu_s(), chromium_cpu_s(browser.proc.pid))

    def read(self) -> dict[str, float]:
        """``{"server_cpu_pct": ..., "chromium_cpu_pct": ...}`` since this meter started."""
        wall = time.monotonic() - self.start[0]
        server = self.robot.cpu_s() - self.start[1]
        chromium = chromium_cpu_s(self.browser.proc.pid) - self.start[2]
        return {
            "server_cpu_pct": round(100 * server / wall, 1),
            "chromium_cpu_pct": round(100 * chromium / wall, 1),
        }


def list_phase(page: Page, robot: Robot, settings: Settings) -> dict[str, Any]:
    """Rows the refreshes touch: none changed, then one topic added."""
    last = ROW.format(f"/bench/idle_{settings.topics - 1:03d}")
    page.wait_for(f"!!document.querySelector('{last}')", 30, "every topic listed")
    listed = page.evaluate("document.querySelectorAll('#topics tbody tr').length")
    page.evaluate(_WATCH_ROWS)
    time.sleep(settings.refreshes * REFRESH_S + 0.3)
    unchanged = sorted(page.evaluate("[...window.rwtRows]"))
    page.evaluate(_WATCH_ROWS)
    with connect(robot.ws_url) as ws:  # a client advertises one more topic
        ws.send(json.dumps({"op": "advertise", "topic": "/bench/added", "type": "std_msgs/String"}))
        page.wait_for(f"!!document.querySelector('{ROW.format('/bench/added')}')", 15, "the row")
        time.sleep((settings.refreshes - 1) * (REFRESH_S + 0.3))  # more refreshes with it
        added = sorted(page.evaluate("[...window.rwtRows]"))
    return {"rows_listed": listed, "rows_touched_unchanged": unchanged, "rows_touched_added": added}


def echo_phase(page: Page, browser: Browser, robot: Robot, settings: Settings) -> dict[str, Any]:
    """The camera echoed while mouse events come in."""
    page.click(ROW.format("/bench/camera"))
    page.wait_for("document.querySelectorAll('#echo-output .message').length > 0", 30, "the echo")
    page.evaluate(_WATCH_INPUT)
    box = page.evaluate(
        "(r => [r.left + 10, r.top + 10, r.width - 20])"
        "(document.getElementById('topic-name').getBoundingClientRect())"
    )
    meter = Meter(robot, browser)
    started, page_started = time.monotonic(), page.evaluate("performance.now()")
    sent = 0
    while time.monotonic() - started < settings.phase_s:
        x = box[0] + (sent % 2) * min(box[2], 40)
        page.send("Input.dispatchMouseEvent", type="mouseMoved", x=x, y=box[1])
        sent += 1
        time.sleep(random.uniform(0.05, 0.15))
    shares = meter.read()
    page_ended = page.evaluate("performance.now()")
    time.sleep(0.2)  # the last events' frames
    latencies = sorted(page.evaluate("window.rwtLatencies"))
    renders = page.evaluate(
        f"window.rwtRenders.filter((t) => t >= {page_started} && t < {page_ended}).length"
    )
    elapsed = (page_ended - page_started) / 1000
    received = page.text("#echo-stats").split(" ", 1)[0]
    return {
        "input_events": sent,
        "input_handled": len(latencies),
        "input_p50_ms": round(statistics.median(latencies), 1) if latencies else None,
        "input_p99_ms": round(_percentile(latencies, 0.99), 1) if latencies else None,
        "echo_renders_per_s": round(renders / elapsed, 2),
        "echo_received_hz": received,
        **shares,
    }


def _percentile(values: list[float], q: float) -> float:
    """The ``q`` quantile of sorted ``values`` (nearest rank)."""
    return values[min(len(values) - 1, max(0, round(q * len(values) + 0.5) - 1))]


def stream_phase(
    page: Page, browser: Browser, robot: Robot, settings: Settings, kind: str
) -> dict[str, Any]:
    """The Images tab showing the camera as ``kind`` (mjpeg or vp8)."""
    page.evaluate(
        f"(s => {{ s.value = '{kind}'; s.dispatchEvent(new Event('change')); }})"
        "(document.getElementById('image-kind'))"
    )
    figure = '#images figure[data-topic="/bench/camera"]'
    if kind == "mjpeg":
        page.wait_for(
            f"(i => i && i.naturalWidth > 0)(document.querySelector('{figure} img'))",
            30,
            "the MJPEG image",
        )
        src = page.evaluate(f"document.querySelector('{figure} img').src")
        page.evaluate(f"{_COUNT_PARTS}({json.dumps(src)})")
        count = "window.rwtParts"
    else:
        page.wait_for(
            f"(v => v && v.readyState >= 3)(document.querySelector('{figure} video'))",
            30,
            "the VP8 video to play",
        )
        count = (
            f"document.querySelector('{figure} video').getVideoPlaybackQuality().totalVideoFrames"
        )
    meter = Meter(robot, browser)
    first, started = page.evaluate(count), time.monotonic()
    time.sleep(settings.phase_s)
    frames = page.evaluate(count) - first
    elapsed = time.monotonic() - started
    shares = meter.read()
    if kind == "mjpeg":
        page.evaluate("window.rwtPartsAbort.abort()")
    return {"frames_per_s": round(frames / elapsed, 1), **shares}


def measure(settings: Settings) -> dict[str, Any]:
    """Every phase against one robot and one browser; the figures as a dict."""
    executable = chromium_path()
    if executable is None:
        raise RuntimeError("chromium is not installed (apt-get install chromium)")
    robot = Robot(settings)
    browser = Browser(executable)
    try:
        page = browser.new_page()
        # the page's CSP lets it fetch only its own origin: the MJPEG part counter
        # reads the video port
        page.send("Page.setBypassCSP", enabled=True)
        # the Network domain would copy every WebSocket frame (1.2 MB a camera image)
        # into the DevTools connection: a load of the benchmark's own, not the page's
        page.send("Network.disable")
        page.goto(robot.ws_url.replace("ws://", "http://") + "/")
        page.wait_for("!!document.querySelector('#status.ok')", 30, "the console to connect")
        results: dict[str, Any] = {"settings": vars(settings) | {"cpus": os.cpu_count()}}
        results["list"] = list_phase(page, robot, settings)
        results["echo"] = echo_phase(page, browser, robot, settings)
        page.click(ROW.format("/bench/idle_000"))  # the echo stops: the streams alone
        page.click('#tabs button[data-tab="images"]')
        results["mjpeg"] = stream_phase(page, browser, robot, settings, "mjpeg")
        results["vp8"] = stream_phase(page, browser, robot, settings, "vp8")
        results["page_errors"] = page.errors()
        return results
    finally:
        browser.close()
        robot.close()


def table(results: dict[str, Any]) -> str:
    """The figures as a markdown table, with the targets."""
    listed, echo = results["list"], results["echo"]
    mjpeg, vp8 = results["mjpeg"], results["vp8"]

    def verdict(value: float | None, key: str) -> str:
        if value is None:
            return "-"
        return f"<= {TARGETS[key]:g}: {'met' if value <= TARGETS[key] else 'missed'}"

    rows = [
        (
            "input latency p50 / p99, ms (echo running)",
            f"{echo['input_p50_ms']} / {echo['input_p99_ms']} ({echo['input_handled']} events)",
            verdict(echo["input_p99_ms"], "input_p99_ms"),
        ),
        (
            "Chromium CPU, % of a core (echo running)",
            f"{echo['chromium_cpu_pct']}",
            verdict(echo["chromium_cpu_pct"], "chromium_cpu_pct"),
        ),
        (
            "echo renders/s (messages/s received)",
            f"{echo['echo_renders_per_s']} ({echo['echo_received_hz']})",
            verdict(echo["echo_renders_per_s"], "echo_renders_per_s"),
        ),
        ("server CPU, % of a core (echo running)", f"{echo['server_cpu_pct']}", "-"),
        (
            f"rows listed; touched by {results['settings']['refreshes']} refreshes,"
            " nothing changed",
            f"{listed['rows_listed']}; {len(listed['rows_touched_unchanged'])}",
            "0",
        ),
        (
            "rows touched when one topic is added",
            f"{len(listed['rows_touched_added'])}",
            "1 (the new row)",
        ),
        (
            "MJPEG: frames/s reaching the page; server CPU %; Chromium CPU %",
            f"{mjpeg['frames_per_s']}; {mjpeg['server_cpu_pct']}; {mjpeg['chromium_cpu_pct']}",
            "-",
        ),
        (
            "VP8: frames/s presented; server CPU %; Chromium CPU %",
            f"{vp8['frames_per_s']}; {vp8['server_cpu_pct']}; {vp8['chromium_cpu_pct']}",
            "-",
        ),
    ]
    lines = ["| measure | value | target |", "|---|---|---|"]
    lines += [f"| {name} | {value} | {target} |" for name, value, target in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print its table and save ``results/console.json``."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks console", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="brief phases, 50 topics (smoke)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="where console.json goes")
    args = parser.parse_args(argv)
    results = measure(QUICK if args.quick else Settings())
    print(table(results))
    if not args.quick:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "console.json").write_text(json.dumps(results, indent=1) + "\n")
    return 1 if results["page_errors"] else 0
