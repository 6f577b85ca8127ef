"""The real Foxglove client in Node (tests/js/foxglove_extras.mjs): server time, assets, bags.

With `rwt serve --play`, the bag (tests/bag/bags.py, written by rosbags) plays
from a paused start; the client resumes it and seeks through the /rwt/player
services over rosbridge. With `--package-path`, it fetches package:// assets.
With `--record`, what it publishes is in the bag, as rosbags reads it back.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.sync.client import ClientConnection, connect

from rwt_foxglove.assets import MAX_ASSET_BYTES
from tests.bag.bags import CHATTER_GAP_S, T0, write_bag
from tests.bag.support import read_bag
from tests.integration.client_harness import JS_DIR, ServerProcess

from . import extras

pytestmark = pytest.mark.node


@pytest.fixture(scope="module")
def player(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    tmp = tmp_path_factory.mktemp("foxplay")
    bag = write_bag(tmp / "bag", "mcap")
    process = ServerProcess(tmp, ("--play", str(bag), "--start-paused", "--no-tf"))
    try:
        yield process
    finally:
        process.stop()


def test_server_time_follows_the_bag_and_steps_on_a_seek(player: ServerProcess) -> None:
    got = extras.run("play", player.url, "/chatter", "4")
    assert "time" in got["capabilities"]
    gap = int(CHATTER_GAP_S * 1e9)
    first = T0 + 100_000_000
    assert got["messages"] == [
        {"logTime": str(first + i * gap), "data": f"chatter {i} ✓"} for i in range(4)
    ]
    times = [int(ns) for ns in got["times"]]
    assert times == sorted(times) and times[0] >= T0
    assert {first + i * gap for i in range(4)} <= set(times)  # each told before its message
    # the seek to 0 shows as a step back: to the bag's start, or (a loaded machine's timer
    # looking later than the 100 ms to the first message) to the first message's time
    assert T0 <= int(got["stepBack"]) <= first
    assert got["afterSeek"] == {"logTime": str(first), "data": "chatter 0 ✓"}


@pytest.fixture(scope="module")
def packages(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[ServerProcess, bytes]]:
    """`rwt serve --package-path WS/src`, WS/src holding robot_description (a 3 MB mesh)."""
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    tmp = tmp_path_factory.mktemp("foxassets")
    meshes = tmp / "ws" / "src" / "robot_description" / "meshes"
    meshes.mkdir(parents=True)
    mesh = bytes(range(256)) * (3 * 4096)
    (meshes / "base.stl").write_bytes(mesh)
    (tmp / "secret.stl").write_bytes(b"secret")
    (meshes / "escape.stl").symlink_to(tmp / "secret.stl")
    with (meshes / "huge.stl").open("wb") as file:
        file.truncate(MAX_ASSET_BYTES + 1)
    process = ServerProcess(tmp, ("--package-path", str(tmp / "ws" / "src"), "--no-tf"))
    try:
        yield process, mesh
    finally:
        process.stop()


def test_fetch_asset_serves_package_files_and_refuses_the_rest(
    packages: tuple[ServerProcess, bytes],
) -> None:
    server, mesh = packages
    uris = {
        "package://robot_description/meshes/base.stl": (0, None),
        "file:///etc/passwd": (1, "only package:// URIs are served"),
        "package://robot_description/../../secret.stl": (1, "without empty, . or .. parts"),
        "package://robot_description//etc/passwd.stl": (1, "without empty, . or .. parts"),
        "package://robot_description/meshes/escape.stl": (1, "a link out of the package"),
        "package://robot_description/meshes/huge.stl": (1, f"larger than {MAX_ASSET_BYTES}"),
        "package://robot_description/meshes/none.stl": (1, "no such file"),
        "package://other_pkg/a.stl": (1, "no package 'other_pkg' here"),
    }
    got = extras.run("assets", server.url, *uris)
    assert "assets" in got["capabilities"] and got["open"]
    answers = dict(zip(uris, got["responses"], strict=True))
    ok = answers["package://robot_description/meshes/base.stl"]
    assert ok == {
        "requestId": 1,
        "status": 0,
        "length": len(mesh),
        "sha256": hashlib.sha256(mesh).hexdigest(),
    }
    for uri, (status, reason) in uris.items():
        assert answers[uri]["status"] == status, (uri, answers[uri])
        if reason is not None:
            assert answers[uri]["error"].startswith(uri[:60])
            assert reason in answers[uri]["error"], (uri, answers[uri])


def _rosbridge_op(ws: ClientConnection, name: str) -> dict[str, object]:
    while True:
        op = json.loads(ws.recv(timeout=20))
        if op["op"] == name:
            return op  # type: ignore[no-any-return]


def _subscribers(ws: ClientConnection, topic: str) -> list[str]:
    call = {"op": "call_service", "service": "/rosapi/subscribers", "args": {"topic": topic}}
    ws.send(json.dumps(call))
    return _rosbridge_op(ws, "service_response")["values"]["subscribers"]  # type: ignore[index, no-any-return]


def test_a_foxglove_clients_publish_is_recorded(tmp_path: Path) -> None:
    if (reason := extras.missing()) is not None:
        pytest.skip(reason)
    bag = tmp_path / "fromfox"
    server = ServerProcess(tmp_path, ("--record", str(bag), "--record-topics", "/fg_rec"))
    publisher = None
    try:
        publisher = subprocess.Popen(
            extras.command("publish", server.url, "/fg_rec", "from foxglove"),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            cwd=JS_DIR,
        )
        with connect(server.url) as ws:
            for _ in range(400):  # until the recorder subscribed (it looks every 0.2 s)
                if "/rwt_recorder" in _subscribers(ws, "/fg_rec"):
                    break
                time.sleep(0.05)  # the Node client has not advertised /fg_rec yet
            else:
                raise AssertionError("the recorder never subscribed to /fg_rec")
            ws.send(json.dumps({"op": "subscribe", "topic": "/fg_rec"}))
            heard = [_rosbridge_op(ws, "publish")["msg"] for _ in range(3)]
    finally:
        if publisher is not None:
            publisher.kill()
            publisher.wait(10)
        code = server.stop()
    assert code == 0, server.stderr_text()
    assert heard == [{"data": "from foxglove"}] * 3
    recorded = read_bag(bag)
    assert list(recorded) == ["/fg_rec"]
    # each message after the recorder subscribed, at least those the rosbridge client heard
    assert len(recorded["/fg_rec"]) >= 3
    want = {"data": "from foxglove", "__msgtype__": "std_msgs/msg/String"}
    assert all(message == want for message in recorded["/fg_rec"]), recorded
