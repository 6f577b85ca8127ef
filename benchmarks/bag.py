"""B20: record and replay throughput next to rosbags alone, and replay timing accuracy.

Recording: an in-process publisher sends already-converted messages (100 B
``std_msgs/String`` and 1 MB ``sensor_msgs/Image``) to a ``Recorder`` of an MCAP
bag, from the first publish until the bag is closed; next to it, in the same
run, rosbags alone serializes the same messages (built as rosbags objects
beforehand) and writes them with its own MCAP writer. Replay: a ``Player``
at the fastest rate it takes (``rwt_graph.playback.MAX_RATE``, a million times:
the bag's schedule never holds it back; no check pass) publishes a bag to one
in-process subscriber, next to rosbags alone reading and deserializing the
same bag with ``AnyReader``. Target for every ratio rwt / rosbags: >= 0.7.

Timing accuracy: the player replays 1 s of 200 Hz messages at rate 1; each
message's deviation is its arrival minus its place on the bag's schedule
(anchored at the first message), reported as p50 and p99 in ms.

    python benchmarks/bag.py [--runs 3] [--smoke]

Prints a table and writes ``benchmarks/results/bag.json`` (not with --smoke).
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import anyio
import anyio.lowlevel
import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from rwt_bag import Player, Recorder
from rwt_graph.graph import Graph
from rwt_graph.playback import MAX_RATE

RESULTS = Path(__file__).parent / "results" / "bag.json"
TARGET = 0.7
MB = 1_000_000


@dataclass(frozen=True)
class Load:
    """One kind of message: its type, one message (internal form), how many."""

    name: str
    type_name: str
    msg: dict[str, object]
    count: int

    @property
    def size(self) -> int:
        """Approximate payload bytes of one message (what MB/s counts)."""
        data = self.msg["data"]
        return len(data)  # type: ignore[arg-type]


def loads(smoke: bool) -> list[Load]:
    """100 B strings and 1 MB images (fewer with --smoke)."""
    image = {
        "header": {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": "camera"},
        "height": 512,
        "width": 2048,
        "encoding": "mono8",
        "is_bigendian": 0,
        "step": 2048,
        "data": np.random.default_rng(1).integers(0, 256, 1 << 20, dtype=np.uint8).tobytes(),
    }
    return [
        Load("100 B strings", "std_msgs/msg/String", {"data": "x" * 100}, 200 if smoke else 50_000),
        Load("1 MB images", "sensor_msgs/msg/Image", image, 5 if smoke else 200),
    ]


def _timed(work: Callable[[], object]) -> float:
    start = time.perf_counter()
    work()
    return time.perf_counter() - start


def record_rwt(load: Load, path: Path) -> float:
    """Seconds for rwt to record ``load`` (first publish to closed bag)."""
    graph = Graph()
    msgtype = graph.registry.message(load.type_name)
    msg = msgtype.from_python(load.msg)
    publisher = graph.create_publisher("/bench", load.type_name)

    async def main() -> float:
        recorder = Recorder(graph, path, checkpoint_s=1.0)
        async with anyio.create_task_group() as tg:
            await tg.start(recorder.run)
            start = time.perf_counter()
            for i in range(load.count):
                publisher.publish(msg, validated=True)
                if i % 256 == 255 or load.size > 64 * 1024:
                    await anyio.lowlevel.checkpoint()  # the writer takes a batch, as in a server
            while recorder.stats.messages + recorder.stats.dropped < load.count:  # noqa: ASYNC110
                await anyio.sleep(0.001)
            tg.cancel_scope.cancel()
        assert recorder.stats.messages == load.count, recorder.stats
        return time.perf_counter() - start

    return anyio.run(main)


def record_rosbags(load: Load, path: Path) -> float:
    """Seconds for rosbags alone to serialize and write ``load`` (objects built beforehand)."""
    graph = Graph()
    msgtype = graph.registry.message(load.type_name)
    store = graph.registry.typestore()
    obj = msgtype.to_rosbags(msgtype.from_python(load.msg), store)
    name = msgtype.rosbags_name

    def work() -> None:
        with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conn = writer.add_connection("/bench", name, typestore=store)
            for i in range(load.count):
                writer.write(conn, i, store.serialize_cdr(obj, name))

    return _timed(work)


def replay_rwt(bag: Path, count: int) -> float:
    """Seconds for the player to publish the whole bag to a subscriber, unthrottled."""
    graph = Graph()
    got = 0

    def arrived(_msg: object) -> None:
        # counts, as the rosbags side does: keeping every message alive (200 MB of
        # images, 50000 dicts for the collector to walk) is work rosbags alone skips
        nonlocal got
        got += 1

    graph.create_subscription("/bench", arrived, _bag_type(bag))

    async def main() -> float:
        player = Player(graph, bag, rate=MAX_RATE, check=False)
        start = time.perf_counter()
        await player.run()
        return time.perf_counter() - start

    elapsed = anyio.run(main)
    assert got == count, got
    return elapsed


def _bag_type(bag: Path) -> str:
    with AnyReader([bag]) as reader:
        return str(reader.connections[0].msgtype)


def replay_rosbags(bag: Path, count: int) -> float:
    """Seconds for rosbags alone to read and deserialize the whole bag."""

    def work() -> None:
        n = 0
        with AnyReader([bag]) as reader:
            for conn, _, raw in reader.messages():
                reader.deserialize(raw, conn.msgtype)
                n += 1
        assert n == count

    return _timed(work)


def timing(tmp: Path, hz: float = 200.0, seconds: float = 1.0) -> tuple[float, float]:
    """p50 and p99 (ms) of the arrival deviations from the bag's schedule at rate 1."""
    store = Graph().registry.typestore()
    cls = store.types["std_msgs/msg/String"]
    bag = tmp / "timing"
    count = int(hz * seconds)
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/tick", "std_msgs/msg/String", typestore=store)
        for i in range(count):
            raw = store.serialize_cdr(cls(data=str(i)), "std_msgs/msg/String")
            writer.write(conn, 10**18 + int(i * 1e9 / hz), raw)
    graph = Graph()
    arrivals: list[float] = []
    graph.create_subscription(
        "/tick", lambda _: arrivals.append(time.monotonic()), "std_msgs/String"
    )
    anyio.run(Player(graph, bag).run)
    assert len(arrivals) == count
    deviations = [abs(t - arrivals[0] - i / hz) * 1000 for i, t in enumerate(arrivals)]
    quantiles = statistics.quantiles(deviations, n=100)
    return statistics.median(deviations), quantiles[98]


def run(runs: int, smoke: bool) -> dict[str, object]:
    """Every measurement, medians of ``runs``."""
    rows: list[dict[str, object]] = []
    tmp = Path(tempfile.mkdtemp(prefix="rwt-bag-bench-"))
    try:
        for load in loads(smoke):
            rec: dict[str, list[float]] = {"rwt": [], "rosbags": []}
            rep: dict[str, list[float]] = {"rwt": [], "rosbags": []}
            for r in range(runs):
                for who, fn in (("rwt", record_rwt), ("rosbags", record_rosbags)):
                    path = tmp / f"{who}-{r}-{load.count}"
                    rec[who].append(fn(load, path))
                bag = tmp / f"rosbags-{r}-{load.count}"
                rep["rwt"].append(replay_rwt(bag, load.count))
                rep["rosbags"].append(replay_rosbags(bag, load.count))
                for each in tmp.glob(f"*-{r}-{load.count}"):
                    shutil.rmtree(each)
            for what, times in (("record", rec), ("replay", rep)):
                rwt_s, bags_s = statistics.median(times["rwt"]), statistics.median(times["rosbags"])
                rows.append(
                    {
                        "measure": f"{what} {load.name}",
                        "count": load.count,
                        "rwt_msg_s": load.count / rwt_s,
                        "rwt_mb_s": load.count * load.size / rwt_s / MB,
                        "rosbags_msg_s": load.count / bags_s,
                        "rosbags_mb_s": load.count * load.size / bags_s / MB,
                        "ratio": bags_s / rwt_s,
                    }
                )
        p50, p99 = timing(tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"runs": runs, "rows": rows, "timing_p50_ms": p50, "timing_p99_ms": p99}


def table(result: dict[str, object]) -> str:
    """The results as a Markdown table."""
    lines = [
        "| measure | rwt msg/s | rwt MB/s | rosbags alone msg/s | rosbags alone MB/s "
        "| ratio | target |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in result["rows"]:  # type: ignore[attr-defined]
        met = "met" if row["ratio"] >= TARGET else "NOT met"
        lines.append(
            f"| {row['measure']} ({row['count']}) | {row['rwt_msg_s']:,.0f} | "
            f"{row['rwt_mb_s']:,.1f} | {row['rosbags_msg_s']:,.0f} | {row['rosbags_mb_s']:,.1f} | "
            f"{row['ratio']:.2f} | >= {TARGET} {met} |"
        )
    lines.append(
        f"\nReplay timing at rate 1 (200 Hz, 1 s): deviation from the bag's schedule "
        f"p50 {result['timing_p50_ms']:.2f} ms, p99 {result['timing_p99_ms']:.2f} ms."
    )
    return "\n".join(lines)


def main() -> None:
    """Run, print the table, save the JSON."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--smoke", action="store_true", help="tiny counts, one run, no file")
    args = parser.parse_args()
    result = run(1 if args.smoke else args.runs, args.smoke)
    print(table(result))
    if not args.smoke:
        RESULTS.write_text(json.dumps(result, indent=2) + "\n", "utf-8")


if __name__ == "__main__":
    main()
