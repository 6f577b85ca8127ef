"""The HTTP API's attack replay in its smoke form: class 31 with 80 streams, briefly
(benchmarks/attacks_http.py). The figures of so short a run mean nothing; what a client
sees does: one host's streams past its share (64) are refused 503, another host's is
served. The latency verdict is not asserted (it is a timing)."""

from __future__ import annotations

import anyio
import pytest
from benchmarks.attack_kit import replay

from benchmarks import attacks_http


def test_one_hosts_streams_past_its_share_are_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(attacks_http, "ONE_HOST", attacks_http.HOST_SHARE + 16)
    (streams,) = [a for a in attacks_http.ATTACKS if a.number == "31"]
    result = anyio.run(lambda: replay(streams, scale=0.1))
    assert result.outcome["answered by status"] == {200: attacks_http.HOST_SHARE, 503: 16}
    assert result.outcome["another host's first message ms"] is not None
    assert result.rights_ok and result.log_tracebacks == 0
