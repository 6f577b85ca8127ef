"""``RosbridgeServer.stop``: a graceful stop that ``serve`` honours even when asked first.

``rwt serve`` stops gracefully at the first SIGINT or SIGTERM and at once at the
second: it tells them apart by ``stop_requested``.
"""

from __future__ import annotations

import anyio

import rwt

HANG_GUARD_S = 60  # a bound on a serve that never returns, not a speed requirement


def test_a_stop_asked_before_serve_is_kept_and_serve_returns() -> None:
    server = rwt.RosbridgeServer(rwt.Graph(), rwt.ServerConfig(host="127.0.0.1", port=0))
    assert not server.stop_requested
    server.stop()
    assert server.stop_requested

    async def serve() -> None:
        with anyio.fail_after(HANG_GUARD_S):
            await server.serve()

    anyio.run(serve)
    assert server.stop_requested
