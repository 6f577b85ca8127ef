"""B13: PNG compression of large messages, next to the Robot Web Tools paper's Table III.

The paper (section IV.D, Table III) reports a 732x413 map going from 2725 KB to
39 KB in 40 ms, and three markers (42.1 -> 5.1 KB, 42.1 -> 4.8 KB, 78.1 -> 7.7 KB)
in about 1 ms. This script builds the same kinds of messages (a synthetic
``nav_msgs/OccupancyGrid`` of 732x413 cells: unknown outside, free rooms, walls;
``visualization_msgs/Marker`` point, line strip and line list markers), publishes
each through rwt to a subscriber with ``compression: "png"``, and reports:

- the JSON size of the publish op and the size of the ``png`` op rwt sends;
- rwt's time from publish to queued frame (conversion, JSON, PNG, base64), and
  the PNG step alone (``encode_png`` of the JSON text);
- a bare Pillow encode of the same padded bytes, in the same run, and the ratio
  of rwt's PNG step to it (target <= 1.3, B13).

Times are medians over ``--runs`` repetitions. Usage:

    python benchmarks/png_compression.py [--runs 15]

Prints a table and writes ``benchmarks/results/png_compression.json``.
"""

from __future__ import annotations

import argparse
import io
import json
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image

from rwt_graph.graph import Graph
from rwt_protocol.codecs.png import encode_png, png_dimensions
from rwt_protocol.server.session import Session

RESULTS = Path(__file__).parent / "results" / "png_compression.json"

#: Paper Table III: name -> (original KB, compressed KB, ms).
PAPER = {
    "Map (732x413)": (2725.0, 39.0, 40.0),
    "3D Point Array Marker": (42.1, 5.1, 0.8),
    "3D Line Strip Marker": (42.1, 4.8, 0.9),
    "3D Line List Marker": (78.1, 7.7, 1.0),
}


def occupancy_grid(width: int = 732, height: int = 413) -> dict[str, object]:
    """A synthetic building map: unknown (-1) outside, free (0) rooms, walls (100)."""
    rng = np.random.default_rng(4)
    grid = np.full((height, width), -1, dtype=np.int8)
    grid[40:380, 60:680] = 0
    for x in range(60, 681, 124):
        grid[40:380, x : x + 3] = 100
    for y in (40, 200, 377):
        grid[y : y + 3, 60:683] = 100
    for x in range(120, 680, 124):
        grid[195:208, x : x + 20] = 0  # doors
    clutter = rng.random((height, width)) < 0.004
    grid[clutter & (grid == 0)] = 100
    return {
        "header": {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": "map"},
        "info": {"resolution": 0.05, "width": width, "height": height},
        "data": grid.ravel().tolist(),
    }


def marker(kind: int, count: int) -> dict[str, object]:
    """A ``visualization_msgs/Marker`` of ``count`` points on a 5 cm grid, 40 per row."""
    points = [
        {"x": round((i % 40) * 0.05, 2), "y": round((i // 40) * 0.05, 2), "z": 0.0}
        for i in range(count)
    ]
    return {
        "header": {"frame_id": "map"},
        "ns": "bench",
        "type": kind,
        "scale": {"x": 0.05, "y": 0.05, "z": 0.05},
        "color": {"r": 1.0, "a": 1.0},
        "points": points,
    }


def median_ms(run: Callable[[], object], runs: int) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        run()
        times.append((time.perf_counter() - start) * 1000)
    return statistics.median(times)


def bare_pillow(data: bytes) -> bytes:
    """The same image rwt makes, straight from Pillow: frombytes + save, no base64."""
    width, height = png_dimensions(len(data))
    padded = data + b"\n" * (width * height * 3 - len(data))
    out = io.BytesIO()
    Image.frombytes("RGB", (width, height), padded).save(out, format="PNG")
    return out.getvalue()


def measure(name: str, type_name: str, msg: dict[str, object], runs: int) -> dict[str, object]:
    """Publish ``msg`` through rwt to a png subscriber and time the parts."""
    graph = Graph()
    publisher = graph.create_publisher("/bench", type_name)
    subscriber = Session(graph.port, "sub")
    subscriber.receive_frame(
        json.dumps({"op": "subscribe", "topic": "/bench", "compression": "png"}), 0.0
    )
    plain = Session(graph.port, "json")
    plain.receive_frame(json.dumps({"op": "subscribe", "topic": "/bench"}), 0.0)

    def publish() -> bytes:
        publisher.publish(msg)
        plain.frames_to_send()
        [frame] = subscriber.frames_to_send()
        return frame.data

    png_op = publish()
    publish_ms = median_ms(publish, runs)
    publisher.publish(msg)
    [text_frame] = plain.frames_to_send()
    subscriber.frames_to_send()
    text = text_frame.data
    png_ms = median_ms(lambda: encode_png(text), runs)
    bare_ms = median_ms(lambda: bare_pillow(text), runs)
    return {
        "name": name,
        "json_kb": len(text) / 1000,
        "png_op_kb": len(png_op) / 1000,
        "png_file_kb": len(bare_pillow(text)) / 1000,
        "publish_to_frame_ms": publish_ms,
        "png_step_ms": png_ms,
        "bare_pillow_ms": bare_ms,
        "ratio_to_bare": png_ms / bare_ms,
        "paper": dict(zip(("original_kb", "compressed_kb", "ms"), PAPER[name], strict=True)),
    }


def cases() -> list[tuple[str, str, dict[str, object]]]:
    """The messages of Table III: (name, type, message)."""
    return [
        ("Map (732x413)", "nav_msgs/msg/OccupancyGrid", occupancy_grid()),
        ("3D Point Array Marker", "visualization_msgs/msg/Marker", marker(8, 1500)),
        ("3D Line Strip Marker", "visualization_msgs/msg/Marker", marker(4, 1500)),
        ("3D Line List Marker", "visualization_msgs/msg/Marker", marker(5, 2800)),
    ]


def measure_all(runs: int) -> list[dict[str, object]]:
    """``measure`` every case of ``cases()``."""
    return [measure(name, type_name, msg, runs) for name, type_name, msg in cases()]


def main() -> None:
    parser = argparse.ArgumentParser(description="B13: PNG compression vs paper Table III")
    parser.add_argument("--runs", type=int, default=15)
    runs = parser.parse_args().runs
    rows = measure_all(runs)
    header = (
        f"{'message':<22} {'JSON KB':>8} {'png op KB':>9} {'PNG KB':>7} {'publish ms':>10}"
        f" {'png ms':>7} {'Pillow ms':>9} {'ratio':>5} | paper: {'KB':>6} {'-> KB':>6} {'ms':>5}"
    )
    print(header)
    print("-" * len(header))
    for r in rows:
        paper = r["paper"]
        assert isinstance(paper, dict)
        print(
            f"{r['name']:<22} {r['json_kb']:>8.1f} {r['png_op_kb']:>9.1f} {r['png_file_kb']:>7.1f}"
            f" {r['publish_to_frame_ms']:>10.2f} {r['png_step_ms']:>7.2f}"
            f" {r['bare_pillow_ms']:>9.2f} {r['ratio_to_bare']:>5.2f} |"
            f" {paper['original_kb']:>13.1f} {paper['compressed_kb']:>6.1f} {paper['ms']:>5.1f}"
        )
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps({"runs": runs, "rows": rows}, indent=2) + "\n")
    print(f"\nmedians of {runs} runs; written to {RESULTS.relative_to(Path.cwd())}")


if __name__ == "__main__":
    main()
