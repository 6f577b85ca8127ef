"""B14: the cost of checking one small inbound publish op, in-process.

Run as ``python -m benchmarks.microbench`` with this checkout's ``src`` on
PYTHONPATH; prints JSON. ``bare_us`` is msgspec decoding and re-encoding the
same frame (the floor, docs/benchmarks.md: about 1 us); ``validate_us`` is what rwt
does to a publish frame before handing the message to the graph: decode, check
the op, convert the message against its type; ``receive_frame_us`` is the
whole ``Session.receive_frame`` on a topic without subscribers.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable

import msgspec

FRAME = b'{"op":"publish","topic":"/b14","msg":{"data":"hello world, a small message"}}'


def _per_call_us(fns: dict[str, Callable[[], object]], seconds: float = 0.3) -> dict[str, float]:
    """Median over 5 rounds of the time per call of each function, microseconds.

    The rounds interleave the functions (one batch of each per round): this
    shared machine's speed changes by up to 2x within seconds, and measuring
    one function after the other would compare different machines.
    """
    batch = 1000
    for fn in fns.values():
        start = time.perf_counter()
        while time.perf_counter() - start < 0.05:
            fn()
    results: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(5):
        for name, fn in fns.items():
            count = 0
            start = time.perf_counter()
            while time.perf_counter() - start < seconds / 5:
                for _ in range(batch):
                    fn()
                count += batch
            results[name].append((time.perf_counter() - start) / count * 1e6)
    return {name: sorted(values)[2] for name, values in results.items()}


def measure() -> dict[str, float]:
    """The three figures, in microseconds per frame."""
    from rwt_graph.graph import Graph  # noqa: PLC0415
    from rwt_protocol.server.session import Session  # noqa: PLC0415

    from . import inbound  # noqa: PLC0415

    graph = Graph()
    session = Session(graph.port, "bench")
    session.receive_frame(b'{"op":"advertise","topic":"/b14","type":"std_msgs/msg/String"}', 0.0)
    validate = inbound.validator(graph)
    decoder = msgspec.json.Decoder()
    encoder = msgspec.json.Encoder()
    return _per_call_us(
        {
            "bare_us": lambda: encoder.encode(decoder.decode(FRAME)),
            "validate_us": lambda: validate(FRAME),
            "receive_frame_us": lambda: session.receive_frame(FRAME, 1.0),
        }
    )


if __name__ == "__main__":
    print(json.dumps(measure()))
