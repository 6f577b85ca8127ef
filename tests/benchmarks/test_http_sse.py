"""The SSE-against-WebSocket benchmark runs and both readers get every message."""

from __future__ import annotations

import anyio
from benchmarks.http_sse import measure


def test_both_readers_get_every_published_message() -> None:
    result = anyio.run(measure, 0.1, 200.0)
    assert result["ws"] == result["sse"] == result["sent"] == 20
