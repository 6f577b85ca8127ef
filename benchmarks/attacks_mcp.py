"""The MCP classes of the attack replays (``benchmarks/attacks.py``): 4, 5, 7-13.

Agents are the official MCP client (``mcp``, Streamable HTTP); attackers that speak
HTTP badly on purpose are raw httpx. The attacker is 127.0.0.1; another host's
clients come from 127.0.0.2, the robot (``benchmarks/attack_robot.py``) from 127.0.0.3.
"""

from __future__ import annotations

import io
import json
import time
from collections import Counter
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import httpx
import httpx2
from mcp import ClientSession
from mcp.client.streamable_http import streamable_http_client
from mcp.shared.exceptions import MCPError
from mcp.types import ImageContent, TextContent
from PIL import Image
from websockets.asyncio.client import connect

from .attack_kit import OTHER_HOST, Attack, Context, Outcome
from .attack_robot import compressed_publisher, topics_advertised
from .bystander import auth_op
from .servers import proc_stats

__all__ = ["ATTACKS"]

ACCEPT = {"Accept": "application/json, text/event-stream", "Content-Type": "application/json"}
VERSION = "2025-06-18"
INITIALIZE = {
    "jsonrpc": "2.0",
    "id": 1,
    "method": "initialize",
    "params": {
        "protocolVersion": VERSION,
        "capabilities": {},
        "clientInfo": {"name": "attacker", "version": "0"},
    },
}
INITIALIZED = {"jsonrpc": "2.0", "method": "notifications/initialized"}
WAIT_S = 60.0
"""A bound on one request's wait: a hang, not a measurement."""


def _endpoint(context: Context) -> str:
    return context.http + "/mcp"


async def open_raw(
    http: httpx.AsyncClient, endpoint: str, headers: dict[str, str] | None = None
) -> tuple[int, dict[str, str] | None]:
    """Open a session with raw requests: the status of ``initialize`` and the session's headers."""
    opened = await http.post(endpoint, json=INITIALIZE, headers={**ACCEPT, **(headers or {})})
    if opened.status_code != 200:
        return opened.status_code, None
    session = {
        **ACCEPT,
        **(headers or {}),
        "Mcp-Session-Id": opened.headers["Mcp-Session-Id"],
        "Mcp-Protocol-Version": VERSION,
    }
    await http.post(endpoint, json=INITIALIZED, headers=session)
    return 200, session


@asynccontextmanager
async def agent(endpoint: str) -> AsyncIterator[ClientSession]:
    """The official MCP client, initialized; its session ends with the context."""
    http = httpx2.AsyncClient(timeout=httpx2.Timeout(WAIT_S, read=300))
    async with (
        http,
        streamable_http_client(endpoint, http_client=http) as (read, write),
        ClientSession(read, write) as session,
    ):
        await session.initialize()
        yield session


def _text(result: Any) -> str:
    return " ".join(b.text for b in result.content if isinstance(b, TextContent))


async def _until(deadline: float, call: Callable[[], Awaitable[str]], tally: Counter[str]) -> None:
    """``call`` back to back until ``deadline``, each answer's kind counted in ``tally``."""
    while time.monotonic() < deadline:
        with anyio.move_on_after(max(0.1, deadline - time.monotonic() + 5)):
            tally[await call()] += 1


# ---- 4: MCP calls in flight under a low descriptor limit ------------------------------------

NOFILE = 256  # --max-connections 256 - 128 - 16 = 112, shares past 84
HOG_SESSIONS = 32
CALLS_PER_SESSION = 8  # 256 sockets, all the descriptors
NEWCOMER_LIMIT_S = 1.0


async def _held_echo(
    http: httpx.AsyncClient,
    endpoint: str,
    session: dict[str, str],
    n: int,
    heads: Counter[str],
) -> None:
    """An ``echo`` of a quiet topic: its request holds a socket until it times out."""
    call = {
        "jsonrpc": "2.0",
        "id": n,
        "method": "tools/call",
        "params": {
            "name": "echo",
            "arguments": {"topic": "/quiet", "type": "std_msgs/msg/String", "timeout_s": 30},
        },
    }
    try:
        async with http.stream("POST", endpoint, json=call, headers=session) as reply:
            heads[str(reply.status_code)] += 1
            await reply.aread()
    except httpx.HTTPError as error:
        heads[type(error).__name__] += 1


async def _newcomer(ws_url: str) -> float:
    """Seconds another host's new WebSocket client waits for its first answer."""
    started = time.monotonic()
    async with connect(ws_url, local_addr=(OTHER_HOST, 0), open_timeout=WAIT_S) as ws:
        await ws.send(json.dumps({"op": "call_service", "service": "/rosapi/get_time", "id": "n"}))
        while '"n"' not in str(await ws.recv()):
            pass
    return time.monotonic() - started


async def _descriptors(context: Context) -> Outcome:
    endpoint = _endpoint(context)
    heads: Counter[str] = Counter()
    opened: Counter[int] = Counter()
    waits: list[float] = []
    limits = httpx.Limits(max_connections=None, max_keepalive_connections=0)
    deadline = time.monotonic() + context.seconds
    async with (
        httpx.AsyncClient(timeout=WAIT_S, limits=limits) as http,
        anyio.create_task_group() as tg,
    ):

        async def hog() -> None:
            calls = 0
            for _ in range(HOG_SESSIONS):
                status, session = await open_raw(http, endpoint)
                opened[status] += 1
                if session is None:
                    continue
                for _ in range(CALLS_PER_SESSION):
                    calls += 1
                    tg.start_soon(_held_echo, http, endpoint, session, calls, heads)

        tg.start_soon(hog)
        await anyio.sleep(min(3.0, context.seconds / 4))  # the calls are held
        while time.monotonic() < deadline - 1.0:
            started = time.monotonic()
            with anyio.move_on_after(deadline - started) as waited:
                waits.append(await _newcomer(context.ws_url))
            if waited.cancelled_caught:  # still waiting when the attack ended
                waits.append(time.monotonic() - started)
                break
            await anyio.sleep(1.0)
        await anyio.sleep(max(0.0, deadline - time.monotonic()))
        tg.cancel_scope.cancel()
    log = context.log.read_text(errors="replace")
    backoff = log.count("event=accept_backoff")
    return Outcome(
        {
            "sessions by status": dict(opened),
            "calls held (heads by status)": dict(heads),
            "another host's new WebSocket clients": len(waits),
            "their longest wait for a first answer, s": round(max(waits, default=0.0), 3),
            "accept() out of descriptors (event=accept_backoff)": backoff,
        },
        bool(waits) and max(waits) <= NEWCOMER_LIMIT_S and not backoff,
        f"another host's new client served within {NEWCOMER_LIMIT_S} s, never out of descriptors",
    )


# ---- 5: echo of a PNG bomb ------------------------------------------------------------------


def png_bomb() -> bytes:
    """A PNG of 6300x6300 RGB, one colour: ~115 KB that decode to 119 MB."""
    out = io.BytesIO()
    Image.new("RGB", (6300, 6300)).save(out, "PNG")
    return out.getvalue()


BOMB_TOPIC = "/camera/compressed"


async def _bomb_robot(context: Context) -> None:
    publisher = compressed_publisher(context.ws_url, BOMB_TOPIC, "png", png_bomb(), 5.0)
    await context.stack.enter_async_context(publisher)


def _kind(result: Any) -> str:
    text = _text(result)
    if any(isinstance(b, ImageContent) for b in result.content):
        return "an image"
    if result.is_error and "MAX_DECODE_PIXELS" in text:
        return "error: over MAX_DECODE_PIXELS"
    if result.is_error and "times a second" in text:
        return "error: called too often"
    return ("error: " if result.is_error else "text: ") + text[:70]


async def _bomb(context: Context) -> Outcome:
    tally: Counter[str] = Counter()
    deadline = time.monotonic() + context.seconds
    async with agent(_endpoint(context)) as session:

        async def echo() -> str:
            args = {"topic": BOMB_TOPIC, "count": 1, "timeout_s": 10}
            return _kind(await session.call_tool("echo", args))

        await _until(deadline, echo, tally)
    clear = {"error: over MAX_DECODE_PIXELS", "error: called too often"}
    return Outcome(
        {"PNG bytes": len(png_bomb()), "answers": dict(tally)},
        bool(tally) and set(tally) <= clear,
        "every echo an error naming the decode bound (or the call rate)",
    )


# ---- 7: listings of 2,000 topics from 4 sessions --------------------------------------------

TOPICS = 2000
LISTERS = 4


async def _topics(context: Context) -> None:
    names = [f"/bench/topic_{n:04d}" for n in range(TOPICS)]
    for half in (names[: TOPICS // 2], names[TOPICS // 2 :]):  # --max-advertisements 1000 each
        await context.stack.enter_async_context(topics_advertised(context.ws_url, half))


async def _listings(context: Context) -> Outcome:
    tallies = [Counter[str]() for _ in range(LISTERS)]
    deadline = time.monotonic() + context.seconds

    async def lister(tally: Counter[str]) -> None:
        async with agent(_endpoint(context)) as session:

            async def listing() -> str:
                result = await session.call_tool("list_topics", {})
                if not result.is_error:
                    return "listed"
                text = _text(result)
                return "refused: rate" if "LISTING_CALLS_PER_S" in text else "error: " + text[:60]

            await _until(deadline, listing, tally)

    async with anyio.create_task_group() as tg:
        for tally in tallies:
            tg.start_soon(lister, tally)
    total = sum(tallies, Counter[str]())
    allowed = LISTERS * (2 * context.seconds + 5)  # LISTING_CALLS_PER_S 2, LISTING_BURST 5
    return Outcome(
        {
            "answers (4 sessions)": dict(total),
            "listings a second": round(total["listed"] / context.seconds, 1),
        },
        total["listed"] <= allowed and set(total) <= {"listed", "refused: rate"},
        "listings within 2 a second a session (+5), refusals naming LISTING_CALLS_PER_S",
    )


# ---- 8: idle sessions from one host ---------------------------------------------------------

IDLE_TIMEOUT_S = 5.0
MAX_SESSIONS = 300
SESSION_KB = 452  # the figure of one idle session
HOST_SHARE = 64  # --max-connections-per-host's default
OPENERS = 4  # sessions opened at once


def _most_alive(opened: list[float]) -> int:
    """The most of ``opened`` (monotonic times, sorted) within one ``IDLE_TIMEOUT_S``: all
    alive together, since none can have idled out yet (D40's share bounds this)."""
    most, start = 0, 0
    for end, at in enumerate(opened):
        while opened[start] <= at - IDLE_TIMEOUT_S:
            start += 1
        most = max(most, end - start + 1)
    return most


async def _idle_sessions(context: Context) -> Outcome:
    """Sessions opened back to back: the host's share bounds those alive together. The
    host's pace (D55) spaces the opening, so sessions opened early idle out while later
    ones open: the total opened may pass the share, never those alive at once."""
    endpoint = _endpoint(context)
    statuses: Counter[int] = Counter()
    opened: list[float] = []
    first: list[dict[str, str]] = []
    opening = max(1.0, context.seconds - IDLE_TIMEOUT_S - 2)
    deadline = time.monotonic() + opening
    async with httpx.AsyncClient(timeout=WAIT_S) as http:

        async def opener() -> None:
            while time.monotonic() < deadline and sum(statuses.values()) < MAX_SESSIONS:
                status, session = await open_raw(http, endpoint)
                statuses[status] += 1
                if status == 200:
                    opened.append(time.monotonic())
                if session is not None and not first:
                    first.append(session)

        async with anyio.create_task_group() as tg:
            for _ in range(OPENERS):
                tg.start_soon(opener)
        await anyio.sleep(IDLE_TIMEOUT_S + 2)  # the first session: idle past --idle-timeout
        probe = 0
        if first:
            probe = (await http.post(endpoint, json=INITIALIZED, headers=first[0])).status_code
    alive = _most_alive(opened)
    return Outcome(
        {
            "sessions opened by status": dict(statuses),
            "most opened within one --idle-timeout (alive together)": alive,
            "the first session, idle past --idle-timeout": probe,
        },
        alive <= HOST_SHARE and statuses[503] > 0 and probe == 404,
        f"at most {HOST_SHARE} sessions of one host alive together, the rest 503, "
        "an idle one ended (404)",
    )


# ---- 9: POSTs without a session id ----------------------------------------------------------

FLOODERS = 8


async def _flood(
    context: Context, bodies: list[tuple[bytes, bool]]
) -> tuple[Counter[str], int, float]:
    """Post ``bodies`` in turn (with the session's headers where marked) from ``FLOODERS``
    clients back to back until the attack ends: the statuses and error codes, their count
    and the server's CPU milliseconds a request."""
    endpoint = _endpoint(context)
    tally: Counter[str] = Counter()
    async with httpx.AsyncClient(timeout=WAIT_S) as http:
        _, session = await open_raw(http, endpoint)
        cpu = proc_stats(context.pid).cpu_s
        deadline = time.monotonic() + context.seconds

        async def flooder(offset: int) -> None:
            n = offset
            while time.monotonic() < deadline:
                body, in_session = bodies[n % len(bodies)]
                n += 1
                headers = session if in_session and session is not None else ACCEPT
                reply = await http.post(endpoint, content=body, headers=headers)
                code = ""
                if reply.headers.get("content-type", "").startswith("application/json"):
                    code = str(reply.json().get("error", {}).get("code", ""))
                tally[f"{reply.status_code} {code}".strip()] += 1

        async with anyio.create_task_group() as tg:
            for offset in range(FLOODERS):
                tg.start_soon(flooder, offset)
    requests = sum(tally.values())
    return (
        tally,
        requests,
        round((proc_stats(context.pid).cpu_s - cpu) * 1000 / max(1, requests), 2),
    )


async def _no_session(context: Context) -> Outcome:
    body = json.dumps({"jsonrpc": "2.0", "id": 2, "method": "tools/list"}).encode()
    tally, requests, cpu_ms = await _flood(context, [(body, False)])
    built = context.log.read_text(errors="replace").count("event=connect client=mcp:") - 1
    return Outcome(
        {
            "requests": requests,
            "requests a second": round(requests / context.seconds),
            "server CPU ms a request": cpu_ms,
            "by status and JSON-RPC code": dict(tally),
            "sessions built for them (event=connect client=mcp:)": built,
        },
        set(tally) == {"400 -32600"} and built == 0,
        "all 400 (-32600) and no session built for them",
    )


# ---- 10: hostile bodies ---------------------------------------------------------------------

HOSTILE = [
    b"[" * 100_000 + b"]" * 100_000,
    b'{"jsonrpc":"2.0","id":' + b"9" * 5000 + b',"method":"ping"}',
    b'{"jsonrpc":"2.0","id":1,"method":"' + bytes([0xFF, 0xFE]) + b'"}',
]


async def _hostile(context: Context) -> Outcome:
    size = context.log.stat().st_size
    tally, requests, cpu_ms = await _flood(
        context, [(body, in_session) for body in HOSTILE for in_session in (True, False)]
    )
    log = context.log.read_text(errors="replace")
    grown = len(log.encode()) - size
    tracebacks = log.count("Traceback (most recent call last)")
    return Outcome(
        {
            "requests": requests,
            "server CPU ms a request": cpu_ms,
            "by status and JSON-RPC code": dict(tally),
            "log bytes a request": round(grown / max(1, requests), 1),
            "tracebacks in the log": tracebacks,
        },
        set(tally) == {"400 -32700"} and not tracebacks,
        "all 400 with a JSON-RPC parse error (-32700), no traceback",
    )


# ---- 11 and 12: refusals an agent must hear of ----------------------------------------------


async def _refusals_robot(context: Context) -> None:
    names = ["/battery", "/scan", "/odom"]
    advertised = topics_advertised(context.ws_url, names, "sensor_msgs/msg/BatteryState")
    await context.stack.enter_async_context(advertised)


async def _refusals(context: Context) -> Outcome:
    answers: dict[str, str] = {}
    deadline = time.monotonic() + context.seconds
    async with agent(_endpoint(context)) as session:
        result = await session.call_tool("set_parameter", {"name": "/ghost:gain", "value": 2})
        answers["set_parameter of a node that does not exist"] = _answer(result)
        result = await session.call_tool(
            "echo", {"topic": "/battery", "type": "std_msgs/msg/String", "timeout_s": 2}
        )
        answers["echo with a type the topic does not have"] = _answer(result)
        try:
            await session.subscribe_resource("ros://topics/odom")  # type: ignore[arg-type]
            answers["resources/subscribe (the session's one subscription)"] = "ok"
            await session.subscribe_resource("ros://topics/scan")  # type: ignore[arg-type]
            answers["resources/subscribe past --max-subscriptions 1"] = "success"
        except MCPError as error:
            answers["resources/subscribe past --max-subscriptions 1"] = "error: " + str(error)[:110]
        result = await session.call_tool("echo", {"topic": "/battery", "timeout_s": 2})
        answers["echo past --max-subscriptions 1"] = _answer(result)
    await anyio.sleep(max(0.0, deadline - time.monotonic()))
    refused = [k for k in answers if k != "resources/subscribe (the session's one subscription)"]
    clear = all(answers[k].startswith("error: ") and "refused" in answers[k] for k in refused)
    return Outcome(answers, clear, "every refusal a tool error saying the server refused it")


def _answer(result: Any) -> str:
    return ("error: " if result.is_error else "success: ") + _text(result)[:110]


# ---- 13: a flood of video tokens, then a victim's token -------------------------------------

TOKENS = 300


async def _authenticated(ws_url: str, secret: str, host: str) -> Any:
    ws = await connect(ws_url, local_addr=(host, 0), open_timeout=WAIT_S, max_size=None)
    await ws.send(json.dumps(auth_op(secret, host, "127.0.0.1", f"r-{host}")))
    return ws


async def _token(ws: Any, call_id: str) -> str:
    await ws.send(json.dumps({"op": "call_service", "service": "/rwt/video_token", "id": call_id}))
    while True:
        answer = json.loads(await ws.recv())
        if answer.get("id") == call_id:
            return str(answer.get("values", {}).get("message", ""))


async def _tokens(context: Context) -> Outcome:
    assert context.secret is not None
    victim = await _authenticated(context.ws_url, context.secret, "127.0.0.3")
    attacker = await _authenticated(context.ws_url, context.secret, "127.0.0.1")
    try:
        token = await _token(victim, "mine")
        started = time.monotonic()
        for n in range(TOKENS):
            await _token(attacker, f"t{n}")
        flood_s = time.monotonic() - started
        async with httpx.AsyncClient(timeout=WAIT_S) as http:
            bearer = {"Authorization": f"Bearer {token}"}
            status, _ = await open_raw(http, _endpoint(context), bearer)
        await anyio.sleep(max(0.0, context.seconds - (time.monotonic() - started)))
    finally:
        await victim.close()
        await attacker.close()
    return Outcome(
        {
            "tokens asked for by the attacker": TOKENS,
            "seconds for them": round(flood_s, 2),
            "the victim's MCP session with its earlier token": status,
        },
        status == 200,
        "the victim's token still opens its MCP session (200)",
    )


def _mcp(*more: str) -> Callable[[Path], list[str]]:
    return lambda _: ["--mcp", "--no-tf", *more]


ATTACKS = [
    Attack(
        "4",
        "MCP calls in flight under a low RLIMIT_NOFILE",
        _mcp(),
        _descriptors,
        f"RLIMIT_NOFILE {NOFILE} instead of 1024: {HOG_SESSIONS} sessions x {CALLS_PER_SESSION} "
        "echo calls held (instead of 127 x 8); another host's new WebSocket client every s",
        nofile=NOFILE,
    ),
    Attack(
        "5",
        "echo of a PNG CompressedImage bomb",
        _mcp(),
        _bomb,
        "one session's echo calls back to back for 20 s (the issue: 47 s)",
        setup=_bomb_robot,
    ),
    Attack(
        "7",
        "4 MCP sessions listing 2,000 topics",
        _mcp("--max-advertisements", "2000"),
        _listings,
        "4 sessions calling list_topics back to back for 20 s",
        setup=_topics,
    ),
    Attack(
        "8",
        "idle MCP sessions from one host",
        _mcp("--idle-timeout", str(IDLE_TIMEOUT_S)),
        _idle_sessions,
        f"up to {MAX_SESSIONS} sessions (instead of 14,892), {OPENERS} at a time, then "
        f"{IDLE_TIMEOUT_S + 2:g} s idle; --idle-timeout {IDLE_TIMEOUT_S:g}",
        bound=(
            HOST_SHARE * SESSION_KB * 1024 + 16 * 1024 * 1024,
            f"D40: {HOST_SHARE} sessions of a host (--max-connections-per-host) x ~{SESSION_KB} KB "
            "(+16 MB slack)",
        ),
    ),
    Attack(
        "9",
        "POSTs to /mcp without a session id",
        _mcp(),
        _no_session,
        f"{FLOODERS} clients posting tools/list back to back for 10 s",
        seconds=10.0,
    ),
    Attack(
        "10",
        "hostile MCP bodies",
        _mcp(),
        _hostile,
        f"{FLOODERS} clients posting the 3 bodies (in a session and without) back to back for 10 s",
        seconds=10.0,
    ),
    Attack(
        "11+12",
        "refusals MCP tools must report",
        _mcp("--max-subscriptions", "1"),
        _refusals,
        "each refusal once",
        setup=_refusals_robot,
        seconds=5.0,
    ),
    Attack(
        "13",
        "300 video token calls, then a victim's token",
        _mcp("--webrtc"),
        _tokens,
        f"{TOKENS} calls one after another (the store kept 256)",
        secret=True,
        seconds=5.0,
    ),
]
