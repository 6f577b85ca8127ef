"""Hostile WebRTC offers: refused before the server builds or holds anything (docs/webrtc.md).

D37: one host cannot take every connecting slot. D38: an offer is checked before a
slot is held: well-formed SDP, bounded media sections and candidates, and candidates
that cannot point the server's STUN checks at loopback, broadcast or hundreds of hosts.
Real aiortc peers make the offers these are cut from.
"""

from __future__ import annotations

import logging
import re
from collections.abc import AsyncIterator, Callable

import httpx
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)


from rwt_transports.admission.shares import SHARES_FROM
from rwt_transports.server import ServerConfig
from rwt_transports.webrtc.offer import (
    MAX_CANDIDATE_ADDRESSES,
    MAX_MEDIA_SECTIONS,
    MAX_SECTION_CANDIDATES,
)
from rwt_transports.webrtc.peers import MAX_CONNECTING
from rwt_transports.webrtc.signalling import MAX_OFFER_BYTES, WebRtcOptions
from tests.support.clients import HAS_AIORTC
from tests.webrtc.peer import Served, closed_offer, peers_of, rtc_client, serving

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.skipif(not HAS_AIORTC, reason="WebRTC needs an address besides loopback"),
]

SDP = {"Content-Type": "application/sdp"}


@pytest.fixture(scope="module")
async def offer() -> str:
    """A real offer with a ``rosbridge`` data channel (its peer closed: never connects)."""
    return await closed_offer()


@pytest.fixture(scope="module")
async def served() -> AsyncIterator[Served]:
    """One server for the refusals: a refused offer holds nothing."""
    async with serving(ServerConfig(port=0, webrtc=WebRtcOptions(connect_timeout_s=2))) as s:
        yield s


async def post(served: Served, sdp: str) -> httpx.Response:
    async with httpx.AsyncClient(base_url=served.base, timeout=30) as http:
        return await http.post("/webrtc", content=sdp, headers=SDP)


def held(served: Served) -> tuple[int, int, int]:
    """Connecting slots, peers and connection slots held (a refused offer adds to none)."""
    peers = peers_of(served.server)
    return peers.connecting, len(peers.peers), served.server.slots_taken


def added_nothing(served: Served, before: tuple[int, int, int]) -> bool:
    """Nothing is held that was not before (an answered peer of another test may go)."""
    return all(now <= then for now, then in zip(held(served), before, strict=True))


async def test_one_host_cannot_keep_another_hosts_peer_out(offer: str) -> None:
    # answered peers that never connect hold their slots (60 s here); one address
    # posting them used to take all MAX_CONNECTING and keep every other host out
    config = ServerConfig(port=0, webrtc=WebRtcOptions(connect_timeout_s=60))
    async with serving(config) as served, httpx.AsyncClient(base_url=served.base) as http:
        answered = 0
        for _ in range(MAX_CONNECTING):
            reply = await http.post("/webrtc", content=offer, headers=SDP)
            if reply.status_code != 201:
                break
            answered += 1
        assert reply.status_code == 503 and "too many WebRTC peers connecting" in reply.text
        assert answered == int(MAX_CONNECTING * SHARES_FROM)  # the rest: other hosts'
        async with rtc_client(served.base, local_address="127.0.0.2") as other:
            other.send({"op": "call_service", "service": "/rosapi/nodes", "id": "b"})
            assert (await other.next_op("service_response"))["result"] is True


def media_sections(count: int) -> str:
    """An offer of ``count`` bundled ``m=video`` sections, well-formed, under 64 KiB."""
    head = [
        "v=0",
        "o=- 1 1 IN IP4 0.0.0.0",
        "s=-",
        "t=0 0",
        "a=group:BUNDLE " + " ".join(str(n) for n in range(count)),
        "a=ice-ufrag:abcd",
        "a=ice-pwd:abcdefghijklmnopqrstuvwx",
        "a=fingerprint:sha-256 " + ":".join(["AB"] * 32),
        "a=setup:actpass",
    ]
    section = "m=video 9 UDP/TLS/RTP/SAVPF 96\r\na=mid:{}\r\na=recvonly\r\na=rtcp-mux\r\n"
    sections = "".join(section.format(n) + "a=rtpmap:96 VP8/90000\r\n" for n in range(count))
    return "\r\n".join(head) + "\r\n" + sections


async def test_an_offer_with_600_media_sections_is_refused_before_aiortc_builds_it(
    served: Served,
) -> None:
    sdp = media_sections(600)
    assert len(sdp) <= MAX_OFFER_BYTES  # within the byte bound: the sections are what count
    before = held(served)
    reply = await post(served, sdp)
    assert reply.status_code == 400
    assert f"more than {MAX_MEDIA_SECTIONS} media sections" in reply.text
    assert added_nothing(served, before)


def with_candidates(offer: str, lines: list[str]) -> str:
    """``offer`` with ``lines`` (``a=candidate:...``) added to its data channel section."""
    return offer.replace("a=end-of-candidates", "\r\n".join([*lines, "a=end-of-candidates"]), 1)


def candidate(n: int, address: str, port: int = 40000, rest: str = "typ host") -> str:
    return f"a=candidate:c{n} 1 udp 2130706431 {address} {port} {rest}"


async def test_800_candidates_cannot_point_the_servers_checks_at_706_hosts(
    served: Served, offer: str
) -> None:
    lines = [candidate(n, f"198.51.{n // 250}.{n % 250 + 1}", 1024 + n) for n in range(800)]
    sdp = with_candidates(offer, lines)
    assert 40_000 < len(sdp) <= MAX_OFFER_BYTES
    before = held(served)
    reply = await post(served, sdp)
    assert reply.status_code == 400
    assert f"the candidates name more than {MAX_CANDIDATE_ADDRESSES} addresses" in reply.text
    assert added_nothing(served, before)
    ports = with_candidates(offer, [candidate(n, "203.0.113.5", 1024 + n) for n in range(40)])
    reply = await post(served, ports)  # one address, as many ports
    assert reply.status_code == 400
    assert f"more than {MAX_SECTION_CANDIDATES} candidates in media section 1" in reply.text


async def test_an_offer_names_at_most_a_few_addresses_for_the_servers_checks(
    served: Served, offer: str
) -> None:
    addresses = [f"203.0.113.{n}" for n in range(1, MAX_CANDIDATE_ADDRESSES + 1)]
    many = with_candidates(offer, [candidate(n, a) for n, a in enumerate(addresses)])
    before = held(served)
    reply = await post(served, many)
    assert reply.status_code == 400
    assert f"the candidates name more than {MAX_CANDIDATE_ADDRESSES} addresses" in reply.text
    assert added_nothing(served, before)


async def test_a_browsers_kinds_of_candidates_are_answered(served: Served, offer: str) -> None:
    # what Chromium offers with a STUN and a TURN server: TCP host candidates (port 9,
    # never checked), its public address (srflx, raddr hidden) and a relayed one
    browser = [
        "a=candidate:t1 1 tcp 1518280447 192.0.2.77 9 typ host tcptype active generation 0",
        candidate(2, "203.0.113.7", 40001, "typ srflx raddr 0.0.0.0 rport 0 generation 0"),
        candidate(3, "198.51.100.9", 50001, "typ relay raddr 203.0.113.7 rport 40001"),
    ]
    reply = await post(served, with_candidates(offer, browser))
    assert reply.status_code == 201, reply.text


def sub(pattern: str, replacement: str) -> Callable[[str], str]:
    return lambda sdp: re.sub(pattern, replacement, sdp, flags=re.MULTILINE)


def drop(prefix: str) -> Callable[[str], str]:
    return lambda sdp: "\r\n".join(x for x in sdp.split("\r\n") if not x.startswith(prefix))


CANDIDATE = r"^(a=candidate:\S+ 1 udp \d+) (\S+) (\d+)"

# each was answered 201 and held a connecting slot until the connect deadline (or
# was refused with aiortc's words: "'NoneType' object has no attribute 'role'", "")
MALFORMED = {
    "no a=setup": (drop("a=setup"), "has no a=setup"),
    "a=setup:holdconn": (sub("^a=setup:.*$", "a=setup:holdconn"), "is not actpass"),
    "no fingerprint": (drop("a=fingerprint"), "has no DTLS fingerprint"),
    "a bad digest": (sub("^a=fingerprint:sha-256 .*$", "a=fingerprint:sha-256 ZZ"), "digest"),
    "a 2-letter ufrag": (sub("^a=ice-ufrag:.*$", "a=ice-ufrag:ab"), "a=ice-ufrag must be"),
    "a ufrag with spaces": (sub("^a=ice-ufrag:.*$", "a=ice-ufrag:a b!c"), "a=ice-ufrag must"),
    "a 1-letter pwd": (sub("^a=ice-pwd:.*$", "a=ice-pwd:x"), "a=ice-pwd must be"),
    "candidate port 99999": (sub(CANDIDATE, r"\1 \2 99999"), "candidate port '99999'"),
    "candidate port 0": (sub(CANDIDATE, r"\1 \2 0"), "candidate port '0'"),
    "candidate type": (sub("typ host", "typ bogus"), "candidate type 'bogus'"),
    "candidate DNS name": (sub(CANDIDATE, r"\1 example.com \3"), "an mDNS name"),
    "candidate priority": (sub(r"^(a=candidate:\S+ 1 udp) \d+", r"\1 -5"), "priority '-5'"),
    "candidate transport": (sub(r"^(a=candidate:\S+ 1) udp", r"\1 sctp"), "transport 'sctp'"),
    "candidate loopback": (sub(CANDIDATE, r"\1 127.0.0.1 \3"), "loopback"),
    "candidate broadcast": (sub(CANDIDATE, r"\1 255.255.255.255 \3"), "reserved address"),
    "candidate multicast": (sub(CANDIDATE, r"\1 224.0.0.1 \3"), "multicast"),
    "candidate 0.0.0.0": (sub(CANDIDATE, r"\1 0.0.0.0 \3"), "unspecified"),
    "candidate too short": (sub("^a=candidate:.*$", "a=candidate:1 1 udp"), "is not <foundation>"),
    "no a=sctp-port": (drop("a=sctp-port"), "has no a=sctp-port"),
    "a=sctp-port:99999": (sub("^a=sctp-port:.*$", "a=sctp-port:99999"), "is not 1-65535"),
    "max-message-size -1": (sub("^a=max-message-size:.*$", "a=max-message-size:-1"), "bytes"),
    "m=application RTP": (sub(r"^m=application (\d+) \S+", r"m=application \1 RTP/AVP"), "a data"),
    "m=application x": (sub("^m=application .*$", "m=application x"), "is not m=<kind>"),
    "no a=mid": (drop("a=mid"), "has no a=mid"),
    "BUNDLE of no mid": (sub("^a=group:BUNDLE .*$", "a=group:BUNDLE 7"), "no section's a=mid"),
    "no o=": (drop("o="), "has no o= line"),
    "no t=": (drop("t="), "has no t= line"),
    "a line without =": (sub("^a=mid", "garbage\r\na=mid"), "is not a <type>=<value> line"),
    "a NUL byte": (sub("^s=-", "s=\x00"), "a control character"),
    "m=text": (sub("^m=application", "m=text"), "the server answers audio, video and"),
}


@pytest.mark.parametrize("name", MALFORMED)
async def test_a_malformed_offer_gets_400_with_its_reason_and_holds_nothing(
    served: Served, offer: str, name: str, caplog: pytest.LogCaptureFixture
) -> None:
    mutate, reason = MALFORMED[name]
    sdp = mutate(offer)
    assert sdp != offer
    before = held(served)
    with caplog.at_level(logging.WARNING):
        reply = await post(served, sdp)
    assert reply.status_code == 400, reply.text
    assert "the offer is not a usable SDP offer" in reply.text and reason in reply.text
    assert added_nothing(served, before)
    assert not [r for r in caplog.records if r.exc_info or r.name == "asyncio"]
