"""``playbackControl``: Foxglove's playback bar drives a bag played into the graph.

The byte layout of the request and the state is checked against the Foxglove
SDK's own server (PyPI ``foxglove-sdk``): the same request bytes reach both, and
both answer the same state bytes.
"""

from __future__ import annotations

import json
import math
import struct
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest
from websockets.asyncio.client import ClientConnection, connect

from rwt_bag.player import Player
from rwt_foxglove.limits import MAX_PLAYBACK_REQUEST_ID_BYTES
from rwt_foxglove.protocol import (
    PlaybackCommand,
    PlaybackControlRequest,
    PlaybackStatusCode,
    encode_playback_state,
    parse_binary,
)
from rwt_graph.graph import Graph
from rwt_graph.simtime import follow_clock
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.bag.bags import CHATTER_GAP_S, T0, write_bag

from .sansio import Client

PLAY, PAUSE = 0, 1
F32_MAX = 3.4028234663852886e38  # the largest 32-bit float: the largest speed on the wire
END = T0 + 1_050_000_000  # the last record time of the tests' bag
FIRST_CHATTER = T0 + 100_000_000


def request(command: int, speed: float = 1.0, seek: int | None = None, rid: str = "r1") -> bytes:
    """A playback control request frame as the Foxglove app sends it."""
    name = rid.encode()
    head = struct.pack("<BBfBQI", 3, command, speed, seek is not None, seek or 0, len(name))
    return head + name


def parse_state(frame: bytes) -> dict[str, Any]:
    """A playback state frame (opcode 0x05) as a dict."""
    assert frame[0] == 5
    status, now, speed, did_seek, length = struct.unpack_from("<BQfBI", frame, 1)
    assert len(frame) == 19 + length
    rid = frame[19:].decode()
    return {"status": status, "time": now, "speed": speed, "did_seek": bool(did_seek), "id": rid}


def take(client: Client) -> tuple[list[dict[str, Any]], list[int], list[int]]:
    """The states, time frames and message data log times the client got since last asked."""
    client.drain()
    states, times, data = [], [], []
    for frame in client.binary:
        if frame[0] == 5:
            states.append(parse_state(frame))
        elif frame[0] == 2:
            times.append(struct.unpack_from("<Q", frame, 1)[0])
        else:
            data.append(struct.unpack_from("<Q", frame, 5)[0])
    client.binary = []
    return states, times, data


def errors(client: Client) -> list[str]:
    return [str(op["message"]) for op in client.take_ops("status") if op["level"] == 2]


class FakeTime:
    """The player's monotonic clock, moved by hand (the player reads ``time.monotonic``)."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now


@pytest.fixture
def bag(tmp_path: Path) -> Path:
    return write_bag(tmp_path / "bag", "mcap")


@pytest.fixture
def fake_time(monkeypatch: pytest.MonkeyPatch) -> FakeTime:
    fake = FakeTime()
    monkeypatch.setattr("rwt_bag.player.time", types.SimpleNamespace(monotonic=fake.monotonic))
    return fake


@pytest.fixture
def paused(bag: Path) -> Iterator[tuple[Graph, Player]]:
    """A graph and a paused player of the bag, not running (its clock driven by ``fake_time``)."""
    graph = Graph()
    player = Player(graph, [bag], paused=True)
    try:
        yield graph, player
    finally:
        player.source.close()


def offered(graph: Graph, player: Player) -> Any:
    """The graph offering ``player`` as a running player does (without running it)."""
    return graph.port.use_timeline(player.clock_ns, playback=player)


# ---- without a player -----------------------------------------------------------


def test_without_a_player_no_capability_and_a_request_gets_an_error() -> None:
    graph = Graph()
    client = Client(graph)
    info = client.ops[0]
    assert "playbackControl" not in info["capabilities"]  # type: ignore[operator]
    assert "dataStartTime" not in info and "dataEndTime" not in info
    client.send_raw(request(PAUSE), binary=True)
    assert errors(client) == ["playback control is not supported by this server"]
    assert take(client)[0] == []


def test_sim_time_has_time_but_no_playback_control() -> None:
    graph = Graph()
    with follow_clock(graph):
        client = Client(graph)
        caps = client.ops[0]["capabilities"]
        assert "time" in caps and "playbackControl" not in caps  # type: ignore[operator]
        client.send_raw(request(PLAY), binary=True)
        assert errors(client) == ["playback control is not supported by this server"]


# ---- sans-IO with the player's clock in hand --------------------------------------


def test_server_info_has_the_range_and_the_first_state_comes_at_once(
    paused: tuple[Graph, Player], fake_time: FakeTime
) -> None:
    graph, player = paused
    with offered(graph, player):
        client = Client(graph)
    info = client.ops[0]
    assert info["capabilities"] == [
        "clientPublish",
        "services",
        "connectionGraph",
        "time",
        "playbackControl",
    ]
    assert info["dataStartTime"] == {"sec": T0 // 10**9, "nsec": T0 % 10**9}
    assert info["dataEndTime"] == {"sec": END // 10**9, "nsec": END % 10**9}
    states, times, _ = take(client)
    assert times == [T0]
    assert states == [{"status": 1, "time": T0, "speed": 1.0, "did_seek": False, "id": ""}]


def test_play_pause_seek_and_speed_drive_the_clock(
    paused: tuple[Graph, Player], fake_time: FakeTime
) -> None:
    graph, player = paused
    with offered(graph, player):
        client = Client(graph)
        take(client)

        client.send_raw(request(PLAY, rid="play-1"), binary=True)
        (state,), _, _ = take(client)
        assert state == {"status": 0, "time": T0, "speed": 1.0, "did_seek": False, "id": "play-1"}
        assert not player.paused
        fake_time.now += 0.25
        client.session.tick()
        assert take(client) == ([], [T0 + 250_000_000], [])  # the clock runs at 1x

        client.send_raw(request(PLAY, speed=4.0, rid="fast"), binary=True)
        (state,), _, _ = take(client)
        assert (state["status"], state["speed"], state["id"]) == (0, 4.0, "fast")
        assert player.rate == 4.0
        fake_time.now += 0.1
        client.session.tick()
        assert take(client) == ([], [T0 + 650_000_000], [])  # 0.1 s at 4x: 0.4 s of bag

        client.send_raw(request(PAUSE, speed=4.0, rid="hold"), binary=True)
        (state,), _, _ = take(client)
        assert (state["status"], state["time"], state["id"]) == (1, T0 + 650_000_000, "hold")
        fake_time.now += 5.0
        client.session.tick()
        assert take(client) == ([], [], [])  # paused: time stands still, nothing told

        target = T0 + 300_000_000  # back, paused: a step and did_seek
        client.send_raw(request(PAUSE, speed=4.0, seek=target, rid="back"), binary=True)
        (state,), _, _ = take(client)
        assert state == {"status": 1, "time": target, "speed": 4.0, "did_seek": True, "id": "back"}
        client.session.tick()
        assert take(client) == ([], [target], [])  # the step back in time

        client.send_raw(request(PAUSE, speed=0.5, seek=T0 + 10**12, rid="far"), binary=True)
        (state,), _, _ = take(client)  # past the end: clamped to the bag's end
        assert (state["time"], state["speed"], state["did_seek"]) == (END, 0.5, True)
        client.send_raw(request(PAUSE, speed=0.1, seek=0, rid="early"), binary=True)
        (state,), _, _ = take(client)  # before the start: clamped to the bag's start
        assert state["time"] == T0
        assert player.rate == 0.1  # as chosen, not float32's 0.10000000149
        assert state["speed"] == struct.unpack("<f", struct.pack("<f", 0.1))[0]


def test_bad_requests_get_error_statuses_and_the_connection_goes_on(
    paused: tuple[Graph, Player], fake_time: FakeTime
) -> None:
    graph, player = paused
    good = request(PLAY)
    longest = "x" * MAX_PLAYBACK_REQUEST_ID_BYTES
    bad = {
        good[:10]: "playback control request of 10 bytes: shorter than its 19-byte header",
        good[:-1]: "playback control request of 20 bytes: its 2-byte request id needs 21",
        good + b"!": "playback control request of 22 bytes: its 2-byte request id needs 21",
        request(2): "playback control request: unknown command 2 (0 play, 1 pause)",
        request(PLAY, speed=math.nan): "speed nan is not a finite number above 0",
        request(PLAY, speed=math.inf): "speed inf is not a finite number above 0",
        request(PLAY, speed=0.0): "speed 0.0 is not a finite number above 0",
        request(PLAY, speed=-1.0): "speed -1.0 is not a finite number above 0",
        # within a 32-bit float but not a speed a player takes (rwt_graph.playback):
        # refused whole, its seek too
        request(PLAY, speed=F32_MAX, seek=T0 + 500_000_000): "playback control request: "
        "speed 3.403e+38 is not from 0.001 to 1000000 times the recorded speed",
        request(PLAY, speed=2e6): "speed 2e+06 is not from 0.001 to 1000000",
        request(PLAY, speed=1e-5, seek=END): "speed 1e-05 is not from 0.001 to 1000000",
        good[:15] + struct.pack("<I", 2) + b"\xff\xfe": "the request id is not UTF-8",
        request(PLAY, rid=longest + "x"): f"a request id of {len(longest) + 1} bytes (at most "
        f"{MAX_PLAYBACK_REQUEST_ID_BYTES})",
    }
    with offered(graph, player):
        client = Client(graph)
        take(client)
        for frame, message in bad.items():
            client.send_raw(frame, binary=True)
            (got,) = errors(client)
            assert message in got, frame
        assert take(client)[0] == [] and player.paused  # none was applied
        assert (player.rate, player.clock_ns()) == (1.0, T0)
        client.send_raw(request(PLAY, rid=longest), binary=True)  # the longest id: answered
        (state,), _, _ = take(client)
        assert state["id"] == longest and not player.paused


def test_every_client_learns_of_another_clients_request(
    paused: tuple[Graph, Player], fake_time: FakeTime
) -> None:
    graph, player = paused
    with offered(graph, player):
        asking = Client(graph, client_id="foxglove:a#1")
        watching = Client(graph, client_id="foxglove:b#2")
        take(asking), take(watching)
        target = T0 + 500_000_000
        asking.send_raw(request(PLAY, speed=2.0, seek=target, rid="go"), binary=True)
        (answer,), _, _ = take(asking)
        assert answer == {"status": 0, "time": target, "speed": 2.0, "did_seek": True, "id": "go"}
        assert take(watching)[0] == []  # told at its next tick
        watching.session.tick()
        asking.session.tick()
        (told,), times, _ = take(watching)
        assert told == {"status": 0, "time": target, "speed": 2.0, "did_seek": True, "id": ""}
        assert times == [target]
        assert take(asking)[0] == []  # the asking client was answered already
        player.pause()  # a change from elsewhere (/rwt/player/pause): both are told
        for client in (asking, watching):
            client.session.tick()
            (state,), _, _ = take(client)
            assert (state["status"], state["did_seek"], state["id"]) == (1, False, "")


# ---- a playing bag ---------------------------------------------------------------


@pytest.mark.anyio
async def test_pause_stops_messages_and_time_play_resumes_and_the_end_is_told(bag: Path) -> None:
    graph = Graph()
    player = Player(graph, [bag], paused=True, linger=True)
    got: list[int] = []
    async with anyio.create_task_group() as tasks:
        await tasks.start(player.run)
        client = Client(graph)
        take(client)
        channel = client.channel("/chatter")
        client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]})

        async def until(enough: Any) -> list[dict[str, Any]]:
            states: list[dict[str, Any]] = []
            with anyio.fail_after(20):
                while not enough(states):
                    await anyio.sleep(0.01)
                    client.session.tick()
                    new, _, data = take(client)
                    states += new
                    got.extend(data)
            return states

        client.send_raw(request(PLAY, rid="p"), binary=True)
        await until(lambda states: len(got) >= 2)
        client.send_raw(request(PAUSE, rid="h"), binary=True)
        ((state,), _, late) = take(client)
        assert (state["status"], state["id"]) == (1, "h")
        got.extend(late)
        held = len(got)
        clock = player.clock_ns()
        assert clock == state["time"]
        client.session.tick()  # the clock's last move before the pause, if not told yet
        assert take(client)[1] in ([], [clock])
        for _ in range(20):  # a while paused: no message, the time stands
            await anyio.sleep(0.01)
            client.session.tick()
            states, times, data = take(client)
            assert (states, times, data) == ([], [], [])
        assert player.clock_ns() == clock
        client.send_raw(request(PLAY, speed=8.0, rid="p2"), binary=True)
        states = await until(lambda states: any(s["status"] == 3 for s in states))
        assert states[-1] == {"status": 3, "time": END, "speed": 8.0, "did_seek": False, "id": ""}
        tasks.cancel_scope.cancel()
    gap = int(CHATTER_GAP_S * 1e9)
    assert len(got) > held  # resumed, then played to the end, every message once
    assert got == [FIRST_CHATTER + i * gap for i in range(len(got))]


# ---- over a real socket ----------------------------------------------------------


async def _binary(ws: ClientConnection, opcode: int) -> bytes:
    with anyio.fail_after(20):
        while True:
            frame = await ws.recv()
            if isinstance(frame, bytes) and frame[0] == opcode:
                return frame


async def _binaries(ws: ClientConnection, opcodes: tuple[int, ...]) -> list[bytes]:
    """The next binary frames of ``opcodes``, which must come in that order."""
    got: list[bytes] = []
    with anyio.fail_after(20):
        while len(got) < len(opcodes):
            frame = await ws.recv()
            if isinstance(frame, bytes) and frame[0] in opcodes:
                assert frame[0] == opcodes[len(got)]
                got.append(frame)
    return got


async def _status(ws: ClientConnection) -> dict[str, Any]:
    with anyio.fail_after(20):
        while True:
            frame = await ws.recv()
            if isinstance(frame, str) and json.loads(frame)["op"] == "status":
                return json.loads(frame)  # type: ignore[no-any-return]


@pytest.mark.anyio
async def test_two_clients_over_the_wire_see_the_state_of_a_served_bag(bag: Path) -> None:
    graph = Graph()
    player = Player(graph, [bag], paused=True, linger=True)
    server = RosbridgeServer(graph, ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        await tg.start(player.run)
        url = await tg.start(server.serve)
        async with (
            connect(url, subprotocols=["foxglove.sdk.v1"]) as one,
            connect(url, subprotocols=["foxglove.sdk.v1"]) as two,
        ):
            for ws in (one, two):
                info = json.loads(await ws.recv())
                assert "playbackControl" in info["capabilities"]
                assert info["dataStartTime"] == {"sec": T0 // 10**9, "nsec": T0 % 10**9}
                first = parse_state(await _binary(ws, 5))  # the state at connect
                assert (first["status"], first["time"], first["id"]) == (1, T0, "")
            target = T0 + 700_000_000
            await one.send(request(PAUSE, speed=2.0, seek=target, rid="seek-1"))
            answer = parse_state(await _binary(one, 5))
            assert answer == {
                "status": 1,
                "time": target,
                "speed": 2.0,
                "did_seek": True,
                "id": "seek-1",
            }
            time_frame, state_frame = await _binaries(two, (2, 5))  # from its tick: time first
            assert struct.unpack_from("<Q", time_frame, 1)[0] == target
            assert parse_state(state_frame) == {**answer, "id": ""}
            await two.send(request(7))  # a bad one: an error status, the connection goes on
            assert "unknown command 7" in (await _status(two))["message"]
            await two.send(request(PLAY, speed=2.0, rid="go"))
            assert parse_state(await _binary(two, 5))["id"] == "go"
            assert parse_state(await _binary(one, 5))["status"] == 0
        tg.cancel_scope.cancel()


@pytest.mark.anyio
async def test_a_speed_past_the_bound_is_refused_and_the_others_are_served(bag: Path) -> None:
    graph = Graph()
    player = Player(graph, [bag], paused=True, linger=True)
    server = RosbridgeServer(graph, ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        await tg.start(player.run)
        url = await tg.start(server.serve)
        async with (
            connect(url, subprotocols=["foxglove.sdk.v1"]) as hostile,
            connect(url, subprotocols=["foxglove.sdk.v1"]) as bystander,
        ):
            for ws in (hostile, bystander):
                json.loads(await ws.recv())  # serverInfo
                await _binary(ws, 5)  # the state at connect
            for speed in (F32_MAX, 1_000_001.0, 1e-4):
                await hostile.send(request(PLAY, speed=speed, seek=END, rid="hostile"))
                status = await _status(hostile)
                assert status["level"] == 2
                assert "is not from 0.001 to 1000000 times the recorded speed" in status["message"]
            assert (player.rate, player.paused, player.clock_ns()) == (1.0, True, T0)
            await hostile.send(request(PAUSE, speed=1e6, rid="fastest"))  # the bound: taken
            answer = parse_state(await _binary(hostile, 5))
            assert (answer["speed"], answer["id"]) == (1e6, "fastest")
            await bystander.send(request(PAUSE, speed=2.0, seek=END, rid="mine"))
            mine = parse_state(await _binary(bystander, 5))
            assert (mine["speed"], mine["time"], mine["id"]) == (2.0, END, "mine")
        tg.cancel_scope.cancel()
    assert player.rate == 2.0


# ---- the Foxglove SDK's server as the reference of the byte layout -----------------


def test_the_byte_layout_is_the_foxglove_sdks(
    paused: tuple[Graph, Player], fake_time: FakeTime
) -> None:
    foxglove = pytest.importorskip("foxglove")
    from foxglove.websocket import (  # noqa: PLC0415
        Capability,
        PlaybackState,
        PlaybackStatus,
        ServerListener,
    )
    from websockets.sync.client import connect as connect_sync  # noqa: PLC0415

    seen: list[Any] = []
    answer = {"time": T0 + 123_456_789, "speed": 2.5}

    class Listener(ServerListener):
        def on_playback_control_request(self, playback_control_request: Any) -> Any:
            seen.append(playback_control_request)
            return PlaybackState(
                status=PlaybackStatus.Paused,
                current_time=answer["time"],
                playback_speed=answer["speed"],
                did_seek=True,
                request_id=None,  # the SDK puts the request's id in
            )

    server = foxglove.start_server(
        port=0,
        capabilities=[Capability.PlaybackControl],
        server_listener=Listener(),
        playback_time_range=(T0, END),
    )
    sent = request(PAUSE, speed=2.5, seek=answer["time"], rid="req-ü")
    try:
        with connect_sync(f"ws://127.0.0.1:{server.port}", subprotocols=["foxglove.sdk.v1"]) as ws:
            sdk_info = json.loads(ws.recv(timeout=10))
            ws.send(sent)
            sdk_state = ws.recv(timeout=10)
            while not isinstance(sdk_state, bytes):
                sdk_state = ws.recv(timeout=10)
    finally:
        server.stop()

    # the SDK read the request as rwt does
    (sdk_request,) = seen
    ours = parse_binary(sent)
    assert ours == PlaybackControlRequest(PlaybackCommand.PAUSE, 2.5, answer["time"], "req-ü")
    assert int(sdk_request.playback_command.value) == int(ours.command)  # type: ignore[attr-defined]
    assert (sdk_request.playback_speed, sdk_request.seek_time, sdk_request.request_id) == (
        ours.speed,  # type: ignore[attr-defined]
        ours.seek_ns,  # type: ignore[attr-defined]
        ours.request_id,  # type: ignore[attr-defined]
    )
    # the SDK's answer is rwt's bytes for the same state
    assert sdk_state == encode_playback_state(
        PlaybackStatusCode.PAUSED, answer["time"], 2.5, did_seek=True, request_id="req-ü"
    )
    # rwt answers the same request in the same layout, and its range is written the same way
    graph, player = paused
    with offered(graph, player):
        client = Client(graph)
        take(client)
        client.send_raw(sent, binary=True)
        (frame,) = client.binary
    assert frame == sdk_state
    info = client.ops[0]
    assert info["dataStartTime"] == sdk_info["dataStartTime"]
    assert info["dataEndTime"] == sdk_info["dataEndTime"]
    assert "playbackControl" in sdk_info["capabilities"]


def test_rwt_serve_play_offers_the_playback_bar(tmp_path: Path) -> None:
    """The command line's player (``rwt serve --play``): paused at start, a seek, the end."""
    from websockets.sync.client import connect as connect_sync  # noqa: PLC0415

    from tests.integration.client_harness import ServerProcess  # noqa: PLC0415

    bag = write_bag(tmp_path / "bag", "mcap")
    server = ServerProcess(tmp_path, ("--play", str(bag), "--start-paused", "--no-tf"))
    try:
        with connect_sync(server.url, subprotocols=["foxglove.sdk.v1"]) as ws:
            info = json.loads(ws.recv(timeout=20))
            assert "playbackControl" in info["capabilities"]
            assert info["dataEndTime"] == {"sec": END // 10**9, "nsec": END % 10**9}

            def state() -> dict[str, Any]:
                while True:
                    frame = ws.recv(timeout=20)
                    if isinstance(frame, bytes) and frame[0] == 5:
                        return parse_state(frame)

            assert state()["status"] == 1  # --start-paused
            near_end = END - 100_000_000
            ws.send(request(PLAY, speed=2.0, seek=near_end, rid="to-the-end"))
            answer = state()
            assert (answer["status"], answer["time"], answer["did_seek"]) == (0, near_end, True)
            ended = state()  # the bag played out: told without a request id
            assert (ended["status"], ended["time"], ended["id"]) == (3, END, "")
            ws.send(request(PAUSE, speed=2.0, seek=T0, rid="again"))  # it lingers: seekable
            again = state()
            assert (again["status"], again["time"], again["did_seek"]) == (1, T0, True)
    finally:
        server.stop()
