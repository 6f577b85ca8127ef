"""B14 (in-process validation, run in a subprocess) and B15 (soak)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

from .. import msgs
from ..loadgen.engine import (
    ExactSubscriber,
    ParsingSubscriber,
    RatePublisher,
    close_all,
    percentile_ms,
    run_loop,
)
from ..loadgen.wire import client_frame, server_frame
from ..servers import ROOT
from .common import Metrics, Run, settle
from .latency import LatencyTrack

__all__ = ["microbench_run", "soak_run"]

Sample = tuple[float, float]
"""(perf_counter seconds, RSS MB)."""


def microbench_run(run: Run) -> Metrics:
    """B14 in a fresh interpreter on this checkout's ``src``; ``us_per_op`` per kind."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), str(ROOT)])
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.microbench"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    figures: dict[str, float] = json.loads(out.stdout)
    figures["us_per_op"] = figures["bare_us"] if run.kind == "bare" else figures["validate_us"]
    return figures


def soak_run(run: Run, *, rate_hz: float, duration_s: float) -> Metrics:
    """B15: a String stream at ``rate_hz`` plus 640x480 rgb8 JSON images at 30 Hz.

    ``rate_hz`` is a fallback: half of rwt's median B1 String rate when B1 ran
    before (``run.context``), the same rate for both servers.

    RSS is sampled every second; the slope (MB per 10 min) is fitted over the
    samples after the warm-up (the first tenth, at least the first 30 s: the
    server's heap and the sockets' buffers grow to their working size in the
    first seconds, which a short run would otherwise read as a leak). The
    String latency p99 of the first and the last third give the drift.
    """
    duration = duration_s * run.scale
    b1 = run.context.get("B1 String 100 B, 1 -> 1", {}).get("rwt", {}).get("msg_per_s")
    if b1:
        rate_hz = b1["median"] / 2
    topic, image_topic = "/b15", "/b15_image"
    track = LatencyTrack(lambda i: msgs.string_publish(topic, i % 10**msgs.SEQ_DIGITS))
    sub = ParsingSubscriber(
        run.port,
        run.kind,
        [msgs.subscribe(topic, "std_msgs/msg/String")],
        lambda opcode, payload, now: track.check(payload, now),
    )
    pub = RatePublisher(
        run.port,
        run.kind,
        [msgs.advertise(topic, "std_msgs/msg/String")],
        lambda i: client_frame(msgs.string_publish(topic, i)),
        rate_hz=rate_hz,
        duration_s=duration,
    )
    track.publisher = pub
    images = [msgs.publish_json(image_topic, msgs.image_json_msg(i, 640, 480)) for i in range(2)]
    image_sub = ExactSubscriber(
        run.port,
        run.kind,
        [msgs.subscribe(image_topic, "sensor_msgs/msg/Image")],
        b"".join(server_frame(p) for p in images),
        len(server_frame(images[0])),
        group="image",
    )
    image_frames = [client_frame(p) for p in images]
    image_pub = RatePublisher(
        run.port,
        run.kind,
        [msgs.advertise(image_topic, "sensor_msgs/msg/Image")],
        lambda i: image_frames[i % 2],
        rate_hz=30.0,
        duration_s=duration,
        group="image",
    )
    samples: list[Sample] = []
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(1.0):
            samples.append((time.perf_counter(), run.server.stats().rss_bytes / 1e6))

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    try:
        run_loop(
            [pub, image_pub],
            [sub, image_sub],
            done=lambda: (
                pub.finished
                and image_pub.finished
                and sub.received >= pub.sent
                and image_sub.received >= image_pub.sent
            ),
            limit_s=duration + 60.0,
        )
    finally:
        stop.set()
        sampler.join()
        close_all([pub, sub, image_pub, image_sub])
    lat = track.latencies_s
    third = max(1, len(lat) // 3)
    first, last = percentile_ms(lat[:third], 0.99), percentile_ms(lat[-third:], 0.99)
    settle()
    return {
        "rss_slope_mb_per_10min": _slope(_after_warmup(samples, duration)) * 600.0,
        "p99_first_ms": first,
        "p99_last_ms": last,
        "p99_drift_pct": 100.0 * (last - first) / first if first else float("nan"),
        "p99_ms": percentile_ms(lat, 0.99),
        "server_rss_mb": samples[-1][1] if samples else float("nan"),
        "rate_hz": rate_hz,
    }


def _after_warmup(samples: list[Sample], duration_s: float) -> list[Sample]:
    """The RSS samples taken after the first tenth of the run and at least 30 s in
    (a third of a run shorter than 90 s, such as the smoke run)."""
    if not samples:
        return samples
    start = samples[0][0] - 1.0  # the sampler's first sample comes a second in
    warmup = max(duration_s / 10, min(30.0, duration_s / 3))
    return [(t, mb) for t, mb in samples if t - start >= warmup]


def _slope(samples: list[Sample]) -> float:
    """Least-squares slope of (seconds, MB): MB per second."""
    if len(samples) < 2:
        return float("nan")
    n = len(samples)
    mx = sum(t for t, _ in samples) / n
    my = sum(m for _, m in samples) / n
    var = sum((t - mx) ** 2 for t, _ in samples)
    return sum((t - mx) * (m - my) for t, m in samples) / var if var else float("nan")
