"""``--ice-server``: the STUN and TURN URLs aiortc can use, and a clear refusal of the others.

What the servers do for a session behind NAT is test_nat.py's; this is the URL.
"""

from __future__ import annotations

import re

import pytest

from rwt_transports.webrtc.ice import parse_ice_server, parse_ice_servers
from rwt_transports.webrtc.native import native_ice_refusal, native_ice_server, native_missing
from rwt_transports.webrtc.signalling import WebRtcOptions
from tests.support.cli import invoke_rwt
from tests.webrtc.conftest import NEEDS_AIORTC


@pytest.mark.parametrize(
    ("text", "url", "username", "credential"),
    [
        ("stun:stun.example.org", "stun:stun.example.org:3478", None, None),
        ("stun:198.18.3.2:19302", "stun:198.18.3.2:19302", None, None),
        ("turn:robot:pw@turn.example.org", "turn:turn.example.org:3478", "robot", "pw"),
        (
            "TURN:robot:p%3Aw%40x@10.1.2.3:3479?transport=tcp",
            "turn:10.1.2.3:3479?transport=tcp",
            "robot",
            "p:w@x",
        ),
        ("turns:a:b@turn.example.org", "turns:turn.example.org:5349", "a", "b"),
        ("turns:a:b@h:443?transport=tcp", "turns:h:443?transport=tcp", "a", "b"),
    ],
)
def test_accepted_urls_are_ones_aiortc_uses(
    text: str, url: str, username: str | None, credential: str | None
) -> None:
    server = parse_ice_server(text)
    assert (server.url, server.username, server.credential) == (url, username, credential)
    pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)
    from aiortc import RTCIceServer  # noqa: PLC0415 (after the skip)
    from aiortc.rtcicetransport import connection_kwargs  # noqa: PLC0415

    kwargs = connection_kwargs(
        [RTCIceServer(urls=server.url, username=server.username, credential=server.credential)]
    )  # aiortc skips a URL it cannot use without a word: this one it takes
    assert kwargs.get("stun_server") or kwargs.get("turn_server")
    if server.kind == "turn":
        assert (kwargs["turn_username"], kwargs["turn_password"]) == (username, credential)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("stun.example.org", "is not stun:HOST[:PORT] or turn:USER:PASS@HOST"),
        ("http://stun.example.org", "is not stun:HOST[:PORT]"),
        ("stuns:stun.example.org", "aiortc has no STUN over TLS"),
        ("stun:u:p@stun.example.org", "a STUN server takes no USER:PASS@"),
        ("stun:h?transport=udp", "a stun: URL takes no ?transport"),
        ("turn:turn.example.org", "a TURN server needs its credentials"),
        ("turn:robot@turn.example.org", "a TURN server needs its credentials"),
        ("turn:a:b@h?transport=tls", "turn: takes ?transport=udp|tcp only"),
        ("turns:a:b@h?transport=udp", "turns: takes ?transport=tcp only"),
        ("turn:a:b@[2001:db8::1]:3478", "aiortc takes no IPv6 address here"),
        ("stun:h:0", "the port '0' is not a number from 1 to 65535"),
        ("stun:h:http", "the port 'http' is not a number"),
        ("stun:bad_host", "'bad_host' is not a host name or IPv4 address"),
        ("stun:", "'' is not a host name"),
    ],
)
def test_a_url_aiortc_cannot_use_is_refused_with_its_reason(text: str, reason: str) -> None:
    with pytest.raises(ValueError, match=re.escape(reason)):
        parse_ice_server(text)


def test_an_error_never_shows_the_turn_password() -> None:
    for text in (
        "turn:robot:hunter2@h?transport=tls",
        "turn//robot:hunter2@h",
        "turn:a:hunter2@h:0",
    ):
        with pytest.raises(ValueError, match=r"^(?!.*hunter2)"):
            parse_ice_server(text)
    assert "hunter2" not in repr(parse_ice_server("turn:robot:hunter2@h"))
    assert "hunter2" not in repr(WebRtcOptions(ice_servers=("turn:robot:hunter2@h",)))


def test_one_stun_and_one_turn_server_at_most() -> None:
    both = parse_ice_servers(["stun:a", "turns:u:p@b"])
    assert [s.kind for s in both] == ["stun", "turn"]
    for twice in (["stun:a", "stun:b"], ["turn:u:p@a", "turns:u:p@b"]):
        with pytest.raises(ValueError, match="aiortc uses one STUN and one TURN server"):
            parse_ice_servers(twice)
    with pytest.raises(ValueError, match="more than one STUN server"):
        WebRtcOptions(ice_servers=("stun:a", "stun:b"))  # embedded: refused when configured


def test_rwt_serve_refuses_a_bad_ice_server_before_starting() -> None:
    result = invoke_rwt("serve", "--webrtc", "--ice-server", "turn:turn.example.org")
    assert result.exit_code == 2
    assert "--ice-server" in result.output and "needs its credentials" in result.output
    twice = invoke_rwt("serve", "--webrtc", "--ice-server", "stun:a", "--ice-server", "stun:b")
    assert twice.exit_code == 2 and "more than one STUN server" in twice.output
    alone = invoke_rwt("serve", "--ice-server", "stun:a")
    assert alone.exit_code == 2 and "add --webrtc" in alone.output


@pytest.mark.parametrize(
    ("url", "host", "port", "relay"),
    [
        ("stun:stun.example.org", "stun.example.org", 3478, None),
        ("turn:u%40x:p%3Aw@turn.example.org:3479", "turn.example.org", 3479, "TurnUdp"),
        ("turn:u:p@turn.example.org?transport=tcp", "turn.example.org", 3478, "TurnTcp"),
        ("turns:u:p@turn.example.org", "turn.example.org", 5349, "TurnTls"),
    ],
)
def test_the_native_stack_takes_each_ice_server_form(
    url: str, host: str, port: int, relay: str | None
) -> None:
    """``--ice-server``'s forms as libdatachannel's ``IceServer`` (D51): host, port, TURN's
    credentials (percent-decoded) and its transport."""
    if (missing := native_missing()) is not None:
        pytest.skip(missing)
    import libdatachannel  # noqa: PLC0415 (after the skip)

    server = parse_ice_server(url)
    native = native_ice_server(libdatachannel, server)
    assert (native.hostname, native.port) == (host, port)
    assert native.type.name == ("Stun" if relay is None else "Turn")
    if relay is not None:
        assert native.relay_type.name == relay
        assert (native.username, native.password) == (server.username, server.credential)


@pytest.mark.parametrize(
    ("urls", "refused"),
    [
        (["stun:stun.example.org", "turn:u:p@turn.example.org"], None),
        (["turn:u:p@turn.example.org?transport=udp"], None),
        (["turn:u:p@turn.example.org?transport=tcp"], "turn:turn.example.org:3478?transport=tcp"),
        (["stun:a", "turns:u:p@turn.example.org"], "turns:turn.example.org:5349"),
    ],
)
def test_the_native_stack_refuses_a_turn_server_it_reaches_over_tcp_or_tls(
    urls: list[str], refused: str | None
) -> None:
    """libjuice reaches TURN over UDP only (libdatachannel ignores the others): said at start."""
    reason = native_ice_refusal(parse_ice_servers(urls))
    if refused is None:
        assert reason is None
    else:
        assert reason is not None and refused in reason and "--webrtc-stack aiortc" in reason


def test_with_a_tcp_turn_server_auto_answers_on_aiortc_and_native_is_refused_at_start() -> None:
    """``auto`` keeps such a server working (aiortc's ICE speaks TURN over TCP and TLS); an
    explicit ``native`` would never reach it, so it is refused before serving."""
    tcp = ("turn:u:p@turn.example.org?transport=tcp",)
    assert not WebRtcOptions(ice_servers=tcp, stack="auto").native
    assert WebRtcOptions(ice_servers=("turn:u:p@turn.example.org",), stack="auto").native == (
        native_missing() is None
    )
    if (missing := native_missing()) is not None:
        pytest.skip(missing)
    with pytest.raises(ValueError, match="over UDP only"):
        WebRtcOptions(ice_servers=tcp, stack="native")
    result = invoke_rwt("serve", "--webrtc", "--webrtc-stack", "native", "--ice-server", tcp[0])
    assert result.exit_code == 2
    assert "--webrtc-stack native: the native WebRTC stack (libjuice)" in result.output
