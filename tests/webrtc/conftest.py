"""The WebRTC tests' server: every test module here skips when aiortc is missing.

Each module calls ``pytest.importorskip("aiortc", reason=NEEDS_AIORTC)`` before it
imports the real peer (peer.py).
"""

from __future__ import annotations

import importlib.util
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING

import pytest

from rwt_protocol.distribution import install_hint
from rwt_transports.server import ServerConfig
from rwt_transports.webrtc.signalling import WebRtcOptions
from rwt_transports.webrtc.stacks import stack_refusal, video_native
from tests.browser.conftest import browser  # noqa: F401 (Chromium, one a test process)
from tests.support.clients import HAS_AIORTC

if TYPE_CHECKING:
    from tests.webrtc.peer import Served

NEEDS_AIORTC = f"the WebRTC tests need aiortc: {install_hint('webrtc')}"


@pytest.fixture(autouse=True)
def _an_interface_besides_loopback() -> None:
    """Skip where WebRTC cannot connect: aiortc installed but only a loopback address."""
    if importlib.util.find_spec("aiortc") is not None and not HAS_AIORTC:
        pytest.skip("WebRTC needs an address besides loopback (aiortc offers no 127.0.0.1)")


CONNECT_TIMEOUT_S = 2.0
"""The tests' ICE+DTLS deadline: short, so a peer that never connects is freed soon."""


@pytest.fixture(params=["aiortc", "native", "reactor"])
def stack(request: pytest.FixtureRequest) -> str:
    """Each WebRTC stack of ``--webrtc-stack`` (D51, D70); one skips where it does not import
    (``native``: Python 3.12+)."""
    if (missing := stack_refusal(str(request.param))) is not None:
        pytest.skip(missing)
    return str(request.param)


def video_stack(stack: str) -> str:
    """The stack that sends the video tracks of a server on ``stack`` (D51, D70):
    libdatachannel where it imports (the reactor stack answers data channels only)."""
    return "native" if video_native(stack) else "aiortc"


@pytest.fixture
async def served_on(stack: str) -> AsyncIterator[Served]:
    """An in-process server with WebRTC on its WebSocket port (port 0), on each stack
    (``stack``): every test of a served peer runs on each (``.ci/run`` runs the native
    ones on Python 3.12)."""
    from tests.webrtc.peer import serving  # noqa: PLC0415 (aiortc: after the skip)

    options = WebRtcOptions(connect_timeout_s=CONNECT_TIMEOUT_S, stack=stack)
    async with serving(ServerConfig(port=0, webrtc=options)) as running:
        yield running


@pytest.fixture
def served(served_on: Served) -> Served:
    """``served_on``: the same server, on each stack."""
    return served_on
