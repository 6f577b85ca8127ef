"""``rwt serve --webrtc`` as a user runs it, with and without ``--auth-secret-file``.

With a secret, an offer either carries a live video token (``/rwt/video_token``)
as ``Authorization: Bearer``, or its channel's first op is ``auth``, as on the
WebSocket (docs/webrtc.md, D23).
"""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

from rwt_protocol.auth import rosauth_mac
from tests.support.cli import rwt_serve
from tests.webrtc.peer import rtc_client

pytestmark = pytest.mark.anyio

SECRET = "1234567890abcdef"


def auth_op() -> dict[str, object]:
    now = time.time()
    fields = {
        "client": "127.0.0.1",
        "dest": "127.0.0.1",
        "rand": "fresh-random-string",
        "t": int(now - 1),
        "level": "user",
        "end": int(now + 60),
    }
    return {"op": "auth", "mac": rosauth_mac(SECRET, **fields), **fields}  # type: ignore[arg-type]


async def test_rwt_serve_webrtc_with_auth_op_bearer_token_and_bad_token(tmp_path: Path) -> None:
    secret = tmp_path / "secret"
    secret.write_text(SECRET)
    args = ("--port", "0", "--webrtc", "--auth-secret-file", str(secret))
    async with rwt_serve(*args) as (_, urls):
        base = urls["ws"].replace("ws://", "http://")
        async with rtc_client(base) as anonymous:  # no token: ops wait for auth
            anonymous.send({"op": "call_service", "service": "/rosapi/topics", "id": "early"})
            refused = await anonymous.next_op("service_response")
            assert refused["result"] is False and "authentication" in str(refused["values"])
        async with rtc_client(base) as client:
            client.send(auth_op())
            client.send({"op": "call_service", "service": "/rwt/video_token", "id": "t"})
            reply = await client.next_op("service_response")
            assert reply["result"] is True
            token = reply["values"]["message"]  # type: ignore[index]
        async with rtc_client(base, headers={"Authorization": f"Bearer {token}"}) as bearer:
            bearer.send({"op": "call_service", "service": "/rosapi/topics", "id": "b"})
            answered = await bearer.next_op("service_response")
            assert answered["id"] == "b" and answered["result"] is True
        async with httpx.AsyncClient(base_url=base) as http:
            bad = await http.post(
                "/webrtc",
                content="v=0\r\n",
                headers={"Content-Type": "application/sdp", "Authorization": "Bearer wrong"},
            )
        assert bad.status_code == 401 and "/rwt/video_token" in bad.text
