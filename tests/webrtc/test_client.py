"""``rwt.Ros`` over the ``rosbridge`` data channel: ``webrtc+http://HOST:PORT/webrtc``."""

from __future__ import annotations

import sys

import anyio
import pytest

from tests.webrtc.conftest import NEEDS_AIORTC

pytest.importorskip("aiortc", reason=NEEDS_AIORTC, exc_type=ImportError)

import rwt
import rwt_client.connectors
from rwt_client.connectors import server_url
from rwt_client.webrtc import signalling_url
from rwt_protocol.distribution import install_hint
from rwt_protocol.errors import ConfigError
from tests.webrtc.peer import Served

pytestmark = pytest.mark.anyio


def webrtc_url(served: Served) -> str:
    return served.base.replace("http://", "webrtc+http://") + "/webrtc"


async def test_publish_subscribe_and_a_service_round_trip(served_on: Served) -> None:
    served_on.graph.create_service(
        "/add", "example_interfaces/srv/AddTwoInts", lambda req: {"sum": req["a"] + req["b"]}
    )
    heard: list[object] = []
    async with rwt.Ros(webrtc_url(served_on)) as ros:
        echo = rwt.Topic(ros, "/echo", "std_msgs/String")
        arrived = anyio.Event()

        def on_message(message: object) -> None:
            heard.append(message)
            arrived.set()

        await echo.subscribe(on_message)
        await echo.publish({"data": "over the data channel"})
        with anyio.fail_after(10):
            await arrived.wait()
        reply = await rwt.Service(ros, "/add", "example_interfaces/AddTwoInts").call(
            {"a": 2, "b": 40}, timeout_s=10
        )
        clients = served_on.server.sessions
        assert any(str(client).startswith("webrtc:") for client in clients)
    assert heard == [{"data": "over the data channel"}]
    assert reply == {"sum": 42}


@pytest.mark.parametrize("size", [200_000, 1024 * 1024], ids=["200KB", "1MiB"])
async def test_a_big_message_comes_back_through_fragments(served_on: Served, size: int) -> None:
    """Over 64 KiB a message goes as ``fragment`` ops both ways, whole at the other end."""
    async with rwt.Ros(webrtc_url(served_on)) as ros:
        echo = rwt.Topic(ros, "/big", "std_msgs/String")
        got: list[str] = []
        arrived = anyio.Event()

        def on_message(message: dict[str, str]) -> None:
            got.append(message["data"])
            arrived.set()

        await echo.subscribe(on_message)
        await echo.publish({"data": "z" * size})  # over 64 KiB: fragment ops
        with anyio.fail_after(20):
            await arrived.wait()
    assert got == ["z" * size]


def test_the_webrtc_scheme_posts_to_its_http_url() -> None:
    assert server_url("webrtc+http://robot.local:9090/webrtc") == (
        "webrtc+http://robot.local:9090/webrtc"
    )
    assert signalling_url("webrtc+http://robot.local:9090") == "http://robot.local:9090/webrtc"
    assert signalling_url("webrtc+https://robot.local/rtc") == "https://robot.local/rtc"
    with pytest.raises(ConfigError, match="webrtc\\+http://HOST:PORT/webrtc"):
        server_url("http://robot.local:9090/webrtc")


async def test_a_refused_offer_is_a_connection_error(served: Served) -> None:
    url = served.base.replace("http://", "webrtc+http://") + "/webrtc/elsewhere"
    with pytest.raises(rwt.ConnectionClosedError, match="refused the offer: 404"):
        async with rwt.Ros(url, reconnect=False):
            pass


async def test_without_aiortc_the_error_says_how_to_install_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(sys.modules, "aiortc", None)  # as if not installed: import fails
    with pytest.raises(ConfigError) as refused:
        await rwt_client.connectors.connect("webrtc+http://127.0.0.1:9/webrtc")
    assert install_hint("webrtc") in str(refused.value)
