"""The WebRTC classes of the attack replays (``benchmarks/attacks.py``): 1, 2, 3, 6, 14, 15.

Every offer is a real aiortc offer (``RTCPeerConnection.createOffer``), posted with
httpx; the peers that must connect are aiortc peers whose ``rosbridge`` data channel
opens. The attacker posts from 127.0.0.1, another host's peer from 127.0.0.2.
"""

from __future__ import annotations

import json
import re
import socket
import time
from collections import Counter
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import anyio
import anyio.to_thread
import httpx
from aiortc import (
    RTCConfiguration,
    RTCPeerConnection,
    RTCRtpReceiver,
    RTCSessionDescription,
)
from aiortc.rtcsctptransport import SCTP_DATA_LAST_FRAG

from .attack_kit import OTHER_HOST, Attack, Context, Outcome
from .attack_robot import camera_publisher
from .servers import proc_stats

__all__ = ["ATTACKS"]

SDP = {"Content-Type": "application/sdp"}
OPEN_S = 10.0
"""Longest wait for a peer's data channel to open (a failure, not a measurement)."""
RETRY_S = 0.25
"""The attacker's pause after a refusal before it posts again."""


async def data_offer() -> str:
    """A real offer with a ``rosbridge`` data channel, its peer closed: it never connects."""
    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    pc.createDataChannel("rosbridge")
    try:
        await pc.setLocalDescription(await pc.createOffer())
        return pc.localDescription.sdp
    finally:
        await pc.close()


async def video_offer() -> str:
    """A WHEP player's offer (one recvonly VP8 transceiver), its peer closed."""
    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    capabilities = RTCRtpReceiver.getCapabilities("video")
    assert capabilities is not None
    vp8 = [c for c in capabilities.codecs if c.mimeType == "video/VP8"]
    pc.addTransceiver("video", direction="recvonly").setCodecPreferences(vp8)
    try:
        await pc.setLocalDescription(await pc.createOffer())
        return pc.localDescription.sdp
    finally:
        await pc.close()


@dataclass
class Inbox:
    """What a peer's ``rosbridge`` channel received; ``arrived`` is set at each message."""

    messages: list[Any] = field(default_factory=list)
    arrived: anyio.Event = field(default_factory=anyio.Event)

    def add(self, message: Any) -> None:
        self.messages.append(message)
        self.arrived.set()

    async def until(self, text: str) -> None:
        """Wait for a text message containing ``text``."""
        while not any(isinstance(m, str) and text in m for m in self.messages):
            self.arrived = anyio.Event()
            await self.arrived.wait()


@asynccontextmanager
async def peer(base: str, host: str) -> AsyncIterator[tuple[RTCPeerConnection, Any, Inbox]]:
    """A real aiortc peer from ``host`` whose ``rosbridge`` channel opened; its messages.

    Raises:
        PermissionError: the offer was refused (its status and text in the message).
        TimeoutError: the channel did not open within ``OPEN_S``.
    """
    pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
    channel = pc.createDataChannel("rosbridge")
    opened = anyio.Event()
    inbox = Inbox()
    channel.on("open", opened.set)
    channel.on("message", inbox.add)
    try:
        await pc.setLocalDescription(await pc.createOffer())
        transport = httpx.AsyncHTTPTransport(local_address=host)
        async with httpx.AsyncClient(base_url=base, transport=transport, timeout=60) as http:
            reply = await http.post("/webrtc", content=pc.localDescription.sdp, headers=SDP)
        if reply.status_code != 201:
            raise PermissionError(f"{reply.status_code} {reply.text.strip()[:100]}")
        await pc.setRemoteDescription(RTCSessionDescription(reply.text, "answer"))
        with anyio.fail_after(OPEN_S):
            await opened.wait()
        yield pc, channel, inbox
    finally:
        await pc.close()


async def _served(channel: Any, inbox: Inbox, call_id: str) -> bool:
    """Whether a ``/rosapi/get_time`` call on ``channel`` is answered within ``OPEN_S``."""
    channel.send(json.dumps({"op": "call_service", "service": "/rosapi/get_time", "id": call_id}))
    with anyio.move_on_after(OPEN_S):
        await inbox.until(f'"{call_id}"')
        return True
    return False


async def other_host_tries(base: str) -> str:
    """Another host's peer: ``connected``, or the status that refused it, or ``timeout``."""
    try:
        async with peer(base, OTHER_HOST) as (_, channel, inbox):
            return "connected" if await _served(channel, inbox, "victim") else "no answer"
    except PermissionError as refused:
        return str(refused).split(" ", 1)[0]
    except TimeoutError:
        return "timeout"


async def _post(http: httpx.AsyncClient, sdp: str, query: str = "") -> httpx.Response:
    return await http.post(f"/webrtc{query}", content=sdp, headers=SDP)


async def _keep_offering(
    context: Context, offers: Callable[[int], tuple[str, str]], statuses: Counter[int]
) -> None:
    """Post offers from 127.0.0.1 until the attack ends, again as soon as one is answered."""
    deadline = time.monotonic() + context.seconds
    n = 0
    async with httpx.AsyncClient(base_url=context.http, timeout=60) as http:
        while time.monotonic() < deadline:
            sdp, query = offers(n)
            n += 1
            reply = await _post(http, sdp, query)
            statuses[reply.status_code] += 1
            if reply.status_code != 201:
                await anyio.sleep(RETRY_S)


# ---- 1: one host's offers that never connect, against another host's peer -------------------


async def _one_host(context: Context) -> Outcome:
    offer = await data_offer()
    statuses: Counter[int] = Counter()
    tries: list[str] = []
    deadline = time.monotonic() + context.seconds

    async def other_host() -> None:
        await anyio.sleep(min(1.0, context.seconds / 4))  # the hog's offers first
        while time.monotonic() < deadline - 0.5:
            started = time.monotonic()
            tries.append(await other_host_tries(context.http))
            await anyio.sleep(max(0.0, 2.0 - (time.monotonic() - started)))

    async with anyio.create_task_group() as tg:
        tg.start_soon(_keep_offering, context, lambda _: (offer, ""), statuses)
        tg.start_soon(other_host)
    connected = tries.count("connected")
    return Outcome(
        {
            "hog offers (127.0.0.1) by status": dict(statuses),
            "other host (127.0.0.2) tries": len(tries),
            "other host connected": connected,
            "other host refusals": dict(Counter(t for t in tries if t != "connected")),
        },
        bool(tries) and connected == len(tries),
        "every try of the other host's peer connected",
    )


# ---- 2: offers of 600 m=video sections ------------------------------------------------------


def media_sections(count: int) -> str:
    """A well-formed offer of ``count`` bundled ``m=video`` sections, under 64 KiB."""
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


SECTION_OFFERS = 16


async def _sections(context: Context) -> Outcome:
    sdp = media_sections(600)
    replies: list[tuple[int, int, str]] = []

    async def offer() -> None:
        async with httpx.AsyncClient(base_url=context.http, timeout=120) as http:
            reply = await _post(http, sdp)
            replies.append((reply.status_code, len(reply.content), reply.text[:90]))

    async with anyio.create_task_group() as tg:
        for _ in range(SECTION_OFFERS):
            tg.start_soon(offer)
    await anyio.sleep(min(2.0, context.seconds))  # what the answered peers keep
    refusals = Counter(text for status, _, text in replies if status != 201)
    return Outcome(
        {
            "offer bytes": len(sdp),
            "offers by status": dict(Counter(status for status, _, _ in replies)),
            "largest answer bytes": max(
                (size for status, size, _ in replies if status == 201), default=0
            ),
            "refusals": dict(refusals),
        },
        all(status == 400 for status, _, _ in replies),
        "every offer refused (400)",
    )


# ---- 3: 4K video offers that never connect --------------------------------------------------

CAMERA = "/bench/camera"
CAMERA_SIZE = (3840, 2160)
CAMERA_HZ = 5.0
VIDEO_OFFERS = 16
CPU_MARGIN = 0.3
"""Cores of server CPU over the baseline's that the never-connecting offers may take
(answers, DTLS and ICE; an encoder of the 4K camera alone takes more than a core here)."""


async def _camera(context: Context) -> None:
    await context.stack.enter_async_context(
        camera_publisher(context.ws_url, CAMERA, CAMERA_SIZE, CAMERA_HZ)
    )


async def _video_offers(context: Context) -> Outcome:
    offer = await video_offer()
    statuses: Counter[int] = Counter()
    cpu = proc_stats(context.pid).cpu_s
    started = time.monotonic()

    def distinct(n: int) -> tuple[str, str]:  # a stream each: an encoder each (16: the cap)
        return offer, f"?video={CAMERA}&bitrate={1_000_000 + n % VIDEO_OFFERS * 1000}"

    async with anyio.create_task_group() as tg:
        for n in range(VIDEO_OFFERS):
            tg.start_soon(_keep_offering, context, lambda k, n=n: distinct(n + k), statuses)
    cores = (proc_stats(context.pid).cpu_s - cpu) / (time.monotonic() - started)
    extra = cores - context.baseline_cores
    return Outcome(
        {
            "offers by status": dict(statuses),
            "server cores, baseline (camera publishing)": round(context.baseline_cores, 2),
            "server cores, attack": round(cores, 2),
        },
        extra <= CPU_MARGIN,
        f"the offers took at most {CPU_MARGIN} core over the baseline (no encoder ran)",
    )


# ---- 6: data channel messages past the answer's bounds --------------------------------------

HUGE = 8 * 1024 * 1024
NEVER_ENDING = 4 * 1024 * 1024


def _bend(pc: RTCPeerConnection, withheld: int) -> None:
    """Make ``pc``'s SCTP send past the answer's ``a=max-message-size``, and never send the
    last fragment of a message of ``withheld`` bytes: a hostile stack."""
    sctp = pc.sctp
    assert sctp is not None
    sctp._remote_max_message_size = 0  # 0: no bound (aiortc's own refuses to send more)
    send = sctp._send

    async def send_all_but_last(stream_id: int, pp_id: int, data: bytes, *a: Any, **k: Any) -> None:
        await send(stream_id, pp_id, data, *a, **k)
        if len(data) == withheld:
            queue = sctp._outbound_queue
            last = next(c for c in reversed(queue) if c.flags & SCTP_DATA_LAST_FRAG)
            queue.remove(last)

    sctp._send = send_all_but_last  # type: ignore[method-assign,assignment]


async def _sctp(context: Context) -> Outcome:
    facts: dict[str, Any] = {}
    ok = False
    try:
        async with peer(context.http, "127.0.0.1") as (pc, channel, inbox):
            _bend(pc, NEVER_ENDING)
            deadline = time.monotonic() + context.seconds
            channel.send(b"\x00" * HUGE)
            channel.send(b"\x00" * NEVER_ENDING)
            served = False
            while time.monotonic() < deadline and not served:
                served = await _served(channel, inbox, f"after{len(inbox.messages)}")
            statuses = [m for m in inbox.messages if isinstance(m, str) and '"status"' in m]
            facts = {
                "messages sent (bytes)": [HUGE, f"{NEVER_ENDING} without its last fragment"],
                "error statuses": [json.loads(s).get("msg", "")[:90] for s in statuses],
                "a call after them answered": served,
            }
            ok = served and len(statuses) >= 2
            await anyio.sleep(max(0.0, deadline - time.monotonic()))
    except (PermissionError, TimeoutError) as error:
        facts = {"peer": f"{type(error).__name__}: {error}"}
    return Outcome(facts, ok, "both messages refused with an error status, the channel served on")


# ---- 14: an offer of 800 candidates ---------------------------------------------------------

CANDIDATES = 800
FIRST_PORT = 42000


def _listeners(address: str) -> list[socket.socket]:
    socks = []
    for n in range(CANDIDATES):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind((address, FIRST_PORT + n))
        sock.setblocking(False)
        socks.append(sock)
    return socks


def _count(socks: list[socket.socket]) -> tuple[int, int]:
    """Datagrams waiting on ``socks`` (read now), and how many sockets got any."""
    total, reached = 0, 0
    for sock in socks:
        got = 0
        with suppress(BlockingIOError):
            while True:
                sock.recv(2048)
                got += 1
        total += got
        reached += got > 0
    return total, reached


def _server_address() -> str:
    """This machine's address besides loopback (the one the server's candidates have)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect(("192.0.2.1", 9))  # no packet: only picks the route's source address
        return str(probe.getsockname()[0])


async def _candidates(context: Context) -> Outcome:
    address = _server_address()
    socks = _listeners(address)
    try:
        offer = await data_offer()
        lines = [
            f"a=candidate:c{n} 1 udp 2130706431 {address} {FIRST_PORT + n} typ host"
            for n in range(CANDIDATES)
        ]
        sdp = offer.replace("a=end-of-candidates", "\r\n".join([*lines, "a=end-of-candidates"]), 1)
        async with httpx.AsyncClient(base_url=context.http, timeout=60) as http:
            reply = await _post(http, sdp)
        total, reached = 0, 0
        deadline = time.monotonic() + context.seconds
        while time.monotonic() < deadline:
            await anyio.sleep(0.2)
            got, hit = _count(socks)
            total, reached = total + got, max(reached, hit)
        return Outcome(
            {
                "offer bytes": len(sdp),
                "status": reply.status_code,
                "reason": reply.text.strip()[:120] if reply.status_code != 201 else "",
                "STUN packets the server sent to the candidates": total,
                "candidate ports reached": reached,
            },
            reply.status_code == 400 and total == 0,
            "the offer refused (400) and no packet sent to its candidates",
        )
    finally:
        for sock in socks:
            sock.close()


# ---- 15: malformed offers -------------------------------------------------------------------


def _sub(pattern: str, replacement: str) -> Callable[[str], str]:
    return lambda sdp: re.sub(pattern, replacement, sdp, count=1, flags=re.MULTILINE)


def _drop(prefix: str) -> Callable[[str], str]:
    return lambda sdp: "\r\n".join(x for x in sdp.split("\r\n") if not x.startswith(prefix))


_CANDIDATE = r"^(a=candidate:\S+ 1 udp \d+) (\S+) (\d+)"
MALFORMED: dict[str, Callable[[str], str]] = {
    "no a=setup": _drop("a=setup"),
    "a=setup:holdconn": _sub("^a=setup:.*$", "a=setup:holdconn"),
    "no fingerprint": _drop("a=fingerprint"),
    "a bad digest": _sub("^a=fingerprint:sha-256 .*$", "a=fingerprint:sha-256 ZZ"),
    "a 2-letter ufrag": _sub("^a=ice-ufrag:.*$", "a=ice-ufrag:ab"),
    "a ufrag with spaces": _sub("^a=ice-ufrag:.*$", "a=ice-ufrag:a b!c"),
    "a 1-letter pwd": _sub("^a=ice-pwd:.*$", "a=ice-pwd:x"),
    "candidate port 99999": _sub(_CANDIDATE, r"\1 \2 99999"),
    "candidate port 0": _sub(_CANDIDATE, r"\1 \2 0"),
    "candidate type": _sub("typ host", "typ bogus"),
    "candidate DNS name": _sub(_CANDIDATE, r"\1 example.com \3"),
    "candidate priority": _sub(r"^(a=candidate:\S+ 1 udp) \d+", r"\1 -5"),
    "candidate transport": _sub(r"^(a=candidate:\S+ 1) udp", r"\1 sctp"),
    "candidate loopback": _sub(_CANDIDATE, r"\1 127.0.0.1 \3"),
    "candidate broadcast": _sub(_CANDIDATE, r"\1 255.255.255.255 \3"),
    "candidate multicast": _sub(_CANDIDATE, r"\1 224.0.0.1 \3"),
    "candidate 0.0.0.0": _sub(_CANDIDATE, r"\1 0.0.0.0 \3"),
    "candidate too short": _sub("^a=candidate:.*$", "a=candidate:1 1 udp"),
    "no a=sctp-port": _drop("a=sctp-port"),
    "a=sctp-port:99999": _sub("^a=sctp-port:.*$", "a=sctp-port:99999"),
    "max-message-size -1": _sub("^a=max-message-size:.*$", "a=max-message-size:-1"),
    "m=application RTP": _sub(r"^m=application (\d+) \S+", r"m=application \1 RTP/AVP"),
    "m=application x": _sub("^m=application .*$", "m=application x"),
    "no a=mid": _drop("a=mid"),
    "BUNDLE of no mid": _sub("^a=group:BUNDLE .*$", "a=group:BUNDLE 7"),
    "no o=": _drop("o="),
    "no t=": _drop("t="),
    "a line without =": _sub("^a=mid", "garbage\r\na=mid"),
    "a NUL byte": _sub("^s=-", "s=\x00"),
    "m=text": _sub("^m=application", "m=text"),
}


async def _malformed(context: Context) -> Outcome:
    offer = await data_offer()
    answered: list[str] = []
    statuses: Counter[int] = Counter()
    unclear: list[str] = []
    async with httpx.AsyncClient(base_url=context.http, timeout=60) as http:
        for name, mutate in MALFORMED.items():
            reply = await _post(http, mutate(offer))
            statuses[reply.status_code] += 1
            if reply.status_code == 201:
                answered.append(name)
            elif "the offer is not a usable SDP offer" not in reply.text:
                unclear.append(f"{name}: {reply.status_code} {reply.text.strip()[:60]!r}")
    tries = []
    deadline = time.monotonic() + context.seconds
    while time.monotonic() < deadline - 0.5:  # another host's peer, while answered ones are held
        started = time.monotonic()
        tries.append(await other_host_tries(context.http))
        await anyio.sleep(max(0.0, 2.0 - (time.monotonic() - started)))
    log = context.log.read_text(errors="replace")
    tracebacks = log.count("Traceback (most recent call last)")
    return Outcome(
        {
            "offers": len(MALFORMED),
            "by status": dict(statuses),
            "answered 201 (each holds a connecting slot)": answered,
            "refused without a reason": unclear,
            "other host's peer": dict(Counter(tries)),
            "tracebacks in the log": tracebacks,
        },
        not answered and not unclear and not tracebacks and set(tries) == {"connected"},
        "all 400 with the SDP reason, no traceback, the other host's peer connected",
    )


def _webrtc(_: Path) -> list[str]:
    return ["--webrtc", "--no-tf"]


ATTACKS = [
    Attack(
        "1",
        "one host's never-connecting WebRTC offers vs another host's peer",
        _webrtc,
        _one_host,
        "20 s instead of 40: the hog posts again as soon as an offer is answered, and 4 times "
        "a second while refused; the other host's aiortc peer tries every 2 s",
    ),
    Attack(
        "2",
        "16 offers of 600 m=video sections at once",
        _webrtc,
        _sections,
        "one round of 16 at once (the issue: three rounds)",
        bound=(32 * 1024 * 1024, "D38: an offer is checked before anything is built (32 MB slack)"),
    ),
    Attack(
        "3",
        "4K video offers that never connect",
        _webrtc,
        _video_offers,
        "20 s; a 3840x2160 mono8 camera at 5 Hz (published over the WebSocket, CBOR) from the "
        "start of the baseline; 16 offers of distinct streams, posted again as slots free",
        bound=(32 * 1024 * 1024, "D37: nothing runs for a peer that never connects (32 MB slack)"),
        setup=_camera,
    ),
    Attack(
        "6",
        "data channel messages past the answer's bounds",
        _webrtc,
        _sctp,
        "one 8 MB message and one of 4 MB whose last fragment never comes, from a bent aiortc",
        bound=(
            16 * 1024 * 1024 + 32 * 1024 * 1024,
            "D39: the inbox bound INBOX_LIMIT_BYTES, 16 MiB (+32 MB slack)",
        ),
        seconds=15.0,
    ),
    Attack(
        "14",
        "an offer of 800 candidates",
        _webrtc,
        _candidates,
        "one offer of 800 UDP candidates, all on this machine's address (800 ports, each a "
        "socket counting what arrives) instead of 706 addresses elsewhere; watched 15 s",
        seconds=15.0,
    ),
    Attack(
        "15",
        "30 malformed SDP offers",
        _webrtc,
        _malformed,
        "each of the 30 once, then another host's peer every 2 s for 15 s",
        seconds=15.0,
    ),
]
