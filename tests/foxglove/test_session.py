"""The Foxglove session without I/O: what a client sees for what it sends and the graph does."""

from __future__ import annotations

import json
import struct

import pytest

from rwt_foxglove import FoxgloveLimits
from rwt_foxglove.protocol import select_subprotocol
from rwt_graph.graph import Graph
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.runtime.access import AccessPolicy
from rwt_protocol.runtime.rules import ClientRules
from tests.foxglove.sansio import Client, cdr


def test_subprotocol_is_the_first_foxglove_name_offered() -> None:
    assert select_subprotocol(["foxglove.websocket.v1", "foxglove.sdk.v1"]) == (
        "foxglove.websocket.v1"
    )
    assert select_subprotocol(["chat", "foxglove.sdk.v1"]) == "foxglove.sdk.v1"
    assert select_subprotocol(["chat"]) is None
    assert select_subprotocol([]) is None


def test_server_info_comes_first_then_the_published_topics(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    graph.create_publisher("/chatter", "std_msgs/msg/String")
    graph.create_subscription("/only_subscribed", lambda msg: None, "std_msgs/msg/String")
    client = Client(graph)
    info = client.ops[0]
    assert info["op"] == "serverInfo"
    assert info["capabilities"] == ["clientPublish", "services", "connectionGraph"]
    assert info["supportedEncodings"] == ["cdr", "json"]
    assert info["sessionId"] == "s1"
    channel = client.channel("/chatter")
    assert channel["encoding"] == "cdr"
    assert channel["schemaName"] == "std_msgs/msg/String"
    assert channel["schemaEncoding"] == "ros2msg"
    assert channel["schema"] == "string data\n"
    with pytest.raises(AssertionError):
        client.channel("/only_subscribed")  # no publisher: nothing to show


def test_image_schema_carries_header_and_time_after_rules(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    graph.create_publisher("/image", "sensor_msgs/msg/Image")
    schema = str(Client(graph).channel("/image")["schema"])
    rule = "=" * 80
    assert f"{rule}\nMSG: std_msgs/Header\n" in schema
    assert f"{rule}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n" in schema


def test_ros1_graph_speaks_ros1() -> None:
    graph = Graph(TypeRegistry(Dialect.ROS1))
    publisher = graph.create_publisher("/chatter", "std_msgs/String")
    client = Client(graph)
    assert client.ops[0]["supportedEncodings"] == ["ros1", "json"]
    channel = client.channel("/chatter")
    assert (channel["encoding"], channel["schemaEncoding"]) == ("ros1", "ros1msg")
    assert channel["schemaName"] == "std_msgs/String"
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]})
    publisher.publish({"data": "hi"})
    client.drain()
    assert client.data()[0][2] == struct.pack("<I", 2) + b"hi"


def test_subscribe_delivers_in_order_and_unsubscribe_stops(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    client = Client(graph)
    cid = client.channel("/chatter")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": cid}]})
    for i in range(3):
        publisher.publish({"data": f"m{i}"})
    client.drain()
    got = client.data()
    assert [sid for sid, _, _ in got] == [7, 7, 7]
    assert [payload for _, _, payload in got] == [
        cdr(graph, "std_msgs/msg/String", {"data": f"m{i}"}) for i in range(3)
    ]
    assert all(log_time > 1_600_000_000 * 10**9 for _, log_time, _ in got)
    client.send({"op": "unsubscribe", "subscriptionIds": [7]})
    publisher.publish({"data": "after"})
    client.drain()
    assert client.data() == []
    assert client.take_ops("status") == []


def test_one_subscription_per_channel_and_the_latched_message_goes_to_each_new_one(
    ros2_types: TypeRegistry,
) -> None:
    """A second subscription of a channel is refused, as the Foxglove SDK's server ignores it:
    4096 subscriptions of one channel would make each message 4096 frames."""
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/map", "std_msgs/msg/String", latch=True)
    publisher.publish({"data": "kept"})
    client = Client(graph)
    cid = client.channel("/map")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": cid}]})
    client.send(
        {"op": "subscribe", "subscriptions": [{"id": n, "channelId": cid} for n in range(2, 4098)]}
    )
    (status,) = client.take_ops("status")  # one status for the 4096 refused entries
    assert status["message"] == (
        f"subscribe: channel {cid} is subscribed already (subscription 1); "
        f"channel {cid} is subscribed already (subscription 1); "
        f"channel {cid} is subscribed already (subscription 1) (and 4093 more refused)"
    )
    expected = cdr(graph, "std_msgs/msg/String", {"data": "kept"})
    assert [(sid, payload) for sid, _, payload in client.data()] == [(1, expected)]
    publisher.publish({"data": "next"})
    client.drain()
    assert [sid for sid, _, _ in client.data()] == [1]  # one frame a message
    client.send({"op": "unsubscribe", "subscriptionIds": [1]})
    client.send({"op": "subscribe", "subscriptions": [{"id": 2, "channelId": cid}]})
    assert [(sid, payload) for sid, _, payload in client.data()] == [
        (2, cdr(graph, "std_msgs/msg/String", {"data": "next"}))
    ]


def test_a_message_that_cannot_be_encoded_is_skipped_and_said_once(
    ros2_types: TypeRegistry,
) -> None:
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    client = Client(graph)
    cid = client.channel("/chatter")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": cid}]})
    for _ in range(2):  # vouched for, but not a String: it cannot be serialized
        publisher.publish({"wrong": 1}, validated=True)
    publisher.publish({"data": "after"})
    client.drain()
    statuses = client.take_ops("status")
    assert [(s["level"], s["message"]) for s in statuses] == [
        (2, "/chatter: cannot encode its messages")
    ]
    expected = cdr(graph, "std_msgs/msg/String", {"data": "after"})
    assert [(sid, payload) for sid, _, payload in client.data()] == [(1, expected)]


def test_topics_that_appear_and_go_are_advertised_and_unadvertised(
    ros2_types: TypeRegistry,
) -> None:
    graph = Graph(ros2_types)
    client = Client(graph)
    publisher = graph.create_publisher("/late", "std_msgs/msg/String")
    client.sync()
    cid = client.channel("/late")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 3, "channelId": cid}]})
    publisher.close()
    client.sync()
    assert client.take_ops("unadvertise") == [{"op": "unadvertise", "channelIds": [cid]}]
    assert "/late" not in graph.topics  # the subscription went with the channel
    again = graph.create_publisher("/late", "std_msgs/msg/String")
    client.sync()
    client.ops = client.ops[-1:]
    assert client.channel("/late")["id"] != cid
    again.publish({"data": "x"})
    client.drain()
    assert client.data() == []  # the old subscription is gone


def test_access_globs_hide_topics(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    graph.create_publisher("/public/a", "std_msgs/msg/String")
    graph.create_publisher("/secret", "std_msgs/msg/String")
    client = Client(graph, access=AccessPolicy(topics=("/public/*",)))
    client.channel("/public/a")
    with pytest.raises(AssertionError):
        client.channel("/secret")
    client.send(
        {
            "op": "advertise",
            "channels": [{"id": 1, "topic": "/secret", "encoding": "json", "schemaName": "x/X"}],
        }
    )
    assert "not allowed" in str(client.take_ops("status")[0]["message"])


def test_split_globs_bind_a_foxglove_client(ros2_types: TypeRegistry) -> None:
    # --topics-pub-glob [/cmd] --topics-sub-glob [/state] (D50): channels are for
    # subscribing, so /cmd has none; the client may advertise /cmd, not /state
    graph = Graph(ros2_types)
    graph.create_publisher("/cmd", "std_msgs/msg/String")
    graph.create_publisher("/state", "std_msgs/msg/String")
    client = Client(graph, access=AccessPolicy(topics_pub=("/cmd",), topics_sub=("/state",)))
    client.channel("/state")
    with pytest.raises(AssertionError):
        client.channel("/cmd")
    for cid, topic in ((1, "/cmd"), (2, "/state")):
        channel = {
            "id": cid,
            "topic": topic,
            "encoding": "json",
            "schemaName": "std_msgs/msg/String",
        }
        client.send({"op": "advertise", "channels": [channel]})
    [status] = client.take_ops("status")
    assert status["message"] == "advertise: topic /state is not allowed on this server"
    assert "foxglove:test#1" in graph.topics["/cmd"].publishers
    assert "foxglove:test#1" not in graph.topics["/state"].publishers


@pytest.mark.parametrize(
    ("frame", "binary", "expected"),
    [
        (b'{"op": "nope"}', False, "unknown op 'nope'"),
        (b'{"op": "getParameters", "parameterNames": []}', False, "not supported"),
        (b"{not json", False, "invalid JSON"),
        (b"[1, 2]", False, "expected a JSON object"),
        (b'{"op": "subscribe"}', False, "subscriptions"),
        (b'{"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 999}]}', False, "999"),
        (b'{"op": "subscribe", "subscriptions": [{"id": -1, "channelId": 1}]}', False, "32-bit"),
        (b'{"op": "unsubscribe", "subscriptionIds": [42]}', False, "unknown subscription 42"),
        (b'{"op": "unadvertise", "channelIds": [5]}', False, "unknown client channel 5"),
        (b'{"op": "subscribe", "x": "\\ud800"}', False, "surrogate"),
        (b'{"op": "unsubscribe", "subscriptionIds": [1' + b"0" * 40 + b"]}", False, "64 bits"),
        (b"[" * 500 + b"]" * 500, False, "nesting"),
        (b"\x09abc", True, "unknown binary opcode 0x09"),
        (b"\x01\x00", True, "shorter than its 5-byte header"),
        (b"", True, "empty binary frame"),
        (b"\x01\x07\x00\x00\x00payload", True, "unknown client channel 7"),
        (b"\x02\x00\x00\x00\x00", True, "shorter than its 13-byte header"),
        (b"\x02" + struct.pack("<III", 1, 1, 99) + b"cdr", True, "past the frame's end"),
        (b"\x02" + struct.pack("<III", 1, 1, 2) + b"\xff\xfe", True, "not UTF-8"),
        (b'{"op": "fetchAsset", "uri": "x", "requestId": 1}', False, "not supported"),
    ],
)
def test_bad_input_gets_an_error_status_and_the_session_goes_on(
    ros2_types: TypeRegistry, frame: bytes, binary: bool, expected: str
) -> None:
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/chatter", "std_msgs/msg/String")
    client = Client(graph)
    client.send_raw(frame, binary=binary)
    statuses = client.take_ops("status")
    assert len(statuses) == 1, statuses
    assert statuses[0]["level"] == 2
    assert expected in str(statuses[0]["message"]), statuses
    cid = client.channel("/chatter")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": cid}]})
    publisher.publish({"data": "still here"})
    client.drain()
    assert len(client.data()) == 1


def test_client_publish_cdr_and_json_reach_graph_subscribers(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    got: list[dict[str, object]] = []
    graph.create_subscription("/cmd", got.append, "geometry_msgs/msg/Twist")
    client = Client(graph)
    client.send(
        {
            "op": "advertise",
            "channels": [
                {
                    "id": 1,
                    "topic": "/cmd",
                    "encoding": "cdr",
                    "schemaName": "geometry_msgs/msg/Twist",
                },
                {"id": 2, "topic": "/cmd", "encoding": "json", "schemaName": "geometry_msgs/Twist"},
            ],
        }
    )
    assert client.take_ops("status") == []
    twist = {"linear": {"x": 1.5, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": -2.0}}
    client.send_raw(
        b"\x01" + struct.pack("<I", 1) + cdr(graph, "geometry_msgs/msg/Twist", twist), binary=True
    )
    client.send_raw(
        b"\x01" + struct.pack("<I", 2) + json.dumps({"linear": {"x": 3}}).encode(), binary=True
    )
    assert client.take_ops("status") == []
    assert got[0] == twist
    assert got[1]["linear"] == {"x": 3.0, "y": 0.0, "z": 0.0}
    client.send_raw(b"\x01" + struct.pack("<I", 1) + b"\x00\x01\x00\x00\x01", binary=True)
    assert "not a cdr message" in str(client.take_ops("status")[0]["message"])
    client.send({"op": "unadvertise", "channelIds": [1]})
    client.send_raw(b"\x01" + struct.pack("<I", 1) + b"\x00\x01\x00\x00", binary=True)
    assert "unknown client channel 1" in str(client.take_ops("status")[0]["message"])
    assert len(got) == 2  # withdrawn: the data reached nobody
    client.send_raw(b"\x01" + struct.pack("<I", 2) + b'{"linear": {"x": "fast"}}', binary=True)
    assert client.take_ops("status")[0]["level"] == 2
    assert len(got) == 2


def test_client_advertise_refusals(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    graph.create_publisher("/chatter", "std_msgs/msg/String")
    client = Client(graph, limits=FoxgloveLimits(max_client_channels=1))
    channel = {"id": 1, "topic": "/chatter", "encoding": "protobuf", "schemaName": "a/B"}
    cases = [
        (channel, "encoding 'protobuf' is not supported"),
        ({**channel, "encoding": "json", "topic": "bad topic"}, "topic:"),
        ({**channel, "encoding": "json", "schemaName": "std_msgs/Int32"}, "std_msgs/msg/String"),
        ({**channel, "encoding": "json", "schemaName": "no_such/msg/Type"}, "no_such"),
    ]
    for spec, expected in cases:
        client.send({"op": "advertise", "channels": [spec]})
        status = client.take_ops("status")
        assert len(status) == 1 and expected in str(status[0]["message"]), (spec, status)
    ok = {**channel, "encoding": "json", "schemaName": "std_msgs/msg/String"}
    client.send({"op": "advertise", "channels": [ok, {**ok, "id": 2}]})
    assert "more than 1 channels" in str(client.take_ops("status")[0]["message"])
    client.send({"op": "advertise", "channels": [ok]})
    assert "id 1 is in use" in str(client.take_ops("status")[0]["message"])


def test_subscription_limits_and_reused_ids(ros2_types: TypeRegistry) -> None:
    """``--max-subscriptions`` binds a Foxglove client as it binds a rosbridge one."""
    graph = Graph(ros2_types)
    graph.create_publisher("/a", "std_msgs/msg/String")
    graph.create_publisher("/b", "std_msgs/msg/String")
    client = Client(graph, config=ClientRules(max_subscriptions=1))
    cid = client.channel("/a")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": cid}]})
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": cid}]})
    assert "in use" in str(client.take_ops("status")[0]["message"])
    other = client.channel("/b")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 2, "channelId": other}]})
    assert client.take_ops("status")[0]["message"] == (
        "subscribe: more than 1 subscriptions (--max-subscriptions)"
    )


def test_a_slow_client_drops_its_oldest_data_and_hears_once_per_episode(
    ros2_types: TypeRegistry,
) -> None:
    graph = Graph(ros2_types)
    publisher = graph.create_publisher("/fast", "std_msgs/msg/String")
    client = Client(graph, limits=FoxgloveLimits(max_queue_messages=5))
    cid = client.channel("/fast")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": cid}]})
    for i in range(20):  # nobody takes: the client reads nothing meanwhile
        publisher.publish({"data": str(i)})
    client.drain()
    statuses = client.take_ops("status")
    assert len(statuses) == 1 and statuses[0]["level"] == 1
    assert "dropped" in str(statuses[0]["message"])
    # a lasting condition: its status has an id, withdrawn once the queue is empty again
    assert client.take_ops("removeStatus") == [
        {"op": "removeStatus", "statusIds": [statuses[0]["id"]]}
    ]
    payloads = [payload for _, _, payload in client.data()]
    assert payloads == [cdr(graph, "std_msgs/msg/String", {"data": str(i)}) for i in range(15, 20)]
    assert client.session.dropped == 15
    for i in range(20):  # a new episode after the queue was empty
        publisher.publish({"data": str(i)})
    client.drain()
    assert len(client.take_ops("status")) == 1


def test_close_releases_the_graph(ros2_types: TypeRegistry) -> None:
    graph = Graph(ros2_types)
    graph.create_publisher("/a", "std_msgs/msg/String")
    client = Client(graph)
    cid = client.channel("/a")["id"]
    client.send({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": cid}]})
    client.send(
        {
            "op": "advertise",
            "channels": [
                {"id": 1, "topic": "/b", "encoding": "json", "schemaName": "std_msgs/String"}
            ],
        }
    )
    assert "/b" in graph.topics and graph.topics["/a"].subscribers
    client.session.close()
    assert "/b" not in graph.topics and not graph.topics["/a"].subscribers


def test_topics_left_out_are_told_once_and_withdrawn_when_all_fit_again(
    ros2_types: TypeRegistry,
) -> None:
    graph = Graph(ros2_types)
    client = Client(graph, limits=FoxgloveLimits(max_channels=1))
    extra = [graph.create_publisher(f"/extra{n}", "std_msgs/msg/String") for n in range(3)]
    client.sync()
    assert len(client.take_ops("advertise")[0]["channels"]) == 1  # type: ignore[arg-type]
    (warning,) = client.take_ops("status")
    assert "2 topics are not advertised" in str(warning["message"]) and warning["id"]
    assert client.take_ops("removeStatus") == []
    for publisher in extra[1:]:
        publisher.close()
    client.sync()
    assert client.take_ops("removeStatus") == [{"op": "removeStatus", "statusIds": [warning["id"]]}]
    assert client.take_ops("status") == []  # told once, withdrawn once
