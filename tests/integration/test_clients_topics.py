"""Topics through `rwt serve` with real clients: roslibpy and roslib (roslibjs) in Node.

Each scenario has a publishing role and a subscribing role, on two connections.
It runs with both roles on the same client library (one process, two
connections) and, for the cross-client cases, with roslibpy on one side and
roslib on the other. Assertions are on what the client's subscribe callback got
("received"), and where it matters on every publish frame the connection got
("wire").
"""

from __future__ import annotations

import base64
from collections.abc import Iterator
from pathlib import Path

import pytest

from .client_harness import (
    Outcome,
    ServerProcess,
    advertise,
    connect,
    publish,
    quiet,
    run_scenario,
    subscribe,
    sync,
    unsubscribe,
    wait,
)

PY, JS = "roslibpy", "roslibjs"


@pytest.fixture(scope="module")
def shared_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    """One `rwt serve` for the whole module: each scenario opens its own connections
    and closes them, and no two tests give one topic different types."""
    server = ServerProcess(tmp_path_factory.mktemp("rwt_serve"))
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def rwt_server(request: pytest.FixtureRequest, shared_server: ServerProcess) -> ServerProcess:
    """The shared server, its stderr attached to a failing test's report (conftest.py)."""
    request.node._rwt_server = shared_server
    return shared_server


def pairs(*combos: tuple[str, str]) -> list:
    """pytest params of (publisher client, subscriber client); Node ones marked."""
    params = []
    for pub, sub in combos:
        marks = [pytest.mark.node] if JS in (pub, sub) else []
        params.append(pytest.param(pub, sub, id=f"{pub}-to-{sub}", marks=marks))
    return params


SAME = pairs((PY, PY), (JS, JS))
ALL = pairs((PY, PY), (JS, JS), (PY, JS), (JS, PY))


def pubsub(
    server: ServerProcess,
    tmp_path: Path,
    pub_client: str,
    sub_client: str,
    topics: dict[str, tuple[str, str]],
    messages: dict[str, list],
) -> Outcome:
    """Subscriber subscribes (proven by a sync), then the publisher publishes.

    `topics` maps a topic to (publisher's type string, subscriber's type string).
    Waits until the subscriber got as many messages as were published per topic.
    """
    phases = [
        (
            "sub",
            [connect("sub")]
            + [subscribe("sub", t, types[1]) for t, types in topics.items()]
            + [sync("sub")],
        ),
        (
            "pub",
            [connect("pub")]
            + [advertise("pub", t, types[0]) for t, types in topics.items()]
            + [publish("pub", t, *msgs) for t, msgs in messages.items()]
            + [sync("pub")],
        ),
        ("sub", [wait("sub", t, len(msgs)) for t, msgs in messages.items()]),
    ]
    return run_scenario(server.url, phases, {"pub": pub_client, "sub": sub_client}, tmp_path)


def assert_no_error_status(outcome: Outcome) -> None:
    assert outcome.status_count == 0, f"server sent status frames: {outcome.statuses}"


# --------------------------------------------------------------------------- basic types
@pytest.mark.parametrize(("pub_client", "sub_client"), ALL)
def test_string_and_twist_arrive_exact(rwt_server, tmp_path, pub_client, sub_client):
    strings = [
        {"data": "hello world"},
        {"data": ""},
        {"data": 'h\u00e9llo "\u2713" \\ \n\t\U0001f916'},
    ]
    twist = {
        "linear": {"x": 1.5, "y": -2.25, "z": 0.1},
        "angular": {"x": 0.0, "y": 1e-3, "z": -3.141592653589793},
    }
    out = pubsub(
        rwt_server,
        tmp_path,
        pub_client,
        sub_client,
        {
            "/chatter": ("std_msgs/String", "std_msgs/msg/String"),
            "/cmd_vel": ("geometry_msgs/msg/Twist", "geometry_msgs/Twist"),
        },
        {"/chatter": strings, "/cmd_vel": [twist]},
    )
    assert out.got("sub", "/chatter") == strings
    assert out.got("sub", "/cmd_vel") == [twist]
    assert_no_error_status(out)


# --------------------------------------------------------------------------- png
@pytest.mark.node
@pytest.mark.parametrize("count", [12, 1000])
def test_png_subscriber_that_reads_gets_every_message_in_order(rwt_server, tmp_path, count):
    """roslib publishing a burst back to back to a roslib `compression: "png"` subscriber.

    The subscriber reads all the while, so it gets every message, in order, as on
    rosbridge_suite (D20, D24: only a subscriber that does not read loses messages;
    docs/limits.md, png). It once got 4 of 12: at most 4 could wait for deflating.
    """
    topic = f"/png_burst_{count}"
    msgs = [{"data": f"message {i}"} for i in range(count)]
    phases = [
        ("sub", [connect("sub"), subscribe("sub", topic, "std_msgs/String", "png"), sync("sub")]),
        (
            "pub",
            [
                connect("pub"),
                advertise("pub", topic, "std_msgs/String"),
                publish("pub", topic, *msgs),
                sync("pub"),
            ],
        ),
        ("sub", [wait("sub", topic, count), quiet(200)]),
    ]
    out = run_scenario(rwt_server.url, phases, {"pub": JS, "sub": JS}, tmp_path)
    assert out.got("sub", topic) == msgs
    assert_no_error_status(out)


# --------------------------------------------------------------------------- images
WIDTH, HEIGHT = 640, 480


def image_bytes() -> bytes:
    """A deterministic 640x480 rgb8 pattern that uses every byte value."""
    row = bytes((x * 3 + c) * 7 % 256 for x in range(WIDTH) for c in range(3))
    return b"".join(row[y % 256 :] + row[: y % 256] for y in range(HEIGHT))


def image_msg(data: object) -> dict:
    return {
        "header": {"stamp": {"sec": 1700000000, "nanosec": 123456789}, "frame_id": "camera"},
        "height": HEIGHT,
        "width": WIDTH,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": WIDTH * 3,
        "data": data,
    }


def assert_image(msgs: list, original: bytes) -> None:
    assert len(msgs) == 1
    got = msgs[0]
    assert got["header"] == {
        "stamp": {"sec": 1700000000, "nanosec": 123456789},
        "frame_id": "camera",
    }
    assert (got["height"], got["width"], got["encoding"], got["step"], got["is_bigendian"]) == (
        HEIGHT,
        WIDTH,
        "rgb8",
        WIDTH * 3,
        0,
    )
    assert isinstance(got["data"], str), (
        f"uint8[] should arrive as base64 text, got {type(got['data']).__name__}"
    )
    data = base64.b64decode(got["data"], validate=True)
    assert len(data) == len(original)
    assert data == original


@pytest.mark.parametrize(("pub_client", "sub_client"), ALL)
def test_image_base64_arrives_byte_exact(rwt_server, tmp_path, pub_client, sub_client):
    original = image_bytes()
    assert len(original) == WIDTH * HEIGHT * 3 and len(set(original)) == 256
    out = pubsub(
        rwt_server,
        tmp_path,
        pub_client,
        sub_client,
        {"/camera/image_raw": ("sensor_msgs/msg/Image", "sensor_msgs/msg/Image")},
        {"/camera/image_raw": [image_msg(base64.b64encode(original).decode("ascii"))]},
    )
    assert_image(out.got("sub", "/camera/image_raw"), original)
    assert_no_error_status(out)


@pytest.mark.parametrize(("pub_client", "sub_client"), pairs((PY, PY), (PY, JS)))
def test_image_int_list_arrives_byte_exact(rwt_server, tmp_path, pub_client, sub_client):
    """roslibpy users often publish bytes as a list of ints; it comes out base64."""
    original = image_bytes()
    out = pubsub(
        rwt_server,
        tmp_path,
        pub_client,
        sub_client,
        {"/camera/image_raw": ("sensor_msgs/Image", "sensor_msgs/Image")},
        {"/camera/image_raw": [image_msg(list(original))]},
    )
    assert_image(out.got("sub", "/camera/image_raw"), original)
    assert_no_error_status(out)


# --------------------------------------------------------------------------- many
@pytest.mark.parametrize(("pub_client", "sub_client"), ALL)
def test_hundred_messages_complete_and_in_order(rwt_server, tmp_path, pub_client, sub_client):
    msgs = [{"data": (i * 7919) % 20011 - 10000} for i in range(100)]
    out = pubsub(
        rwt_server,
        tmp_path,
        pub_client,
        sub_client,
        {"/counter": ("std_msgs/Int32", "std_msgs/Int32")},
        {"/counter": msgs},
    )
    assert out.got("sub", "/counter") == msgs
    assert out.on_wire("sub", "/counter") == msgs
    assert_no_error_status(out)


# --------------------------------------------------------------------------- unsubscribe
@pytest.mark.parametrize(("pub_client", "sub_client"), ALL)
def test_unsubscribe_stops_delivery(rwt_server, tmp_path, pub_client, sub_client):
    t, sentinel = "/unsub_me", "/sentinel"
    phases = [
        (
            "sub",
            [
                connect("sub"),
                subscribe("sub", t, "std_msgs/String"),
                subscribe("sub", sentinel, "std_msgs/String"),
                sync("sub"),
            ],
        ),
        (
            "pub",
            [
                connect("pub"),
                advertise("pub", t, "std_msgs/String"),
                advertise("pub", sentinel, "std_msgs/String"),
                publish("pub", t, {"data": "before"}),
                sync("pub"),
            ],
        ),
        ("sub", [wait("sub", t, 1), unsubscribe("sub", t), sync("sub")]),
        (
            "pub",
            [
                publish("pub", t, {"data": "after"}),
                publish("pub", sentinel, {"data": "done"}),
                sync("pub"),
            ],
        ),
        # The sentinel was published after "after" on the same connection, so a
        # server still routing /unsub_me to us would have delivered "after" first.
        # The short window then catches a late one anyway.
        ("sub", [wait("sub", sentinel, 1), quiet(300)]),
    ]
    out = run_scenario(rwt_server.url, phases, {"pub": pub_client, "sub": sub_client}, tmp_path)
    assert out.got("sub", sentinel) == [{"data": "done"}]
    assert out.got("sub", t) == [{"data": "before"}]
    assert out.on_wire("sub", t) == [{"data": "before"}], "server kept sending after unsubscribe"
    assert_no_error_status(out)


# --------------------------------------------------------------------------- defaults
@pytest.mark.parametrize(("pub_client", "sub_client"), SAME)
def test_partial_messages_get_defaults(rwt_server, tmp_path, pub_client, sub_client):
    out = pubsub(
        rwt_server,
        tmp_path,
        pub_client,
        sub_client,
        {
            "/partial_twist": ("geometry_msgs/Twist", "geometry_msgs/Twist"),
            "/partial_pose": ("geometry_msgs/msg/Pose", "geometry_msgs/msg/Pose"),
            "/empty_string": ("std_msgs/String", "std_msgs/String"),
        },
        {
            "/partial_twist": [{"linear": {"x": 1.0}}, {}],
            "/partial_pose": [{"position": {"x": 1.0, "y": 2.0, "z": 3.0}}],
            "/empty_string": [{}],
        },
    )
    zero = {"x": 0.0, "y": 0.0, "z": 0.0}
    assert out.got("sub", "/partial_twist") == [
        {"linear": {"x": 1.0, "y": 0.0, "z": 0.0}, "angular": zero},
        {"linear": zero, "angular": zero},
    ]
    (pose,) = out.got("sub", "/partial_pose")
    assert pose["position"] == {"x": 1.0, "y": 2.0, "z": 3.0}
    assert pose["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert out.got("sub", "/empty_string") == [{"data": ""}]
    # Filled-in defaults are at most a warning, and the default status level is error.
    assert_no_error_status(out)


# --------------------------------------------------------------------------- names
@pytest.mark.parametrize(("pub_client", "sub_client"), SAME)
def test_relative_and_absolute_names_meet(rwt_server, tmp_path, pub_client, sub_client):
    """`chatter` and `/chatter` are one topic, and each side sees its own spelling.

    Both clients dispatch incoming publishes on the exact topic string, so a
    subscriber that wrote `abs_chatter` only sees messages echoed with that name
    even though the publisher wrote `/abs_chatter`.
    """
    phases = [
        ("sub", [connect("sub"), subscribe("sub", "abs_chatter", "std_msgs/String"), sync("sub")]),
        (
            "pub",
            [
                connect("pub"),
                advertise("pub", "/abs_chatter", "std_msgs/String"),
                publish("pub", "/abs_chatter", {"data": "one"}),
                sync("pub"),
            ],
        ),
        ("sub", [wait("sub", "abs_chatter", 1)]),
    ]
    out = run_scenario(rwt_server.url, phases, {"pub": pub_client, "sub": sub_client}, tmp_path)
    assert out.got("sub", "abs_chatter") == [{"data": "one"}]
    assert_no_error_status(out)


# --------------------------------------------------------------------------- no type
@pytest.mark.parametrize(("pub_client", "sub_client"), ALL)
def test_subscribe_without_type_to_a_known_topic(rwt_server, tmp_path, pub_client, sub_client):
    """Once a topic is advertised, a subscriber may leave the type out.

    roslib then sends no `type`; roslibpy sends `"type": null`.
    """
    phases = [
        (
            "pub",
            [
                connect("pub"),
                advertise("pub", "/typed_by_pub", "std_msgs/msg/Float64"),
                sync("pub"),
            ],
        ),
        ("sub", [connect("sub"), subscribe("sub", "/typed_by_pub", None), sync("sub")]),
        ("pub", [publish("pub", "/typed_by_pub", {"data": 2.5}, {"data": -0.125}), sync("pub")]),
        ("sub", [wait("sub", "/typed_by_pub", 2)]),
    ]
    out = run_scenario(rwt_server.url, phases, {"pub": pub_client, "sub": sub_client}, tmp_path)
    assert out.got("sub", "/typed_by_pub") == [{"data": 2.5}, {"data": -0.125}]
    assert_no_error_status(out)
