"""Video tokens (docs/video.md, D32): issued by a service, checked by the video server.

The clock is the tokens' own (a test's), so expiry is a step of that clock, not a wait.
"""

from __future__ import annotations

import anyio
import httpx
import pytest

from rwt_graph.graph import Graph
from rwt_video import VideoConfig, VideoTokens, serve_video
from rwt_video.tokens import TOKEN_CHARS

pytestmark = pytest.mark.anyio


class Clock:
    """Monotonic seconds that move only when told."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_tokens_are_unguessable_and_expire() -> None:
    clock = Clock()
    tokens = VideoTokens(lifetime_s=30, clock=clock)
    first, second = tokens.issue(), tokens.issue()
    assert first != second and len(first) == TOKEN_CHARS == 64
    assert tokens.valid(first) and tokens.valid(second)
    assert not tokens.valid(first[:-1] + ("A" if first[-1] != "A" else "B"))
    assert not tokens.valid("") and not tokens.valid("é" * TOKEN_CHARS)
    assert not tokens.valid("A" * TOKEN_CHARS)  # well formed, not signed here
    assert not VideoTokens(clock=clock).valid(first)  # another server's key
    clock.now += 29.9
    assert tokens.valid(first)
    clock.now += 0.1
    assert not tokens.valid(first) and not tokens.valid(second)


def test_no_number_of_tokens_issued_revokes_another() -> None:
    """Tokens are signed, not stored: a client asking for many pushes nobody's out (D32)."""
    tokens = VideoTokens(clock=Clock())
    victim = tokens.issue()
    for _ in range(5000):
        tokens.issue()
    assert tokens.valid(victim)


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="positive"):
        VideoTokens(lifetime_s=0)


async def test_the_server_admits_a_live_token_and_refuses_an_expired_one() -> None:
    graph = Graph()
    graph.create_publisher("/camera/image", "sensor_msgs/msg/Image")
    clock = Clock()
    tokens = VideoTokens(lifetime_s=10, clock=clock)
    token = tokens.issue()  # what /rwt/video_token answers (tests/video/test_video_tokens_cli.py)
    async with anyio.create_task_group() as tg:
        url = await tg.start(serve_video, graph, VideoConfig(port=0, tokens=tokens))
        async with httpx.AsyncClient(base_url=url, timeout=20) as client:
            viewer = await client.get(f"/stream_viewer?topic=/camera/image&token={token}")
            assert viewer.status_code == 200
            assert f"token={token}" in viewer.text  # the page's stream URL carries it
            listing = await client.get("/", headers={"Authorization": f"Bearer {token}"})
            assert listing.status_code == 200 and f"token={token}" in listing.text
            clock.now += 10
            expired = await client.get(f"/stream_viewer?topic=/camera/image&token={token}")
            assert expired.status_code == 403
            assert expired.text == "403 the video token is wrong or expired\n"
        tg.cancel_scope.cancel()
