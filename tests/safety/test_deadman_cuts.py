"""Dead-man stops on the cuts the server makes: a slow consumer's, and ``--idle-timeout``'s.

docs/safety.md ("Dead-man stops") and D68 list the ends of a commander's connection
that stop its topic: a close, ``--idle-timeout``, a slow consumer cut, ... The
server makes two of them itself. A commander cut as a slow consumer while it still
commands gets the stop once, because of the cut (the audit's reason says so, and the
cut is logged before it); one that went quiet gets the quiet stop, and the idle cut
that follows publishes no second one. The tests look at what the robot's subscriber
hears; how soon is benchmarks/deadman.py's.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable

import anyio
import pytest
from websockets.exceptions import ConnectionClosed

from rwt import ServerConfig
from rwt_protocol.server.session import SessionConfig
from tests.safety.example import HANG_S, STOP, Robot, twist
from tests.support.clients import WsClient, running_server
from tests.support.rawws import NeverReading

pytestmark = pytest.mark.anyio

RATE_S = 0.1  # a teleop's 10 Hz
LIMIT = 256 * 1024  # the send buffer limit: a quick cut
PAYLOAD = 10_000  # bytes per /flood message
BATCH = 10  # about 100 KB: under the limit, so a bystander that reads between batches
# never drops (with the shortcuts off a batch is queued whole before any of it is sent)
TWIST = "geometry_msgs/msg/Twist"


def _lines(caplog: pytest.LogCaptureFixture, start: str) -> list[str]:
    """The log lines of the server that start with ``start``, in order."""
    return [r.getMessage() for r in caplog.records if r.getMessage().startswith(start)]


def _troubles(caplog: pytest.LogCaptureFixture) -> list[str]:
    """Errors and bugs logged (a traceback is logged at ERROR)."""
    return [
        r.getMessage()
        for r in caplog.records
        if r.levelno >= logging.ERROR or "event=bug" in r.getMessage()
    ]


async def _until(done: Callable[[], bool], what: str) -> None:
    """Wait until ``done()`` holds (polled), within the hang guard."""
    try:
        with anyio.fail_after(HANG_S):
            while not done():
                await anyio.sleep(0.02)
    except TimeoutError:
        raise AssertionError(f"no {what} within {HANG_S:g} s") from None


async def _command_until_cut(commander: NeverReading, ended: list[BaseException]) -> None:
    """Twists at 10 Hz until the connection is gone (the error kept in ``ended``)."""
    try:
        while True:
            await commander.send({"op": "publish", "topic": "/cmd_vel", "msg": twist(0.2)})
            await anyio.sleep(RATE_S)
    except OSError as error:
        ended.append(error)


async def _read(bystander: WsClient, heard: list[int]) -> None:
    """Count each /flood message the bystander reads."""
    async for text in bystander.ws:
        if json.loads(text).get("op") == "publish":
            heard[0] += 1


async def test_a_commander_cut_as_a_slow_consumer_gets_the_stop_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, "rwt")
    robot = Robot.make()
    config = ServerConfig(
        host="127.0.0.1", session=SessionConfig(send_buffer_limit=LIMIT, send_timeout_s=1.0)
    )
    async with running_server(config, graph=robot.graph) as harness:
        server = harness.server
        bystander = await harness.connect("ws", "bystander")
        assert isinstance(bystander, WsClient)
        await bystander.send({"op": "subscribe", "topic": "/flood", "type": "std_msgs/String"})
        commander = await NeverReading.connect(harness.port("websocket"))
        await commander.send({"op": "subscribe", "topic": "/flood", "type": "std_msgs/String"})
        await commander.send({"op": "advertise", "topic": "/cmd_vel", "type": TWIST})
        await _until(
            lambda: (
                len([s for s in server.sessions.values() if s.holdings.subscriptions]) == 2
                and any("/cmd_vel" in s.holdings.advertisements for s in server.sessions.values())
            ),
            "subscriptions and the advertisement",
        )
        cut = next(s for s in server.sessions.values() if "/cmd_vel" in s.holdings.advertisements)
        flood = server.graph.create_publisher("/flood", "std_msgs/msg/String")
        ended: list[BaseException] = []
        heard = [0]
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(_read, bystander, heard)
                tg.start_soon(_command_until_cut, commander, ended)
                await robot.wait_for(lambda: len(robot.cmd_vel) >= 3, "the commands")
                sent = 0
                with anyio.fail_after(60):
                    while cut.client_id in server.sessions:  # flood until the server cuts it
                        for _ in range(BATCH):
                            flood.publish({"data": f"{sent:08d}" + "x" * PAYLOAD})
                            sent += 1
                        while heard[0] < sent:  # paced by the bystander, who reads
                            await anyio.sleep(0.005)
                    await robot.wait_for(lambda: robot.twists[-1:] == [STOP], "the stop")
                    while not ended:  # the commander was still commanding: its send fails
                        await anyio.sleep(0.02)
                    flood.publish({"data": "after the cut"})
                    sent += 1
                    while heard[0] < sent:  # the bystander is still served
                        await anyio.sleep(0.005)
                await anyio.sleep(1.0)  # twice deadman_s: no second stop comes
                tg.cancel_scope.cancel()
        finally:
            commander.close()
    assert isinstance(ended[0], (ConnectionResetError, BrokenPipeError)), ended
    commands = len(robot.twists) - 1
    assert commands >= 3
    assert robot.twists == [twist(0.2)] * commands + [STOP]  # one stop, after every command
    closing = _lines(caplog, f"event=closing client={cut.client_id} ")
    assert len(closing) == 1 and "slow consumer: send buffer over" in closing[0], closing
    stops = _lines(caplog, "event=safety_deadman_stop ")
    assert len(stops) == 1 and "detail='its connection ended'" in stops[0], stops
    assert f"client={cut.client_id} " in stops[0]
    order = [r.getMessage() for r in caplog.records]
    assert order.index(closing[0]) < order.index(stops[0])  # the cut, then its stop
    envelope = robot.graph.safety
    assert envelope is not None and envelope.next_deadline() is None  # no commander left
    assert _troubles(caplog) == []


async def test_the_idle_cut_after_the_quiet_stop_publishes_no_second_stop(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The quiet stop after ``deadman_s``; the idle cut later (D40's rule) adds nothing."""
    caplog.set_level(logging.INFO, "rwt")
    robot = Robot.make()
    config = ServerConfig(host="127.0.0.1", idle_timeout_s=1.5)  # three times deadman_s
    async with running_server(config, graph=robot.graph) as harness:
        client = await harness.connect("ws")
        assert isinstance(client, WsClient)
        await client.send({"op": "advertise", "topic": "/cmd_vel", "type": TWIST})
        for _ in range(3):
            await client.send({"op": "publish", "topic": "/cmd_vel", "msg": twist(0.2)})
            await anyio.sleep(RATE_S)
        # done driving (a held advertisement is never idle): it holds nothing, then is silent
        await client.send({"op": "unadvertise", "topic": "/cmd_vel"})
        await robot.wait_for(lambda: robot.twists[-1:] == [STOP], "the quiet stop")
        (quiet,) = [name for name in harness.server.sessions if name.startswith("ws:")]
        assert _lines(caplog, "event=disconnect client=ws:") == []  # the stop was the quiet one
        with anyio.fail_after(HANG_S), pytest.raises(ConnectionClosed):
            await client.ws.recv()  # nothing comes until the server closes it
        assert client.ws.close_reason == "idle: no input for 1.5 s and nothing held"
        await _until(
            lambda: (
                bool(_lines(caplog, f"event=disconnect client={quiet} "))
                and quiet not in harness.server.sessions
            ),
            "the idle connection's end",
        )
    assert robot.twists == [twist(0.2)] * 3 + [STOP]  # exactly one stop in all
    stops = _lines(caplog, "event=safety_deadman_stop ")
    assert len(stops) == 1 and "detail='no command for 0.5 s'" in stops[0], stops
    (gone,) = _lines(caplog, f"event=disconnect client={quiet} ")
    assert "reason='closed by server: idle: no input for 1.5 s and nothing held'" in gone
    envelope = robot.graph.safety
    assert envelope is not None and envelope.next_deadline() is None  # no commander left
    assert _troubles(caplog) == []
