"""Watch aiortc's SCTP sender in this process: congestion window, fast recovery, retransmissions.

For ``python -m benchmarks.wan_topic --trace-sctp`` (docs/benchmarks.md, "Over a WAN
link"): ``install()`` wraps four methods of aiortc's ``RTCSctpTransport`` to count
what they do and calls each original unchanged, so the association behaves as without
it; ``report`` prints a line ``sctp-trace {json}`` to stderr each second, over the
samples of that second (every 50 ms) of each established association:

- ``cwnd``: the congestion window's min, median and max, bytes of user data;
- ``flight_med``, ``sent_queue_max``, ``in_fast_recovery`` (share of samples);
- counts so far: DATA chunks sent and resent, FORWARD TSN chunks sent, SACKs
  received, fast recoveries entered, T3 (retransmission timer) expiries;
- ``sent_count_hist``: for chunks acknowledged so far, how many times each was sent.
"""

from __future__ import annotations

import json
import statistics
import sys
from collections import Counter
from typing import Any

import anyio

_instances: list[Any] = []
_counts: Counter[str] = Counter()
_sent_counts: Counter[int] = Counter()


def install() -> None:
    """Wrap ``RTCSctpTransport``'s methods to count (their behaviour unchanged)."""
    from aiortc import rtcsctptransport as sctp  # noqa: PLC0415 (only when tracing)

    cls: Any = sctp.RTCSctpTransport
    init, t3, sack, send = cls.__init__, cls._t3_expired, cls._receive_sack_chunk, cls._send_chunk

    def traced_init(self: Any, *args: Any, **kwargs: Any) -> None:
        init(self, *args, **kwargs)
        _instances.append(self)

    def traced_t3(self: Any) -> None:
        _counts["t3_expired"] += 1
        t3(self)

    async def traced_sack(self: Any, chunk: Any) -> None:
        _counts["sacks"] += 1
        before = self._fast_recovery_exit
        for sent in self._sent_queue:  # the chunks this SACK acknowledges cumulatively
            if sctp.uint32_gt(sent.tsn, chunk.cumulative_tsn):
                break
            if not sent._abandoned and not getattr(sent, "_traced", False):
                sent._traced = True
                _sent_counts[sent._sent_count] += 1
        await sack(self, chunk)
        if before is None and self._fast_recovery_exit is not None:
            _counts["fast_recovery"] += 1

    async def traced_send(self: Any, chunk: Any) -> None:
        if isinstance(chunk, sctp.ForwardTsnChunk):
            _counts["forward_tsn"] += 1
        elif isinstance(chunk, sctp.DataChunk):
            _counts["data"] += 1
            _counts["resent"] += chunk._sent_count > 1
        await send(self, chunk)

    cls.__init__, cls._t3_expired = traced_init, traced_t3
    cls._receive_sack_chunk, cls._send_chunk = traced_sack, traced_send


async def report() -> None:
    """Sample every 50 ms; print a ``sctp-trace`` line a second (until cancelled)."""
    samples: list[tuple[int, int, int, bool]] = []
    while True:
        await anyio.sleep(0.05)
        for transport in _instances:
            if transport._association_state == type(transport).State.ESTABLISHED:
                samples.append(
                    (
                        transport._cwnd,
                        transport._flight_size,
                        len(transport._sent_queue),
                        transport._fast_recovery_exit is not None,
                    )
                )
        if len(samples) < 20:
            continue
        cwnd = sorted(s[0] for s in samples)
        last = _instances[-1]
        line = {
            "cwnd": [cwnd[0], cwnd[len(cwnd) // 2], cwnd[-1]],
            "flight_med": statistics.median(s[1] for s in samples),
            "sent_queue_max": max(s[2] for s in samples),
            "in_fast_recovery": round(sum(s[3] for s in samples) / len(samples), 2),
            "ssthresh": last._ssthresh,
            "srtt_s": None if last._srtt is None else round(last._srtt, 3),
            "rto_s": round(last._rto, 3),
            **_counts,
            "sent_count_hist": dict(sorted(_sent_counts.items())),
        }
        print(f"sctp-trace {json.dumps(line)}", file=sys.stderr, flush=True)
        samples.clear()
