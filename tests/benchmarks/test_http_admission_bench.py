"""The replay of requests read before admission, in its smoke form (benchmarks/http_admission.py).

Both kinds of class for a moment against a real ``rwt serve``: 20 sockets holding
bodies short of their last byte, and four sending 1-byte chunks to the HTTP API. The
figures of so short a run mean nothing, only that each part of the replay ran (the
server, the bystander, /proc, the attacker's tally) and that the server answered as
D58 says: the host's share holds a few bodies, the rest get 429, another host is
served. The latency verdict is not asserted (it is a timing).
"""

from __future__ import annotations

import anyio
from benchmarks.attack_kit import replay
from benchmarks.http_admission import ATTACKS, held_attack


def test_held_bodies_replay_with_their_figures_and_outcome() -> None:
    result = anyio.run(lambda: replay(held_attack(sockets=20), scale=0.1))
    assert result.baseline.calls > 0 and result.attack.calls > 0
    answers = result.outcome["answers"]
    assert set(answers) == {"HTTP/1.1 429 Too Many Requests", "held (no answer)"}
    assert sum(answers.values()) == 20
    assert result.outcome["another host's 1 MiB post"].startswith("200 ")


def test_one_byte_chunks_replay_with_their_figures() -> None:
    (chunks,) = [a for a in ATTACKS if a.number == "chunks-api"]
    result = anyio.run(lambda: replay(chunks, scale=0.1))
    assert result.baseline.calls > 0 and result.attack.calls > 0
    assert result.outcome["requests"] >= 4
    assert result.outcome["newcomers answered"] > 0
    assert result.outcome["newcomers failed"] == {}
    assert result.rights_ok
