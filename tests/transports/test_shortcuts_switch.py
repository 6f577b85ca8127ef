"""``RWT_NO_SHORTCUTS`` turns the shortcuts off, and clients cannot tell (rwt_protocol.shortcuts).

A server runs in a subprocess (shortcut_probe.py) with and without the switch,
counting the calls into each shortcut's own code: with the shortcuts on, every
one of them runs; switched off, none does; and every publish frame its
WebSocket, TCP and cbor-raw subscribers receive has the same bytes either way.
The in-process tests check each call site's choice as it is made.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import anyio
import pytest
from anyio.abc import SocketAttribute
from websockets.protocol import State
from websockets.server import ServerProtocol

from rwt_protocol.runtime.outbox import OutFrame
from rwt_protocol.shortcuts import ENV_VAR, SHORTCUTS
from rwt_transports import pump
from rwt_transports.direct import DirectReader, DirectWriter
from rwt_transports.pump import ConnectionPump
from rwt_transports.websocket import WebSocketChannel, WebSocketOptions
from tests.support.shortcuts import switch_off

REPO = Path(__file__).resolve().parents[2]
#: The probe runs no ROS 2 link (tests/ros2/test_batch_take.py and test_take_loop.py
#: cover its two shortcuts),
#: reads no CDR and records no bag (tests/protocol/test_shortcuts.py covers those), and
#: plays no bag (tests/bag/test_ros1read.py covers ``ros1-chunk-read``), and runs no
#: Zenoh link (tests/zenoh/test_deferred.py covers its two), and has no Foxglove
#: client (tests/foxglove/test_shared_frames.py covers ``foxglove-shared-frames``,
#: tests/graph/ and tests/foxglove/test_batched_delivery.py ``batched-delivery``).
OUTSIDE_THE_PROBE = {
    "ros2-batch-take",
    "ros2-take-loop",
    "cdr-input-view",
    "bag-checkpoints",
    "ros1-chunk-read",
    "zenoh-deferred-encode",
    "zenoh-late-copy",
    "foxglove-shared-frames",
    "batched-delivery",
}
SWITCHABLE = {s.name for s in SHORTCUTS} - OUTSIDE_THE_PROBE


def probe(value: str | None) -> dict[str, Any]:
    """Run shortcut_probe.py with ``RWT_NO_SHORTCUTS`` set to ``value`` (None: unset)."""
    env = {k: v for k, v in os.environ.items() if k != ENV_VAR}
    if value is not None:
        env[ENV_VAR] = value
    env["PYTHONPATH"] = os.pathsep.join((str(REPO / "src"), str(REPO)))
    result = subprocess.run(
        [sys.executable, "-m", "tests.transports.shortcut_probe"],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads(result.stdout)  # type: ignore[no-any-return]


@pytest.fixture(scope="module")
def with_shortcuts() -> dict[str, Any]:
    return probe(None)


def _same_frames(a: dict[str, Any], b: dict[str, Any]) -> None:
    for subscriber in ("ws", "tcp", "cbor-raw"):
        assert a[subscriber] == b[subscriber], f"{subscriber} frames differ"


def test_the_probe_goes_through_every_shortcut(with_shortcuts: dict[str, Any]) -> None:
    calls = with_shortcuts["calls"]
    assert set(calls) == SWITCHABLE  # else the tests below prove nothing for the missing ones
    assert all(count > 0 for count in calls.values())


def test_switched_off_no_shortcut_runs_and_the_wire_is_the_same(
    with_shortcuts: dict[str, Any],
) -> None:
    without = probe("1")
    assert without["calls"] == {}
    _same_frames(without, with_shortcuts)


def test_named_shortcuts_are_switched_off_alone(with_shortcuts: dict[str, Any]) -> None:
    named = {"ws-frame-reader", "cbor-splice-decode", "loop-clock", "json-base64-splice"}
    without = probe(" , ".join(sorted(named)))
    assert set(without["calls"]) == SWITCHABLE - named
    _same_frames(without, with_shortcuts)


def _channel() -> WebSocketChannel:
    protocol = ServerProtocol(max_size=1 << 20, state=State.OPEN)
    return WebSocketChannel(object(), protocol, WebSocketOptions(), 10 * 2**20)  # type: ignore[arg-type]


def test_each_call_site_takes_the_general_path_when_switched_off(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv(ENV_VAR, "1")
    channel = _channel()
    assert channel._frame_here is False
    assert ConnectionPump(channel)._direct is None  # type: ignore[arg-type]
    assert pump._clock() is anyio.current_time
    monkeypatch.delenv(ENV_VAR)
    channel = _channel()
    assert channel._frame_here is True
    assert ConnectionPump(channel)._direct is channel  # type: ignore[arg-type]


@pytest.mark.anyio
@pytest.mark.parametrize("value", [None, "1", "direct-read", "direct-write"])
async def test_the_direct_reader_and_writer_follow_the_switch(
    value: str | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    switch_off(monkeypatch, value)
    async with await anyio.create_tcp_listener(local_host="127.0.0.1") as listener:
        port = listener.extra(SocketAttribute.local_port)
        async with await anyio.connect_tcp("127.0.0.1", port) as stream:
            reader, writer = DirectReader.for_stream(stream), DirectWriter.for_stream(stream)
    assert (reader is None) is (value in ("1", "direct-read"))
    assert (writer is None) is (value in ("1", "direct-write"))


class _Wire:
    """A stream that keeps what is sent."""

    def __init__(self) -> None:
        self.sent: list[bytes] = []

    async def send(self, data: bytes) -> None:
        self.sent.append(bytes(data))


@pytest.mark.anyio
async def test_framing_here_writes_the_bytes_websockets_would(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sizes = [0, 1, 125, 126, 65535, 65536, 70000, 3, 200_000]
    payloads = [(bytes(i % 256 for i in range(n)), n % 2 == 1) for n in sizes]
    wires = {}
    for value in ("", "ws-frame-writer"):
        monkeypatch.setenv(ENV_VAR, value)
        wire = _Wire()
        protocol = ServerProtocol(max_size=1 << 20, state=State.OPEN)
        channel = WebSocketChannel(wire, protocol, WebSocketOptions(), 10 * 2**20)  # type: ignore[arg-type]
        await channel.send([OutFrame(data, binary=binary) for data, binary in payloads])
        wires[value] = b"".join(wire.sent)
    assert wires[""] == wires["ws-frame-writer"]


@pytest.mark.anyio
async def test_a_frame_with_a_prefix_is_one_message_either_way(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Foxglove message data: the client's own header before a payload others share
    sizes = [0, 112, 113, 65522, 65523, 70000, 200_000]
    frames = [
        OutFrame(bytes(i % 251 for i in range(n)), True, True, prefix=b"\x01" + bytes(12))
        for n in sizes
    ]
    wires = {}
    for value in ("", "ws-frame-writer"):
        monkeypatch.setenv(ENV_VAR, value)
        wire = _Wire()
        protocol = ServerProtocol(max_size=1 << 20, state=State.OPEN)
        channel = WebSocketChannel(wire, protocol, WebSocketOptions(), 10 * 2**20)  # type: ignore[arg-type]
        await channel.send(frames)
        wires[value] = b"".join(wire.sent)
    assert wires[""] == wires["ws-frame-writer"]
    whole = _Wire()  # the same messages made whole first, as websockets frames them
    protocol = ServerProtocol(max_size=1 << 20, state=State.OPEN)
    channel = WebSocketChannel(whole, protocol, WebSocketOptions(), 10 * 2**20)  # type: ignore[arg-type]
    await channel.send([OutFrame(frame.prefix + frame.data, True) for frame in frames])
    assert wires[""] == b"".join(whole.sent)
