"""Foxglove parameters without I/O: get, set, and updates pushed from every side."""

from __future__ import annotations

import json

from rwt_foxglove import FoxgloveLimits
from rwt_foxglove.params import MAX_ANSWER_BYTES
from rwt_graph.graph import Graph
from rwt_graph.parameters.store import Parameters
from rwt_graph.rosapi import install_rosapi
from rwt_graph.types import Dialect, TypeRegistry
from rwt_protocol.runtime.access import AccessPolicy
from tests.conftest import Peer
from tests.foxglove.sansio import Client

BIG = 2**62 + 1


def _robot(graph: Graph) -> None:
    graph.params.declare("/robot", {"speed": 1.5, "name": "r2", "count": BIG, "gains": [1.0, 2.5]})
    graph.params.declare("/robot", {"serial": "x1"}, read_only=True)


def _values(client: Client) -> list[dict[str, object]]:
    return client.take_ops("parameterValues")


def _errors(client: Client) -> list[str]:
    return [str(op["message"]) for op in client.take_ops("status") if op["level"] == 2]


def test_capabilities_announce_parameters_only_with_the_store(graph: Graph) -> None:
    with_params = Client(graph, with_params=True).ops[0]["capabilities"]
    assert with_params == [
        "clientPublish",
        "services",
        "connectionGraph",
        "parameters",
        "parametersSubscribe",
    ]
    without = Client(graph)
    assert "parameters" not in without.ops[0]["capabilities"]  # type: ignore[operator]
    without.send({"op": "getParameters", "parameterNames": []})
    assert _errors(without) == ["parameters are not supported by this server"]


def test_get_by_name_and_all_with_types_for_floats(graph: Graph) -> None:
    _robot(graph)
    client = Client(graph, with_params=True)
    client.send(
        {
            "op": "getParameters",
            "parameterNames": ["/robot.speed", "/robot.count", "/robot.nope"],
            "id": "q1",
        }
    )
    assert _values(client) == [
        {
            "op": "parameterValues",
            "id": "q1",
            "parameters": [
                {"name": "/robot.speed", "value": 1.5, "type": "float64"},
                {"name": "/robot.count", "value": BIG},
            ],
        }
    ]
    client.send({"op": "getParameters", "parameterNames": []})
    [answer] = _values(client)
    assert "id" not in answer
    assert answer["parameters"] == [
        {"name": "/robot.count", "value": BIG},
        {"name": "/robot.gains", "value": [1.0, 2.5], "type": "float64_array"},
        {"name": "/robot.name", "value": "r2"},
        {"name": "/robot.serial", "value": "x1"},
        {"name": "/robot.speed", "value": 1.5, "type": "float64"},
    ]


def test_bad_names_get_a_status_and_the_rest_an_answer(graph: Graph) -> None:
    _robot(graph)
    client = Client(graph, with_params=True)
    client.send({"op": "getParameters", "parameterNames": ["no_separator", "/robot.name"]})
    assert "expected <node>.<parameter>" in _errors(client)[0]
    assert _values(client)[0]["parameters"] == [{"name": "/robot.name", "value": "r2"}]
    client.send({"op": "getParameters", "parameterNames": "not a list"})
    assert "getParameters" in _errors(client)[0]
    client.send({"op": "getParameters", "parameterNames": ["/" + "n" * 100_000 + ".p"]})
    [error] = _errors(client)
    assert "longer than" in error and len(error) < 200


def test_set_answers_with_the_values_and_refusals_are_statuses(graph: Graph) -> None:
    _robot(graph)
    client = Client(graph, with_params=True)
    client.send(
        {
            "op": "setParameters",
            "id": "s1",
            "parameters": [
                {"name": "/robot.speed", "value": 3},  # a declared double takes an int
                {"name": "/robot.fresh", "value": 2, "type": "float64"},
                {"name": "/robot.count", "value": BIG + 1},
                {"name": "/robot.serial", "value": "changed"},
                {"name": "/robot.name", "value": 7},
                {"name": "/ghost.p", "value": 1},
                {"name": "/robot.bytes", "value": "AAE", "type": "byte_array"},  # unpadded
                {"name": "/robot.gains"},  # no value: deleted
            ],
        }
    )
    errors = _errors(client)
    assert len(errors) == 4, errors
    assert "read-only" in errors[0]
    assert "has type string" in errors[1]
    assert "node /ghost does not exist" in errors[2]
    assert errors[3] == "setParameters: /robot.bytes: a byte_array parameter needs base64 text"
    assert _values(client) == [
        {
            "op": "parameterValues",
            "id": "s1",
            "parameters": [
                {"name": "/robot.speed", "value": 3.0, "type": "float64"},
                {"name": "/robot.fresh", "value": 2.0, "type": "float64"},
                {"name": "/robot.count", "value": BIG + 1},
            ],
        }
    ]
    assert graph.params.get("/robot:speed") == 3.0
    assert graph.params.get("/robot:count") == BIG + 1
    assert not graph.params.has("/robot:gains")
    client.send({"op": "setParameters", "parameters": [{"name": "/robot.name", "value": "r3"}]})
    assert _values(client) == []  # no id: no answer
    assert graph.params.get("/robot:name") == "r3"


def test_byte_arrays_go_out_and_come_in_as_base64(graph: Graph) -> None:
    graph.params.declare("/robot", {"key": b"\x00\x01\xfb\xff", "empty": b"", "name": "r2"})
    client = Client(graph, with_params=True)
    client.send({"op": "subscribeParameterUpdates", "parameterNames": ["/robot.key"]})
    client.send(
        {"op": "getParameters", "parameterNames": ["/robot.key", "/robot.empty"], "id": "g"}
    )
    assert _values(client)[0]["parameters"] == [
        {"name": "/robot.key", "value": "AAH7/w==", "type": "byte_array"},
        {"name": "/robot.empty", "value": "", "type": "byte_array"},
    ]
    client.send(
        {
            "op": "setParameters",
            "id": "s",
            "parameters": [
                {"name": "/robot.key", "value": "3q2+7w==", "type": "byte_array"},
                {"name": "/robot.fresh", "value": "", "type": "byte_array"},
                {"name": "/robot.name", "value": "AA==", "type": "byte_array"},
            ],
        }
    )
    assert _errors(client) == [
        "setParameters: parameter /robot:name has type string, not byte_array"
    ]
    assert _values(client) == [  # the update pushed as it was made, then the answer
        {
            "op": "parameterValues",
            "parameters": [{"name": "/robot.key", "value": "3q2+7w==", "type": "byte_array"}],
        },
        {
            "op": "parameterValues",
            "id": "s",
            "parameters": [
                {"name": "/robot.key", "value": "3q2+7w==", "type": "byte_array"},
                {"name": "/robot.fresh", "value": "", "type": "byte_array"},
            ],
        },
    ]
    assert graph.params.get("/robot:key") == b"\xde\xad\xbe\xef"
    assert graph.params.get("/robot:fresh") == b""


def test_bad_base64_is_a_status_naming_the_parameter_and_the_rest_is_set(graph: Graph) -> None:
    graph.params.declare("/robot", {"key": b"\x01", "speed": 1.5})
    client = Client(graph, with_params=True)
    bad = ["AAE", "AA=E", "A-_=", "not base64!", "é===", 5, [0, 1], {"a": 1}, True]
    client.send(
        {
            "op": "setParameters",
            "id": "s",
            "parameters": [
                *({"name": "/robot.key", "value": value, "type": "byte_array"} for value in bad),
                {"name": "/robot.speed", "value": 2, "type": "float64"},
            ],
        }
    )
    assert _errors(client) == [
        "setParameters: /robot.key: a byte_array parameter needs base64 text"
    ] * len(bad)
    assert _values(client)[0]["parameters"] == [
        {"name": "/robot.speed", "value": 2.0, "type": "float64"}
    ]
    assert graph.params.get("/robot:key") == b"\x01"


def test_ros1_refuses_a_byte_array_with_a_status(graph: Graph) -> None:
    ros1 = Graph(TypeRegistry(Dialect.ROS1))
    client = Client(ros1, with_params=True)
    client.send(
        {
            "op": "setParameters",
            "parameters": [{"name": "/k", "value": "AA==", "type": "byte_array"}],
        }
    )
    assert "a ROS 1 parameter cannot be bytes" in _errors(client)[0]
    assert not ros1.params.has("/k")


def test_changes_from_every_side_are_pushed_to_subscribers(graph: Graph) -> None:
    _robot(graph)
    install_rosapi(graph)
    client = Client(graph, with_params=True)
    other = Client(graph, with_params=True)
    client.send(
        {"op": "subscribeParameterUpdates", "parameterNames": ["/robot.speed", "/robot.name"]}
    )
    peer = Peer(graph, "rb")
    peer.send(
        op="call_service",
        service="/rosapi/set_param",
        args={"name": "/robot:speed", "value": "2.25"},
    )
    client.drain()
    assert _values(client) == [
        {
            "op": "parameterValues",
            "parameters": [{"name": "/robot.speed", "value": 2.25, "type": "float64"}],
        }
    ]
    other.send(
        {"op": "setParameters", "parameters": [{"name": "/robot.name", "value": "from fox"}]}
    )
    graph.params.set("/robot:count", 5)  # not watched
    client.drain()
    assert _values(client) == [
        {"op": "parameterValues", "parameters": [{"name": "/robot.name", "value": "from fox"}]}
    ]
    graph.params.delete("/robot:name")
    client.drain()
    assert _values(client) == [{"op": "parameterValues", "parameters": [{"name": "/robot.name"}]}]
    client.send(
        {"op": "unsubscribeParameterUpdates", "parameterNames": ["/robot.speed", "/not.watched"]}
    )
    graph.params.set("/robot:speed", 9.0)
    client.drain()
    assert _values(client) == [] and _errors(client) == []


def test_changes_while_an_update_waits_are_merged_into_the_next(graph: Graph) -> None:
    _robot(graph)
    client = Client(graph, with_params=True)
    client.send(
        {"op": "subscribeParameterUpdates", "parameterNames": ["/robot.speed", "/robot.name"]}
    )
    for speed in (2.0, 3.0, 4.0):  # the client reads nothing meanwhile
        graph.params.set("/robot:speed", speed)
    graph.params.set("/robot:name", "late")
    client.drain()
    assert [op["parameters"] for op in _values(client)] == [
        [{"name": "/robot.speed", "value": 2.0, "type": "float64"}],
        [
            {"name": "/robot.speed", "value": 4.0, "type": "float64"},
            {"name": "/robot.name", "value": "late"},
        ],
    ]


def test_subscriptions_are_bounded_and_hidden_names_refused(graph: Graph) -> None:
    _robot(graph)
    client = Client(
        graph,
        with_params=True,
        limits=FoxgloveLimits(max_parameter_subscriptions=2),
        access=AccessPolicy(params=("/robot:*",)),
    )
    client.send(
        {"op": "subscribeParameterUpdates", "parameterNames": ["/robot.a", "/robot.b", "/robot.c"]}
    )
    assert _errors(client) == ["subscribeParameterUpdates: more than 2 parameters"]
    graph.params.declare("/arm", {"x": 1})
    client.send({"op": "getParameters", "parameterNames": ["/arm.x"]})
    assert _errors(client) == ["getParameters: parameter /arm:x is not allowed"]
    client.send({"op": "getParameters", "parameterNames": []})
    names = [each["name"] for each in _values(client)[-1]["parameters"]]  # type: ignore[attr-defined]
    assert names and all(name.startswith("/robot.") for name in names)


def test_ros1_names_are_global(graph: Graph) -> None:
    ros1 = Graph(TypeRegistry(Dialect.ROS1))
    ros1.params.set("/robot/speed", 1.5)
    client = Client(ros1, with_params=True)
    client.send(
        {"op": "setParameters", "id": "a", "parameters": [{"name": "/robot/size", "value": 3}]}
    )
    assert _values(client)[0]["parameters"] == [{"name": "/robot/size", "value": 3}]
    client.send({"op": "getParameters", "parameterNames": []})
    assert _values(client)[0]["parameters"] == [
        {"name": "/robot/size", "value": 3},
        {"name": "/robot/speed", "value": 1.5, "type": "float64"},
    ]


def test_a_large_value_is_one_object_for_every_reader_and_idle_clients_cost_nothing(
    graph: Graph,
) -> None:
    _robot(graph)
    idle = [Client(graph, with_params=True, client_id=f"foxglove:idle#{n}") for n in range(50)]
    watcher = Client(graph, with_params=True, client_id="foxglove:watcher#1")
    watcher.send({"op": "subscribeParameterUpdates", "parameterNames": ["/robot.big"]})
    heard: list[object] = []
    graph.params.watch(lambda name, value: heard.append(value), key="/robot:big")
    big = list(range(1_000_000))
    setter = idle[0]
    parameters = [{"name": "/robot.big", "value": big}]
    setter.send({"op": "setParameters", "parameters": parameters, "id": "s"})
    held = graph.params.get("/robot:big")
    assert heard == [held] and heard[0] is held  # the store's own value, not a copy
    assert graph.params.get("/robot:big") is held  # and so for every reader
    [answer] = _values(setter)
    assert answer["id"] == "s" and answer["parameters"] == [{"name": "/robot.big", "value": big}]
    watcher.drain()
    [update] = _values(watcher)
    assert update["parameters"] == [{"name": "/robot.big", "value": big}]
    for client in idle[1:]:
        client.drain()
    assert [client for client in idle[1:] if _values(client)] == []  # the others: nothing


def test_every_parameter_comes_within_the_answer_bound_and_the_rest_is_named(
    graph: Graph,
) -> None:
    blob = "x" * (1536 * 1024)  # 1.5 MiB: two fit in one answer
    graph.params.declare("/robot", {f"blob{n}": blob for n in range(4)})
    client = Client(graph, with_params=True)
    client.send({"op": "getParameters", "parameterNames": [], "id": "all"})  # 56 bytes of request
    [answer] = _values(client)
    assert len(json.dumps(answer)) <= MAX_ANSWER_BYTES
    assert [each["name"] for each in answer["parameters"]] == ["/robot.blob0", "/robot.blob1"]  # type: ignore[index]
    assert _errors(client) == [
        "getParameters: 2 of 4 parameters left out (an answer holds at most 4194304 bytes): "
        "ask for them by name, fewer at a time"
    ]
    client.send({"op": "getParameters", "parameterNames": ["/robot.blob3"] * 100, "id": "one"})
    [answer] = _values(client)  # a name asked a hundred times is answered once
    assert answer["parameters"] == [{"name": "/robot.blob3", "value": blob}]
    assert _errors(client) == []


def test_a_client_is_charged_for_what_it_sets_and_its_node_goes_with_it() -> None:
    graph = Graph()
    graph.params = Parameters(max_params=80, client_share=0.1, nodes=graph.nodes)
    client_id = "foxglove:a#1"
    node = graph.nodes.attach(client_id)
    client = Client(graph, with_params=True, client_id=client_id)
    install_rosapi(graph)
    parameters = [{"name": f"{node}.p{n}", "value": n} for n in range(10)]
    parameters.append({"name": "/rosapi.mine", "value": 1})
    client.send({"op": "setParameters", "parameters": parameters, "id": "s"})
    errors = _errors(client)
    assert len(errors) == 3, errors
    assert all(
        "this client holds its share of the parameter store (8 parameters)" in e for e in errors[:2]
    )
    assert "node /rosapi is the server's" in errors[2]
    assert len(_values(client)[0]["parameters"]) == 8  # type: ignore[arg-type]
    assert graph.params.held_by(client_id) == (8, 64)
    client.session.close()  # the connection went: its node's parameters with it
    assert graph.params.names() == [] and graph.params.held_by(client_id) == (0, 0)
