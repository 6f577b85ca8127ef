"""Encodings with real clients: roslib (Node) and roslibpy against an in-process server.

Issue 4, spec 3.1, D19-D21, D27. The server runs in this
process (anyio), so the test owns its graph: in-process publishers answer a
client's "ready" message, in-process services answer calls, an in-process
subscription checks what fragments reassembled into. Each client runs in its
own process (``tests/js/encodings.mjs``; ``roslibpy_fragments.py``), awaited
with a bound.
"""

from __future__ import annotations

import base64
import hashlib
import json
import shutil
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import anyio
import numpy as np
import pytest

from rwt_graph.graph import Graph
from rwt_protocol.server import encoding
from rwt_transports.server import RosbridgeServer, ServerConfig

pytestmark = pytest.mark.anyio

HERE = Path(__file__).resolve().parent
JS_DIR = HERE.parent / "js"
NODE_MISSING = shutil.which("node") is None or not (JS_DIR / "node_modules" / "roslib").is_dir()
needs_node = pytest.mark.skipif(NODE_MISSING, reason="needs node and `npm ci --prefix tests/js`")
CLIENT_TIMEOUT_S = 60.0
READY = {"topic": "/rwt_ready", "type": "std_msgs/String"}

MULTI_ARRAYS = {
    "Float32MultiArray": ("Float32Array", "float32"),
    "Float64MultiArray": ("Float64Array", "float64"),
    "Int8MultiArray": ("Int8Array", "int8"),
    "Int16MultiArray": ("Int16Array", "int16"),
    "Int32MultiArray": ("Int32Array", "int32"),
    "Int64MultiArray": ("BigInt64Array", "int64"),
    "UInt8MultiArray": ("Uint8Array", "uint8"),
    "UInt16MultiArray": ("Uint16Array", "uint16"),
    "UInt32MultiArray": ("Uint32Array", "uint32"),
    "UInt64MultiArray": ("BigUint64Array", "uint64"),
}


@pytest.fixture
async def served() -> AsyncIterator[tuple[Graph, str]]:
    graph = Graph()
    server = RosbridgeServer(graph, ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield graph, url
        tg.cancel_scope.cancel()


def count_calls(monkeypatch: pytest.MonkeyPatch, name: str) -> list[object]:
    """Record the first argument of each call of ``rwt_protocol.server.encoding.<name>``."""
    real = getattr(encoding, name)
    calls: list[object] = []

    def counted(first: object, *args: object, **kwargs: object) -> object:
        calls.append(first)
        return real(first, *args, **kwargs)

    monkeypatch.setattr(encoding, name, counted)
    return calls


def on_ready(graph: Graph, names: set[str], publish: Callable[[], None]) -> None:
    """Run ``publish`` once every connection in ``names`` said it has subscribed."""
    waiting = set(names)

    def ready(msg: dict[str, object]) -> None:
        waiting.discard(str(msg["data"]))
        if not waiting:
            publish()

    graph.create_subscription(READY["topic"], ready, READY["type"])


async def run_node(url: str, spec: dict[str, object], tmp_path: Path) -> dict[str, object]:
    path = tmp_path / "spec.json"
    path.write_text(json.dumps({"ready": READY, **spec}))
    with anyio.fail_after(CLIENT_TIMEOUT_S):
        done = await anyio.run_process(
            ["node", str(JS_DIR / "encodings.mjs"), url, str(path)], check=False
        )
    assert done.returncode == 0, done.stderr.decode()
    return json.loads(done.stdout.decode().splitlines()[-1])  # type: ignore[no-any-return]


def typed(name: str, values: list[object]) -> dict[str, object]:
    packed = np.asarray(values, dtype=MULTI_ARRAYS_DTYPES[name]).tobytes()
    return {
        "$type": name,
        "length": len(values),
        "values": [str(v) if name.startswith("Big") else v for v in values],
        "sha256": hashlib.sha256(packed).hexdigest(),
    }


MULTI_ARRAYS_DTYPES = {js: "<" + np.dtype(dt).str[1:] for js, dt in MULTI_ARRAYS.values()}


@needs_node
async def test_roslib_cbor_gets_typed_arrays_and_bytes(
    served: tuple[Graph, str], tmp_path: Path
) -> None:
    graph, url = served
    publishers = {
        name: graph.create_publisher(f"/{name}", f"std_msgs/msg/{name}") for name in MULTI_ARRAYS
    }
    chatter = graph.create_publisher("/chatter", "std_msgs/msg/String")
    image = graph.create_publisher("/image", "sensor_msgs/msg/Image")
    pixels = bytes(range(256)) * 3

    def publish() -> None:
        chatter.publish({"data": "hello cbor"})
        image.publish({"height": 16, "width": 16, "encoding": "rgb8", "step": 48, "data": pixels})
        for name, publisher in publishers.items():
            values = [-2.5, 0.0, 3.25] if "Float" in name else [0, 1, 100]
            if name.startswith("Int"):
                values = [-100, 0, 100]
            publisher.publish({"data": values})

    on_ready(graph, {"a"}, publish)
    subscribe = [
        {"topic": "/chatter", "type": "std_msgs/String", "compression": "cbor"},
        {"topic": "/image", "type": "sensor_msgs/Image", "compression": "cbor"},
    ] + [
        {"topic": f"/{name}", "type": f"std_msgs/{name}", "compression": "cbor"}
        for name in MULTI_ARRAYS
    ]
    expect = {f"a:{s['topic']}": 1 for s in subscribe}
    result = await run_node(
        url, {"connections": [{"name": "a", "subscribe": subscribe}], "expect": expect}, tmp_path
    )
    received = result["received"]
    assert received["a:/chatter"] == [{"data": "hello cbor"}]  # type: ignore[index]
    [img] = received["a:/image"]  # type: ignore[index]
    assert img["data"]["$type"] == "Uint8Array"
    assert img["data"]["sha256"] == hashlib.sha256(pixels).hexdigest()
    assert img["header"]["stamp"].keys() == {"sec", "nanosec"}
    for name, (js_type, _) in MULTI_ARRAYS.items():
        [msg] = received[f"a:/{name}"]  # type: ignore[index]
        values = [-2.5, 0.0, 3.25] if "Float" in name else [0, 1, 100]
        if name.startswith("Int"):
            values = [-100, 0, 100]
        assert msg["data"] == typed(js_type, values), name
        assert msg["layout"] == {"dim": [], "data_offset": 0}


@needs_node
async def test_roslib_png_decodes_string_twist_and_image(
    served: tuple[Graph, str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    graph, url = served
    compressed = count_calls(monkeypatch, "encode_png")
    chatter = graph.create_publisher("/chatter", "std_msgs/msg/String")
    twist = graph.create_publisher("/cmd_vel", "geometry_msgs/msg/Twist")
    image = graph.create_publisher("/image", "sensor_msgs/msg/Image")
    pixels = bytes(range(256)) * 12

    def publish() -> None:
        chatter.publish({"data": "hello png " * 50})
        twist.publish({"linear": {"x": 0.5, "y": -1.0}, "angular": {"z": 2.25}})
        image.publish({"height": 32, "width": 32, "encoding": "rgb8", "step": 96, "data": pixels})

    on_ready(graph, {"a"}, publish)
    subscribe = [
        {"topic": "/chatter", "type": "std_msgs/String", "compression": "png"},
        {"topic": "/cmd_vel", "type": "geometry_msgs/Twist", "compression": "png"},
        {"topic": "/image", "type": "sensor_msgs/Image", "compression": "png"},
    ]
    expect = {f"a:{s['topic']}": 1 for s in subscribe}
    result = await run_node(
        url, {"connections": [{"name": "a", "subscribe": subscribe}], "expect": expect}, tmp_path
    )
    received = result["received"]
    assert len(compressed) == 3  # the three messages went out as png ops
    text = "hello png " * 50
    digest = hashlib.sha256(text.encode()).hexdigest()
    assert received["a:/chatter"] == [  # type: ignore[index]
        {"data": {"$type": "string", "length": 500, "sha256": digest}}
    ]
    assert received["a:/cmd_vel"] == [  # type: ignore[index]
        {"linear": {"x": 0.5, "y": -1.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 2.25}}
    ]
    [img] = received["a:/image"]  # type: ignore[index]
    encoded = base64.b64encode(pixels).decode()
    assert img["data"]["sha256"] == hashlib.sha256(encoded.encode()).hexdigest()
    assert (img["width"], img["height"], img["encoding"]) == (32, 32, "rgb8")


@needs_node
async def test_json_and_cbor_subscribers_each_get_their_encoding(
    served: tuple[Graph, str], tmp_path: Path
) -> None:
    graph, url = served
    image = graph.create_publisher("/image", "sensor_msgs/msg/Image")
    pixels = bytes([7, 8, 9]) * 4
    on_ready(
        graph,
        {"json", "cbor"},
        lambda: image.publish(
            {"height": 2, "width": 2, "encoding": "rgb8", "step": 6, "data": pixels}
        ),
    )
    spec = {
        "connections": [
            {"name": "json", "subscribe": [{"topic": "/image", "type": "sensor_msgs/Image"}]},
            {
                "name": "cbor",
                "subscribe": [
                    {"topic": "/image", "type": "sensor_msgs/Image", "compression": "cbor"}
                ],
            },
        ],
        "expect": {"json:/image": 1, "cbor:/image": 1},
    }
    received = (await run_node(url, spec, tmp_path))["received"]
    [as_json] = received["json:/image"]  # type: ignore[index]
    [as_cbor] = received["cbor:/image"]  # type: ignore[index]
    assert as_json["data"] == base64.b64encode(pixels).decode()
    assert as_cbor["data"]["$type"] == "Uint8Array"
    assert as_cbor["data"]["values"] == list(pixels)
    assert {k: v for k, v in as_json.items() if k != "data"} == {
        k: v for k, v in as_cbor.items() if k != "data"
    }


@needs_node
async def test_roslib_reassembles_a_fragmented_service_response(
    served: tuple[Graph, str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    graph, url = served
    fragmented = count_calls(monkeypatch, "fragment_frames")
    text = "".join(f"{i:05d}," for i in range(20_000))  # 120 000 characters
    graph.create_service(
        "/long_story",
        "example_interfaces/srv/Trigger",
        lambda request: {"success": True, "message": text},
    )
    spec = {
        "connections": [
            {
                "name": "a",
                "call": [
                    {
                        "service": "/long_story",
                        "type": "example_interfaces/srv/Trigger",
                        "fragment_size": 1000,
                    }
                ],
            }
        ],
    }
    calls = (await run_node(url, spec, tmp_path))["calls"]
    [reply] = [json.loads(str(text)) for text in fragmented]
    assert reply["op"] == "service_response"  # one reply, sent as fragments
    assert calls["a:/long_story"] == {  # type: ignore[index]
        "result": True,
        "values": {
            "success": True,
            "message": {
                "$type": "string",
                "length": len(text),
                "sha256": hashlib.sha256(text.encode()).hexdigest(),
            },
        },
    }


def big_message_probe(graph: Graph, topic: str) -> list[int]:
    """Record the length of each message on ``topic`` and acknowledge it on /rwt_ack."""
    ack = graph.create_publisher("/rwt_ack", "std_msgs/msg/String")
    sizes: list[int] = []

    def got(msg: dict[str, object]) -> None:
        data = str(msg["data"])
        sizes.append(len(data))
        ack.publish({"data": f"{len(data)}:{set(data) == {'r'} or set(data) == {'j'}}"})

    graph.create_subscription(topic, got, "std_msgs/msg/String")
    return sizes


FIVE_MB = 5 * 1024 * 1024


@needs_node
async def test_roslib_publishes_5_mb_as_fragments(
    served: tuple[Graph, str], tmp_path: Path
) -> None:
    graph, url = served
    sizes = big_message_probe(graph, "/big")
    step = {
        "topic": "/big",
        "type": "std_msgs/String",
        "msg": {"data": "j" * FIVE_MB},
        "fragment_size": 100_000,
    }
    spec = {
        "ready": None,
        "connections": [
            {
                "name": "a",
                "subscribe": [{"topic": "/rwt_ack", "type": "std_msgs/String"}],
                "publish_fragments": [step],
            }
        ],
        "expect": {"a:/rwt_ack": 1},
    }
    received = (await run_node(url, spec, tmp_path))["received"]
    assert received["a:/rwt_ack"] == [{"data": f"{FIVE_MB}:True"}]  # type: ignore[index]
    assert sizes == [FIVE_MB]


async def test_roslibpy_publishes_5_mb_as_fragments(served: tuple[Graph, str]) -> None:
    graph, url = served
    sizes = big_message_probe(graph, "/big")
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    script = HERE / "roslibpy_fragments.py"
    command = [sys.executable, str(script), host, port, "/big", "std_msgs/String"]
    with anyio.fail_after(CLIENT_TIMEOUT_S):
        done = await anyio.run_process([*command, str(FIVE_MB), "65536"], check=False)
    assert done.returncode == 0, done.stderr.decode()[-3000:]
    report = json.loads(done.stdout.decode().splitlines()[-1])
    assert report["acked"] and report["ack"] == [f"{FIVE_MB}:True"]
    assert report["fragments"] > 50
    assert sizes == [FIVE_MB]
