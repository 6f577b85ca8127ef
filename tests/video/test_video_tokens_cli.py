"""``rwt serve --video --auth-secret-file``: the video port opens only with a token.

An authenticated roslibpy session calls ``/rwt/video_token`` and fetches a snapshot
with the token; without one the video server answers 401, with a forged one 403,
and a connection that did not authenticate gets no token (docs/video.md, D32).
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from rwt_protocol.auth import rosauth_mac
from rwt_video.tokens import TOKEN_CHARS
from tests.integration.client_harness import ServerProcess
from tests.support.realclients import run_python

pytestmark = pytest.mark.anyio

SECRET = "video-secret-0123456789"
TIMEOUT_S = 20.0

# an authenticated roslibpy robot: publishes a camera, asks for a token, and reads
# a snapshot with it (and without it), as a page would put it in an <img>
CLIENT = """
import json, threading, urllib.error, urllib.request
import roslibpy

ros = roslibpy.Ros("127.0.0.1", {port})
{auth}
ros.run(timeout=20)
camera = roslibpy.Topic(ros, "/camera/image", "sensor_msgs/msg/Image")
camera.advertise()
frame = {{"header": {{"frame_id": "camera"}}, "height": 8, "width": 8, "encoding": "rgb8",
          "step": 24, "data": [200, 40, 40] * 64}}
stop = threading.Event()

def publish():
    while not stop.wait(0.05):
        camera.publish(roslibpy.Message(frame))

threading.Thread(target=publish, daemon=True).start()
reply = roslibpy.Service(ros, "/rwt/video_token", "std_srvs/srv/Trigger").call(
    roslibpy.ServiceRequest({{}}), timeout=20)

def get(query):
    url = "{video}/snapshot?topic=/camera/image" + query
    try:
        with urllib.request.urlopen(url, timeout=20) as answer:
            return [answer.status, answer.headers["Content-Type"]]
    except urllib.error.HTTPError as error:
        return [error.code, error.headers["Content-Type"]]

token = reply["message"]
print(json.dumps({{"reply": dict(reply), "with": get("&token=" + token), "without": get("")}}))
stop.set()
ros.terminate()
"""


def _auth() -> str:
    now = time.time()
    fields = {
        "client": "127.0.0.1",
        "dest": "127.0.0.1",
        "rand": "fresh-random-string",
        "t": int(now - 1),
        "level": "user",
        "end": int(now + 60),
    }
    mac = rosauth_mac(SECRET, **fields)  # type: ignore[arg-type]
    return f"ros.authenticate({', '.join(repr(v) for v in (mac, *fields.values()))})"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[ServerProcess, str]]:
    workdir: Path = tmp_path_factory.mktemp("video-auth")
    secret = workdir / "secret.txt"
    secret.write_text(SECRET + "\n")
    process = ServerProcess(
        workdir, ("--video", "--video-port", "0", "--auth-secret-file", str(secret))
    )
    try:
        line = process.next_stdout_line()
        assert line is not None and line.startswith("video on http://"), line
        yield process, line.removeprefix("video on ")
    finally:
        process.stop()


async def test_a_token_from_an_authenticated_roslibpy_session_opens_a_snapshot(
    server: tuple[ServerProcess, str],
) -> None:
    process, video = server
    out = json.loads(await run_python(CLIENT.format(port=process.port, video=video, auth=_auth())))
    assert out["reply"]["success"] is True
    assert len(out["reply"]["message"]) == TOKEN_CHARS  # signed, URL-safe base64
    assert out["with"] == [200, "image/jpeg"]
    assert out["without"][0] == 401


@pytest.mark.parametrize("path", ["/", "/stream?topic=/camera/image", "/snapshot?topic=/x"])
def test_an_unauthenticated_get_is_refused(server: tuple[ServerProcess, str], path: str) -> None:
    _, video = server
    answer = httpx.get(video + path, timeout=TIMEOUT_S)
    assert answer.status_code == 401
    assert answer.headers["WWW-Authenticate"].startswith("Bearer")
    assert "/rwt/video_token" in answer.text


def test_a_forged_token_is_refused(server: tuple[ServerProcess, str]) -> None:
    _, video = server
    forged = "A" * TOKEN_CHARS  # well formed, not signed by the server
    answer = httpx.get(f"{video}/stream?topic=/camera/image&token={forged}", timeout=TIMEOUT_S)
    assert answer.status_code == 403
    bearer = httpx.get(
        f"{video}/", headers={"Authorization": f"Bearer {forged}"}, timeout=TIMEOUT_S
    )
    assert bearer.status_code == 403


def test_the_console_files_need_no_token(server: tuple[ServerProcess, str]) -> None:
    """The page itself holds nothing: it gets its tokens over its authenticated WebSocket."""
    _, video = server
    config = httpx.get(f"{video}/console/config.json", timeout=TIMEOUT_S).json()
    assert config["video"]["token"] is True
    assert config["auth"] is True


async def test_an_unauthenticated_connection_gets_no_token(
    server: tuple[ServerProcess, str],
) -> None:
    process, _ = server
    code = f"""
    import json, asyncio
    import websockets

    async def main():
        async with websockets.connect("ws://127.0.0.1:{process.port}") as ws:
            await ws.send(json.dumps({{"op": "call_service", "service": "/rwt/video_token"}}))
            print(await ws.recv())

    asyncio.run(main())
    """
    reply = json.loads(await run_python(code))
    # a failed call (D4), its reason, and no token anywhere
    assert reply["op"] == "service_response" and reply["result"] is False, reply
    assert "authentication required" in json.dumps(reply["values"])
