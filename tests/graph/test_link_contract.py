"""The link contract (rwt_graph.link) and the parts links share: parameter copies, CDR reading."""

from __future__ import annotations

import pytest

from rwt_graph.exports import Exports
from rwt_graph.graph import Graph
from rwt_graph.link import (
    NULL_SINK,
    OPEN_GATE,
    PRIVATE_NAMES,
    RELAY_WAIT_SWEEPS,
    Kind,
    LinkRules,
    Relays,
    matches_private,
    mirror_endpoint,
)
from rwt_graph.parameters.replicas import ParamReplicas
from rwt_graph.parameters.services import MAX_REQUEST_ITEMS, answer, param_nodes
from rwt_graph.parameters.store import ParameterError
from rwt_graph.parameters.wire import from_wire, to_wire, type_code
from rwt_graph.types import Dialect, TypeRegistry
from rwt_graph.types.hashes import message_type_hash
from rwt_graph.types.wire import CDR_TRAILING_SLACK, CdrError, read_cdr
from rwt_protocol.errors import GraphError, RwtError
from rwt_protocol.ports import MessageEvent
from rwt_transports.server import RosbridgeServer, ServerConfig

STRING = "std_msgs/msg/String"


class _Sink:
    def on_message(self, event: MessageEvent) -> None:
        pass


def test_private_names_match_exactly_or_by_prefix() -> None:
    assert matches_private("/client_count", PRIVATE_NAMES)
    assert matches_private("/rosapi/topics", PRIVATE_NAMES)
    assert not matches_private("/client_count_2", PRIVATE_NAMES)
    assert not matches_private("/chatter", PRIVATE_NAMES)


def test_a_server_shares_the_robots_tf_but_keeps_its_helpers_to_itself() -> None:
    # what rwt serve installs: rosapi, the client counts and the TF republisher
    graph = Graph()
    RosbridgeServer(graph, ServerConfig(port=0))
    exports = Exports(graph.port.feed, LinkRules("link:"))
    exports.open()
    names = {name for _, _, name in shared(exports)}
    # the republisher's /tf and /tf_static subscriptions bring the robot's TF in
    assert names == {"/tf", "/tf_static"}
    assert matches_private("/tf2_web_republisher/goal", PRIVATE_NAMES)
    assert not matches_private("/tf2_web_republisher_2", PRIVATE_NAMES)


def shared(exports: Exports) -> dict[tuple[Kind, str, str], tuple[str, bool]]:
    """What a link shares now: (kind, participant, name) -> (type, latched)."""
    return {
        key: (change.type_name, change.latched)
        for entities in exports.current.values()
        for key, change in entities.items()
    }


def test_rules_share_only_local_entities_and_no_private_names() -> None:
    graph = Graph()
    rules = LinkRules("link:")
    exports = Exports(graph.port.feed, rules)
    graph.port.advertise("ws:1", "/chatter", STRING, latch=True)
    exports.open()  # what the graph has when the link starts, then its changes
    graph.port.subscribe("ws:2", "/chatter", STRING, _Sink())
    graph.port.advertise("link:remote", "/chatter", STRING)  # came from outside
    graph.port.subscribe("link:remote2", "/heard", STRING, NULL_SINK)
    graph.port.advertise("ws:1", "/client_count", "std_msgs/msg/Int32")
    graph.create_service("/add", "std_srvs/srv/SetBool", lambda request: {"success": True})
    wanted = shared(exports)
    assert wanted[(Kind.PUBLISHER, "ws:1", "/chatter")] == (STRING, True)
    assert wanted[(Kind.SUBSCRIPTION, "ws:2", "/chatter")] == (STRING, False)
    assert [k[2] for k in wanted if k[0] is Kind.SERVICE] == ["/add"]
    assert len(wanted) == 3  # no entity of the link's, nothing private
    assert rules.ours("link:remote") and not rules.ours("ws:1")
    assert rules.forwards("ws:1", "/chatter")
    assert not rules.forwards("link:remote", "/chatter")  # came in: never back out
    assert not rules.forwards("ws:1", "/rosapi/topics")
    NULL_SINK.on_message(MessageEvent("/heard", STRING, {"data": ""}, 0.0))  # drops it


def test_exports_hold_each_changed_entity_once_in_one_backlog() -> None:
    """A link applies the feed's changes when it can: each entity once, as it is now."""
    graph = Graph()
    woken: list[bool] = []
    exports = Exports(graph.port.feed, LinkRules("link:"), on_backlog=lambda: woken.append(True))
    exports.open()
    assert exports.take() == {} and not exports.pending
    graph.port.advertise("ws:1", "/odom", STRING)
    graph.port.advertise("ws:1", "/odom", STRING, latch=True)  # removed and added again
    graph.port.subscribe("ws:2", "/cmd", STRING, _Sink())
    graph.port.unsubscribe("ws:2", "/cmd")
    graph.port.advertise("link:far", "/odom", STRING)  # the link's own: not its to share
    assert woken == [True]  # once: when the backlog stopped being empty
    taken = exports.take()
    assert set(taken) == {(Kind.PUBLISHER, "ws:1", "/odom"), (Kind.SUBSCRIPTION, "ws:2", "/cmd")}
    odom = taken[(Kind.PUBLISHER, "ws:1", "/odom")]
    assert odom is not None and odom.latched
    assert taken[(Kind.SUBSCRIPTION, "ws:2", "/cmd")] is None  # gone again
    assert exports.topics(Kind.PUBLISHER) == {"/odom": (STRING, True)}
    graph.port.release("ws:1")
    assert exports.take() == {(Kind.PUBLISHER, "ws:1", "/odom"): None}
    assert woken == [True, True]
    exports.close()
    graph.port.advertise("ws:3", "/late", STRING)
    assert not exports.pending  # a stopped link hears nothing more


def test_exports_follow_a_changing_graph_as_a_walk_of_it_would() -> None:
    """The link's view through the feed is what walking the graph's tables finds."""
    graph = Graph()
    rules = LinkRules("link:")
    exports = Exports(graph.port.feed, rules)
    graph.port.advertise("ws:1", "/a", STRING)
    exports.open()
    for client in ("ws:1", "ws:2", "link:x"):
        graph.port.subscribe(client, "/b", STRING, _Sink())
        graph.port.advertise(client, "/rosapi/topics", STRING)  # private: never shared
    graph.port.release("ws:2")
    graph.port.unadvertise("ws:1", "/a")
    graph.port.advertise("ws:2", "/a", STRING, latch=True)
    walked = {
        (kind, client, name): (entry.msgtype.name, latched)
        for name, entry in graph.topics.items()
        if not rules.is_private(name)
        for kind, members in (
            (Kind.PUBLISHER, entry.publishers),
            (Kind.SUBSCRIPTION, {c: False for c in entry.subscribers}),
        )
        for client, latched in members.items()
        if not rules.ours(client)
    }
    assert shared(exports) == walked


def test_rules_remember_privacy_within_a_bound(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("rwt_graph.link.PRIVATE_CACHE", 3)
    rules = LinkRules("link:")
    for i in range(10):
        assert not rules.is_private(f"/t{i}")
    assert rules.is_private("/rosapi/nodes")
    assert len(rules._private_names) <= 3


def test_local_actions_leave_out_the_links_and_private_ones() -> None:
    graph = Graph()
    exports = Exports(graph.port.feed, LinkRules("link:"))
    exports.open()

    async def fib(goal: dict, context: object) -> dict:
        return {"sequence": []}

    graph.create_action_server("/fib", "example_interfaces/action/Fibonacci", fib)
    graph.create_action_server("/rosapi/fib", "example_interfaces/action/Fibonacci", fib)
    owner = graph.actions.entries["/fib"].owner
    assert {name: c.client for name, c in exports.owners(Kind.ACTION).items()} == {"/fib": owner}
    theirs = Exports(graph.port.feed, LinkRules(owner[:3]))  # the actions' owners are its own
    theirs.open()
    assert theirs.owners(Kind.ACTION) == {}


def test_parameter_values_cross_as_rcl_interfaces_values() -> None:
    value_type = TypeRegistry().message("rcl_interfaces/msg/ParameterValue")
    for value in (True, 3, 2.5, "x", b"\x01", (True,), (1, 2), (1.0, 2.5), ("a",)):
        wire = to_wire(value_type, value)
        assert from_wire(wire) == value  # arrays come back as tuples, as the store holds them
    # a byte array read from CDR holds octets: still a byte array, not integers
    assert from_wire({"type": 5, "byte_array_value": [0, 1, 255]}) == b"\x00\x01\xff"
    for bad in ([256], [-1], ["a"], 5):
        with pytest.raises(ParameterError, match="no octet"):
            from_wire({"type": 5, "byte_array_value": bad})
    assert from_wire(value_type.default()) is None
    assert type_code([]) == type_code(()) == 9  # an empty list is a string array
    assert type_code([1, 2.5]) == 8  # ints and floats: a double array
    with pytest.raises(ParameterError):
        type_code({"a": 1})
    with pytest.raises(ParameterError):
        from_wire({"type": 99})


def test_parameter_copies_follow_a_node_through_its_services() -> None:
    graph = Graph()
    held = {"speed": 1.5, "mode": "auto"}
    value_type = graph.registry.message("rcl_interfaces/msg/ParameterValue")

    def list_parameters(request: dict) -> dict:
        return {"result": {"names": list(held), "prefixes": []}}

    def get_parameters(request: dict) -> dict:
        return {"values": [to_wire(value_type, held[n]) for n in request["names"]]}

    def set_parameters(request: dict) -> dict:
        for parameter in request["parameters"]:
            held[parameter["name"]] = from_wire(parameter["value"])
        return {"results": [{"successful": True, "reason": ""}]}

    services = [
        graph.create_service(f"/robot/{name}", f"rcl_interfaces/srv/{kind}", handler)
        for name, kind, handler in (
            ("list_parameters", "ListParameters", list_parameters),
            ("get_parameters", "GetParameters", get_parameters),
            ("set_parameters", "SetParameters", set_parameters),
        )
    ]
    replicas = ParamReplicas(graph, "link:caller", refresh_sweeps=2)
    replicas.sweep({"/robot", "/absent"})  # /absent has no services: nothing held
    assert graph.params.get("/robot:speed") == 1.5
    assert graph.params.get("/robot:mode") == "auto"
    graph.params.set("/robot:speed", 2.5)  # a change here goes to the node
    assert held["speed"] == 2.5
    held["mode"] = 7  # the node changes a parameter's type
    del held["speed"]
    replicas.sweep({"/robot"})
    replicas.sweep({"/robot"})  # the refresh
    assert graph.params.get("/robot:mode") == 7
    assert not graph.params.has("/robot:speed")
    graph.params.set("/elsewhere:x", 1)  # not a copy: nothing is sent
    replicas.sweep(set())  # the node went: its copy goes
    assert not graph.params.has("/robot:mode")
    replicas.sweep({"/robot"})
    replicas.close()
    assert not graph.params.has("/robot:mode")
    for service in services:
        service.close()


def test_graph_type_warnings_come_from_its_links() -> None:
    graph = Graph()
    assert graph.port.type_warning(STRING) is None
    graph.type_checks.append(lambda name: None)
    graph.type_checks.append(lambda name: f"no package for {name}")
    assert graph.port.type_warning(STRING) == f"no package for {STRING}"


def test_read_cdr_takes_trailing_bytes_within_the_slack() -> None:
    registry = TypeRegistry(Dialect.ROS2)
    store = registry.typestore()
    data = registry.serialize(registry.message(STRING), {"data": "hi"})
    assert read_cdr(store, data + bytes(8), STRING).data == "hi"  # type: ignore[attr-defined]
    used = len(data) - 4
    with pytest.raises(CdrError, match="bytes after a payload"):
        read_cdr(store, data + bytes(used + CDR_TRAILING_SLACK + 8), STRING)
    with pytest.raises(CdrError, match="encapsulation"):
        read_cdr(store, b"\x05\x05" + data[2:], STRING)
    with pytest.raises(CdrError, match="cannot deserialize"):
        read_cdr(store, data[:6], STRING)


def test_a_node_whose_parameter_calls_fail_gets_no_copy() -> None:
    graph = Graph()

    def broken(request: dict) -> dict:
        raise RuntimeError("the node is busy")

    service = graph.create_service(
        "/robot/list_parameters", "rcl_interfaces/srv/ListParameters", broken
    )
    replicas = ParamReplicas(graph, "link:caller")
    replicas.sweep({"/robot"})
    assert graph.params.names() == []
    replicas.close()
    replicas.close()  # twice is harmless
    service.close()


def test_a_message_hash_is_rosidls() -> None:
    # what rclpy reports for std_msgs/msg/String's endpoints (ROS 2 Kilted)
    expected = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    assert message_type_hash(TypeRegistry(Dialect.ROS2), STRING) == expected


def test_a_nodes_parameter_services_answer_from_the_store() -> None:
    graph = Graph()
    graph.params.set("/robot:speed", 1.5)
    graph.params.set("/robot:gone", 1)
    value_type = graph.registry.message("rcl_interfaces/msg/ParameterValue")
    assert param_nodes(graph) == frozenset({"/robot"})
    listed = answer(graph, "/robot", "list_parameters", {"prefixes": [], "depth": 0})
    assert listed == {"result": {"names": ["gone", "speed"], "prefixes": []}}
    got = answer(graph, "/robot", "get_parameters", {"names": ["speed", "absent"]})
    assert [from_wire(v) for v in got["values"]] == [1.5, None]  # type: ignore[union-attr]
    request = {
        "parameters": [
            {"name": "speed", "value": to_wire(value_type, 2.0)},
            {"name": "speed", "value": {"type": 99}},
            {"name": "gone", "value": value_type.default()},
        ]
    }
    results = answer(graph, "/robot", "set_parameters", request)["results"]
    assert [r["successful"] for r in results] == [True, False, True]  # type: ignore[index, union-attr]
    assert graph.params.get("/robot:speed") == 2.0
    assert not graph.params.has("/robot:gone")
    with pytest.raises(KeyError):
        answer(graph, "/robot", "get_logger_levels", {})


@pytest.mark.parametrize(
    ("prefixes", "depth", "names", "spaces"),
    [
        ([], 0, ["arm.joint.max", "arm.speed", "rate"], ["arm.joint", "arm"]),
        ([], 1, ["rate"], []),
        ([], 2, ["arm.speed", "rate"], ["arm"]),
        (["arm"], 0, ["arm.joint.max", "arm.speed"], ["arm.joint", "arm"]),
        (["arm"], 1, ["arm.speed"], ["arm"]),
        (["arm.joint", "rate"], 0, ["arm.joint.max", "rate"], ["arm.joint"]),
        (["ar"], 0, [], []),
    ],
)
def test_list_parameters_filters_as_rclpy_does(
    prefixes: list[str], depth: int, names: list[str], spaces: list[str]
) -> None:
    graph = Graph()
    for name in ("arm.joint.max", "arm.speed", "rate"):
        graph.params.set(f"/robot:{name}", 1)
    listed = answer(graph, "/robot", "list_parameters", {"prefixes": prefixes, "depth": depth})
    assert listed == {"result": {"names": names, "prefixes": spaces}}


def test_huge_parameter_requests_are_refused_whole() -> None:
    graph = Graph()
    graph.params.set("/robot:blob", "x" * (1 << 20))
    many = {"names": ["blob"] * (MAX_REQUEST_ITEMS + 1)}
    for part in ("get_parameters", "get_parameter_types", "describe_parameters"):
        with pytest.raises(ParameterError, match="10001 names in one request"):
            answer(graph, "/robot", part, many)
    # a 1 MiB value named 65 times would answer 65 MiB
    with pytest.raises(ParameterError, match="more than 67108864 bytes"):
        answer(graph, "/robot", "get_parameters", {"names": ["blob"] * 65})
    value = {"type": 1, "bool_value": True}
    flood = {"parameters": [{"name": "b", "value": value}] * (MAX_REQUEST_ITEMS + 1)}
    refused = answer(graph, "/robot", "set_parameters_atomically", flood)
    assert refused == {
        "result": {
            "successful": False,
            "reason": "10001 parameters in one request, more than 10000",
        }
    }
    assert not graph.params.has("/robot:b")


class _Linked:
    """A graph with a local subscriber of /chatter and the relays of a link "link:".

    ``known`` is what the link knows of remote publishers: GID -> participant.
    """

    def __init__(self) -> None:
        self.graph = Graph()
        self.heard: list[str] = []
        self.listener = self.graph.create_subscription(
            "/chatter", lambda msg: self.heard.append(str(msg["data"])), STRING
        )
        self.known: dict[bytes, str] = {}
        self.relays = Relays(self.graph, LinkRules("link:"), "/the_link", self.known.get)
        self.entry = self.graph.topics["/chatter"]

    def discover(self, gid: bytes, client: str, *, latched: bool) -> None:
        """The link learns of the remote publisher ``gid`` and mirrors it."""
        mirror_endpoint(
            self.graph, client, "/talker", Kind.PUBLISHER, "/chatter", STRING, latched=latched
        )
        self.known[gid] = client

    def late_subscriber(self) -> list[str]:
        """What a subscriber that comes now gets at once (the latched message, if any)."""
        got: list[str] = []
        self.graph.create_subscription("/chatter", lambda msg: got.append(str(msg["data"])), STRING)
        return got


def _linked_graph() -> tuple[Graph, Relays, list[str]]:
    linked = _Linked()
    return linked.graph, linked.relays, linked.heard


def test_remote_endpoints_join_the_graph_in_their_node() -> None:
    graph = Graph()
    mirror_endpoint(graph, "link:p", "/robot", Kind.PUBLISHER, "/odom", STRING, latched=True)
    mirror_endpoint(graph, "link:s", "/robot", Kind.SUBSCRIPTION, "/cmd", STRING)
    assert graph.topics["/odom"].publishers == {"link:p": True}
    assert graph.topics["/cmd"].subscribers == {"link:s": NULL_SINK}
    assert graph.nodes.clients_of("/robot") == {"link:p", "link:s"}
    with pytest.raises(GraphError, match="type"):  # another type: refused, no node left
        mirror_endpoint(graph, "link:q", "/other", Kind.PUBLISHER, "/odom", "std_msgs/msg/Int32")
    with pytest.raises(RwtError):  # a type the registry does not know
        mirror_endpoint(graph, "link:r", "/other", Kind.SUBSCRIPTION, "/x", "no_msgs/msg/None")
    assert "/other" not in graph.nodes.names()
    with pytest.raises(ValueError, match="service"):
        mirror_endpoint(graph, "link:v", "/robot", Kind.SERVICE, "/srv", STRING)


def test_a_sample_before_its_publisher_is_known_comes_through_a_relay() -> None:
    linked = _Linked()
    graph, relays, entry = linked.graph, linked.relays, linked.entry
    relays.deliver(entry, None, {"data": "early"})
    relays.deliver(entry, b"pub", {"data": "unknown"})  # not a publisher here (yet)
    assert linked.heard == ["early", "unknown"]
    assert graph.nodes.clients_of("/the_link") == {"link:relay:/chatter"}
    linked.discover(b"pub", "link:pub", latched=False)
    relays.deliver(entry, b"pub", {"data": "known"})
    assert linked.heard[-1] == "known"
    relays.sweep({"/chatter"})  # its publisher is known: the relay goes
    assert set(entry.publishers) == {"link:pub"}
    assert "/the_link" not in graph.nodes.names()
    assert linked.late_subscriber() == []  # nothing was latched


def test_relays_go_with_their_topic_or_subscription_and_when_the_link_stops() -> None:
    graph, relays, _ = _linked_graph()
    relays.deliver(graph.topics["/chatter"], None, {"data": "a"})
    relays.sweep({"/chatter"})  # still needed: no publisher known, still received
    assert "link:relay:/chatter" in graph.topics["/chatter"].publishers
    relays.sweep(set())  # the link no longer receives /chatter
    assert "link:relay:/chatter" not in graph.topics["/chatter"].publishers
    relays.deliver(graph.topics["/chatter"], None, {"data": "b"})
    relays.close()
    assert "link:relay:/chatter" not in graph.topics["/chatter"].publishers
    assert "/the_link" not in graph.nodes.names()


def test_a_sample_known_transient_local_reaches_a_subscriber_before_and_after_discovery() -> None:
    # the link knows the sample is transient local (it came on a transient-local
    # subscription), though not yet its publisher: /map, /tf_static
    linked = _Linked()
    linked.relays.deliver(linked.entry, b"map_server", {"data": "map"}, latched=True)
    assert linked.late_subscriber() == ["map"]  # before its publisher is known
    linked.discover(b"map_server", "link:map_server", latched=True)
    linked.relays.sweep({"/chatter"})  # the relay goes, the sample stays
    assert set(linked.entry.publishers) == {"link:map_server"}
    assert linked.late_subscriber() == ["map"]
    assert linked.heard == ["map"]  # once: the hand-over delivers nothing again
    linked.graph.port.release("link:map_server")  # the latched sample goes with it (D13)
    assert linked.late_subscriber() == []


def test_a_sample_of_unknown_durability_is_latched_once_its_publisher_latches() -> None:
    # the link could not tell (a Zenoh sample says nothing of its publisher's QoS)
    linked = _Linked()
    linked.relays.deliver(linked.entry, b"map_server", {"data": "map"})
    assert linked.late_subscriber() == []  # nothing known to latch yet
    linked.discover(b"map_server", "link:map_server", latched=True)
    linked.relays.sweep({"/chatter"})
    assert linked.late_subscriber() == ["map"]
    assert linked.heard == ["map"]


def test_a_volatile_publishers_early_sample_is_not_latched() -> None:
    linked = _Linked()
    linked.relays.deliver(linked.entry, b"talker", {"data": "hello"})
    linked.discover(b"talker", "link:talker", latched=False)
    linked.relays.sweep({"/chatter"})
    assert linked.late_subscriber() == []
    linked.relays.deliver(linked.entry, b"other", {"data": "x"}, latched=True)
    linked.relays.sweep(set())  # the link stops receiving: the relay and its sample go
    assert linked.late_subscriber() == []


def test_the_last_latched_sample_wins_the_hand_over() -> None:
    linked = _Linked()
    relays, entry = linked.relays, linked.entry
    relays.deliver(entry, b"first", {"data": "first"})  # latching, as discovery will tell
    relays.deliver(entry, b"volatile", {"data": "passing"})  # a volatile one's: not kept
    linked.discover(b"first", "link:first", latched=True)
    linked.discover(b"volatile", "link:volatile", latched=False)
    relays.sweep({"/chatter"})
    assert linked.late_subscriber() == ["first"]
    # a latched message after the early sample takes its place
    relays.deliver(entry, b"early", {"data": "early"})
    linked.graph.port.publish_local("link:first", "/chatter", {"data": "newer"}, latch=True)
    linked.discover(b"early", "link:early", latched=True)
    relays.sweep({"/chatter"})
    assert linked.late_subscriber() == ["newer"]
    assert linked.heard == ["first", "passing", "early", "newer"]


class _RunSink:
    """A subscriber that takes runs (a ``BatchSink``, as a client's queue is)."""

    def __init__(self) -> None:
        self.runs: list[list[str]] = []

    def on_message(self, event: MessageEvent) -> None:
        self.on_messages([event])

    def on_messages(self, events: list[MessageEvent]) -> None:
        self.runs.append([str(event.msg["data"]) for event in events])  # type: ignore[index]


def _texts(*texts: str) -> tuple[list[dict[str, object]], list[bytes | None]]:
    return [{"data": text} for text in texts], [None] * len(texts)


def test_a_run_of_samples_reaches_each_subscriber_whole_and_in_order() -> None:
    linked = _Linked()
    relays, entry = linked.relays, linked.entry
    runs = _RunSink()
    linked.graph.port.subscribe("runs", "/chatter", STRING, runs)
    relays.deliver_many(entry, b"pub", *_texts("r0", "r1", "r2"), lifespan=0.02)  # a relay's
    assert linked.heard == ["r0", "r1", "r2"]
    assert runs.runs == [["r0"], ["r1"], ["r2"]]  # one by one while a callback listens too
    linked.listener.close()  # every subscriber takes runs now
    linked.discover(b"pub", "link:pub", latched=False)
    relays.deliver_many(entry, b"pub", *_texts("p0", "p1"))  # its publisher's own
    assert runs.runs[3:] == [["p0", "p1"]]  # one call for the run
    relays.sweep({"/chatter"})
    assert set(entry.publishers) == {"link:pub"}
    assert linked.late_subscriber() == []  # nothing latched


def test_a_latched_run_is_kept_as_its_last_sample() -> None:
    linked = _Linked()
    relays, entry = linked.relays, linked.entry
    relays.deliver_many(entry, b"map_server", *_texts("m0", "m1"), latched=True)
    assert linked.late_subscriber() == ["m1"]  # before its publisher is known
    linked.discover(b"map_server", "link:map_server", latched=True)
    relays.sweep({"/chatter"})  # the relay goes, its last sample stays latched
    assert linked.late_subscriber() == ["m1"]
    relays.deliver_many(entry, b"map_server", *_texts("m2", "m3"))  # the publisher latches
    assert linked.late_subscriber() == ["m3"]
    assert linked.heard == ["m0", "m1", "m2", "m3"]


def test_a_relay_waits_a_while_for_the_publishers_it_relayed_for() -> None:
    # /tf_static: one broadcaster known, a second one's sample came first
    linked = _Linked()
    relays, entry = linked.relays, linked.entry
    linked.discover(b"first", "link:first", latched=True)
    relays.deliver(entry, b"first", {"data": "first"})
    relays.deliver(entry, b"second", {"data": "second"}, latched=True)
    relays.sweep({"/chatter"})  # the second is not known yet: the relay stays
    assert linked.late_subscriber() == ["second"]
    linked.discover(b"second", "link:second", latched=True)
    relays.sweep({"/chatter"})
    assert set(entry.publishers) == {"link:first", "link:second"}
    assert linked.late_subscriber() == ["second"]
    linked.graph.port.release("link:second")
    assert linked.late_subscriber() == []
    # a publisher never known: the relay and its sample go after RELAY_WAIT_SWEEPS
    relays.deliver(entry, b"ghost", {"data": "ghost"}, latched=True)
    for _ in range(RELAY_WAIT_SWEEPS):
        relays.sweep({"/chatter"})
    assert linked.late_subscriber() == ["ghost"]
    relays.sweep({"/chatter"})
    assert set(entry.publishers) == {"link:first"}
    assert linked.late_subscriber() == []


def test_a_relay_holds_a_bounded_number_of_unknown_publishers(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr("rwt_graph.link.HELD_SOURCES", 2)
    linked = _Linked()
    for name in (b"a", b"b", b"c"):
        linked.relays.deliver(linked.entry, name, {"data": name.decode()})
    linked.discover(b"a", "link:a", latched=True)  # forgotten: the oldest past 2
    linked.discover(b"b", "link:b", latched=False)
    linked.discover(b"c", "link:c", latched=False)
    linked.relays.sweep({"/chatter"})
    assert linked.late_subscriber() == []
    linked.relays.deliver(linked.entry, b"d", {"data": "d"})
    linked.relays.deliver(linked.entry, b"e", {"data": "e"})
    linked.discover(b"d", "link:d", latched=True)  # held: handed over
    linked.discover(b"e", "link:e", latched=False)
    linked.relays.sweep({"/chatter"})
    assert linked.late_subscriber() == ["d"]


def test_a_relay_may_not_publish_on_a_topic_the_server_keeps() -> None:
    graph, relays, heard = _linked_graph()
    graph.reserve_topic("/chatter")
    with pytest.raises(GraphError, match="reserved"):
        relays.deliver(graph.topics["/chatter"], None, {"data": "forged"})
    assert heard == []
    assert "/the_link" not in graph.nodes.names()


def test_a_nodes_parameters_are_described_typed_and_set_all_or_nothing() -> None:
    graph = Graph()
    graph.params.set("/robot:speed", 1.5)  # set by a client: dynamically typed
    graph.params.declare("/robot", {"name": "r2"}, read_only=True)
    value_type = graph.registry.message("rcl_interfaces/msg/ParameterValue")
    types = answer(graph, "/robot", "get_parameter_types", {"names": ["speed", "name", "absent"]})
    assert types == {"types": [3, 4, 0]}  # DOUBLE, STRING, NOT_SET (rcl_interfaces)
    described = answer(graph, "/robot", "describe_parameters", {"names": ["speed", "name", "x"]})
    rows = [
        (d["name"], d["type"], d["read_only"], d["dynamic_typing"])
        for d in described["descriptors"]  # type: ignore[union-attr]
    ]
    assert rows == [("speed", 3, False, True), ("name", 4, True, False), ("x", 0, False, False)]
    refused = answer(
        graph,
        "/robot",
        "set_parameters_atomically",
        {
            "parameters": [
                {"name": "speed", "value": to_wire(value_type, 9.0)},
                {"name": "name", "value": to_wire(value_type, "c3po")},  # read-only
            ]
        },
    )["result"]
    assert refused["successful"] is False and "name" in refused["reason"]  # type: ignore[index]
    assert graph.params.get("/robot:speed") == 1.5  # nothing of the refused set applied
    done = answer(
        graph,
        "/robot",
        "set_parameters_atomically",
        {"parameters": [{"name": "speed", "value": to_wire(value_type, 9.0)}]},
    )["result"]
    assert done == {"successful": True, "reason": ""}
    assert graph.params.get("/robot:speed") == 9.0


class _Counting:
    """A sink that keeps what it got."""

    def __init__(self) -> None:
        self.got: list[object] = []

    def on_message(self, event: MessageEvent) -> None:
        self.got.append(event.msg["data"])


class _Dropping(_Counting):
    drops_messages = True


def test_a_fan_out_reaches_the_current_subscribers_and_skips_dropping_sinks() -> None:
    """A replaced or removed subscriber gets nothing more; a sink that drops is never called."""
    graph = Graph()
    first, second, remote = _Counting(), _Counting(), _Dropping()
    graph.port.subscribe("ws:1", "/chatter", STRING, first)
    graph.port.subscribe("link:remote", "/chatter", STRING, remote)
    graph.port.publish("ws:2", "/chatter", {"data": "one"})
    graph.port.subscribe("ws:1", "/chatter", STRING, second)  # the same client again
    graph.port.publish("ws:2", "/chatter", {"data": "two"})
    graph.port.unsubscribe("ws:1", "/chatter")
    graph.port.publish("ws:2", "/chatter", {"data": "three"})
    assert first.got == ["one"]
    assert second.got == ["two"]
    assert remote.got == []
    assert set(graph.topics["/chatter"].subscribers) == {"link:remote"}


def test_a_graph_no_server_serves_holds_no_link_back() -> None:
    graph = Graph()
    delivered: list[object] = []
    graph.create_subscription("/t", delivered.append, STRING)
    publisher = graph.create_publisher("/t", STRING)
    gate = graph.port.inflow
    assert gate is OPEN_GATE
    gate.begin()
    publisher.publish({"data": "x" * 100_000})
    gate.end()
    assert not gate.congested()
    assert gate.take_hold() is None  # nothing congested to wait for
    assert len(delivered) == 1
