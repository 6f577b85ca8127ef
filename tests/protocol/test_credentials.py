"""One ``AuthMode`` per way of proving who you are, and the one check every entry goes through.

``rwt_protocol.credentials``: the same texts and statuses for a mode wherever it is
checked (a WebSocket handshake, a WebRTC offer, MCP, the HTTP API, the video server).
"""

from __future__ import annotations

import logging

import pytest

from rwt_protocol import credentials
from rwt_protocol.auth import auth_query, rosauth_op
from rwt_protocol.credentials import AuthMode, EntryAuth, bearer, op_refusal, video_token
from rwt_protocol.ops import Auth
from rwt_protocol.ratelog import EpisodeLog

LIVE = "live-token"
OP = rosauth_op("s" * 16, client="c", dest="d", rand="r", t=0, level="admin", end=10)


def _admits(op: Auth, peer: str) -> bool:
    return op.mac == OP.mac


ENTRY = EntryAuth(required=True, ops=_admits, token=lambda token: token == LIVE)


def test_the_bearer_header_is_read_once_as_rfc_6750_says() -> None:
    assert bearer({"authorization": "Bearer  abc "}) == "abc"
    assert bearer({"authorization": "bearer abc"}) == "abc"
    assert bearer({"authorization": "Basic abc"}) is None
    assert bearer({"authorization": "Bearer "}) is None
    assert bearer({}) is None
    # a video token: the query's first (the last one given), else the bearer's
    assert video_token({"authorization": "Bearer b"}, "token=a&token=q") == "q"
    assert video_token({"authorization": "Bearer b"}, "token=") == "b"
    assert video_token({}, "%zz") is None


@pytest.mark.parametrize(
    ("mode", "headers", "query", "status", "text"),
    [
        (AuthMode.BEARER, {}, "", 401, "a bearer token is needed: call /rwt/video_token"),
        (AuthMode.BEARER, {"authorization": "Bearer x"}, "", 401, "wrong or expired"),
        (AuthMode.BEARER, {}, f"token={LIVE}", 401, "Authorization: Bearer <token>"),
        (AuthMode.VIDEO_TOKEN, {}, "", 401, "a video token is needed"),
        (AuthMode.VIDEO_TOKEN, {}, "token=x", 403, "the video token is wrong or expired"),
        (AuthMode.URL_TOKEN, {}, "", 401, "authentication required: add the token to the URL"),
        (AuthMode.URL_TOKEN, {}, "mac=1", 403, "authentication failed: auth query:"),
        (AuthMode.URL_TOKEN, {}, auth_query(OP).replace("mac=", "mac=0"), 403, "failed"),
    ],
)
def test_each_mode_refuses_with_its_own_status_and_text(
    mode: AuthMode, headers: dict[str, str], query: str, status: int, text: str
) -> None:
    refusal = ENTRY.check(mode, "1.2.3.4:5", headers=headers, query=query, now=0.0)
    assert refusal is not None and refusal.status == status and text in refusal.text


def test_a_valid_proof_passes_and_the_modes_without_one_at_entry_pass_through() -> None:
    check = ENTRY.check
    assert check(AuthMode.BEARER, "p", headers={"authorization": f"Bearer {LIVE}"}, now=0) is None
    assert check(AuthMode.VIDEO_TOKEN, "p", query=f"token={LIVE}", now=0) is None
    assert check(AuthMode.URL_TOKEN, "p", query=auth_query(OP), now=0) is None
    assert check(AuthMode.OP, "p", now=0) is None  # the session asks for the op
    assert check(AuthMode.NONE, "p", now=0) is None  # /version (D49)
    assert EntryAuth().check(AuthMode.BEARER, "p", now=0) is None  # nothing required


def test_an_auth_op_is_checked_once_for_the_session_and_the_url(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a new episode: another test's failing authenticator may have opened this one
    monkeypatch.setattr(credentials, "_episodes", EpisodeLog(credentials.logger))
    assert op_refusal(_admits, OP, "p", now=0) is None
    assert op_refusal(_admits, OP, "p", nonce="other", now=0) == (
        "rand is not this connection's auth_challenge"
    )

    def broken(op: Auth, peer: str) -> bool:
        raise RuntimeError("a bug in embedding code")

    with caplog.at_level(logging.ERROR, logger="rwt.server"):
        assert op_refusal(broken, OP, "p", now=0) == "refused by the authenticator"
    assert "event=authenticator_failed" in caplog.text
