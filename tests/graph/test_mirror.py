"""The shared mirror (rwt_graph.mirror) with a fake discovery source: what rosapi sees.

Both links hand their discovery to this mirror (the Zenoh link token by token,
the ROS 2 link a snapshot each sweep); the real links are tested end to end in
tests/zenoh and tests/ros2.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import pytest

from rwt_graph.graph import Graph
from rwt_graph.link import LinkRules
from rwt_graph.mirror import Mirror, RemoteEntity, RemoteKind
from rwt_graph.ratelog import EpisodeLog
from rwt_protocol.errors import GraphError
from rwt_protocol.ops import CallService, CancelActionGoal, SendActionGoal

STRING = "std_msgs/msg/String"
SET_BOOL = "std_srvs/srv/SetBool"
FIBONACCI = "example_interfaces/action/Fibonacci"

NODE = RemoteEntity(RemoteKind.NODE, "/robot")
TALKER = RemoteEntity(RemoteKind.PUBLISHER, "/robot", "/chatter", STRING, gid=b"t" * 16)
MAP = RemoteEntity(RemoteKind.PUBLISHER, "/robot", "/map", STRING, latched=True, gid=b"m" * 16)
LISTENER = RemoteEntity(RemoteKind.SUBSCRIPTION, "/robot", "/cmd", STRING)
SERVICE = RemoteEntity(RemoteKind.SERVICE, "/robot", "/enable", SET_BOOL)
ACTION = RemoteEntity(RemoteKind.ACTION, "/robot", "/fib", FIBONACCI)


class _Provider:
    def __init__(self) -> None:
        self.requests: list[str] = []

    def on_service_request(self, request: CallService) -> None:
        self.requests.append(str(request.id))

    def on_service_lost(self, service: str, reason: str) -> None:
        pass

    def on_action_goal(self, goal: SendActionGoal) -> None:
        pass

    def on_action_cancel(self, cancel: CancelActionGoal) -> None:
        pass

    def on_action_lost(self, action: str, reason: str) -> None:
        pass


@dataclass
class _Side:
    """A fake link: refuses the endpoints named in ``refuse``, records releases."""

    refuse: set[str] = field(default_factory=set)
    providers: dict[str, _Provider] = field(default_factory=dict)
    gone: list[tuple[str, object]] = field(default_factory=list)

    def check_endpoint(self, entity: RemoteEntity) -> None:
        if entity.name in self.refuse:
            raise GraphError(f"{entity.name}: another definition")

    def service_provider(self, client: str, entity: RemoteEntity) -> _Provider:
        return self._provider(client)

    def action_provider(self, client: str, entity: RemoteEntity) -> _Provider:
        return self._provider(client)

    def _provider(self, client: str) -> _Provider:
        provider = self.providers[client] = _Provider()
        return provider

    def released(self, client: str, entity: RemoteEntity, provider: object) -> None:
        self.gone.append((client, provider))


class _Linked:
    def __init__(self, *, per_entity: bool = False) -> None:
        self.graph = Graph()
        self.side = _Side()
        self.mirror = Mirror(
            self.graph,
            LinkRules("link:"),
            self.side,
            EpisodeLog(logging.getLogger("rwt.test_mirror")),
            event="test",
            episode_per_entity=per_entity,
        )

    def listed(self) -> dict[str, set[str]]:
        """What rosapi lists: each node's participants."""
        return {node: self.graph.nodes.clients_of(node) for node in self.graph.nodes.names()}


def _skips(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if "event=test_skip" in r.getMessage()]


@pytest.mark.parametrize(
    ("entity", "check"),
    [
        (NODE, lambda graph: "link:e" in graph.nodes.clients_of("/robot")),
        (TALKER, lambda graph: graph.topics["/chatter"].publishers == {"link:e": False}),
        (MAP, lambda graph: graph.topics["/map"].publishers == {"link:e": True}),
        (LISTENER, lambda graph: set(graph.topics["/cmd"].subscribers) == {"link:e"}),
        (SERVICE, lambda graph: graph.services.entries["/enable"].owner == "link:e"),
        (ACTION, lambda graph: graph.actions.entries["/fib"].owner == "link:e"),
    ],
    ids=["node", "publisher", "latched publisher", "subscription", "service", "action"],
)
def test_each_kind_joins_the_graph_in_its_node_and_leaves_with_it(entity, check) -> None:  # type: ignore[no-untyped-def]
    linked = _Linked()
    linked.mirror.apply({"link:e": entity})
    assert check(linked.graph)
    assert linked.listed() == {"/robot": {"link:e"}}
    assert linked.mirror.mirrored("link:e")
    linked.mirror.apply({})
    assert linked.listed() == {}
    assert linked.graph.topics.get(entity.name) is None
    assert "/enable" not in linked.graph.services.entries
    assert "/fib" not in linked.graph.actions.entries
    assert linked.side.gone == [("link:e", linked.side.providers.get("link:e"))]


def test_a_snapshot_is_diffed_against_what_is_mirrored() -> None:
    linked = _Linked()
    mirror = linked.mirror
    mirror.apply({"link:n": NODE, "link:t": TALKER, "link:s": SERVICE})
    provider = linked.side.providers["link:s"]
    mirror.apply({"link:n": NODE, "link:t": TALKER, "link:s": SERVICE})  # nothing changed
    assert linked.side.gone == []
    assert linked.side.providers["link:s"] is provider
    latched = RemoteEntity(RemoteKind.PUBLISHER, "/robot", "/chatter", STRING, latched=True)
    mirror.apply({"link:n": NODE, "link:t": latched})  # one changed, one went
    assert linked.graph.topics["/chatter"].publishers == {"link:t": True}
    assert "/enable" not in linked.graph.services.entries
    assert [client for client, _ in linked.side.gone] == ["link:t", "link:s"]


def test_a_remote_publishers_latched_message_goes_with_it() -> None:
    linked = _Linked()
    linked.mirror.add("link:m", MAP)
    linked.graph.port.publish_local("link:m", "/map", {"data": "the map"}, latch=True)
    got: list[object] = []
    linked.graph.create_subscription("/map", lambda msg: got.append(msg["data"]), STRING)
    assert got == ["the map"]
    linked.mirror.remove("link:m")
    late: list[object] = []
    linked.graph.create_subscription("/map", lambda msg: late.append(msg["data"]), STRING)
    assert late == []  # D13


def test_a_gone_services_callers_fail() -> None:
    linked = _Linked()
    linked.mirror.add("link:s", SERVICE)
    replies: list[tuple[bool, object]] = []
    linked.graph.port.call_service(
        "ws:1",
        *_ENABLE,
        lambda ok, value: replies.append((ok, value)),
    )
    assert linked.side.providers["link:s"].requests  # the call went across
    linked.mirror.remove("link:s")
    assert [ok for ok, _ in replies] == [False]  # D15


@pytest.mark.parametrize("entity", [SERVICE, ACTION], ids=["service", "action"])
def test_a_provider_that_exists_keeps_its_name_until_it_goes(entity: RemoteEntity) -> None:
    linked = _Linked()
    graph = linked.graph
    if entity.kind is RemoteKind.SERVICE:
        local = graph.create_service("/enable", SET_BOOL, lambda request: {"success": True})
        entries: dict[str, object] = graph.services.entries  # type: ignore[assignment]
    else:

        async def fib(goal: dict, context: object) -> dict:  # type: ignore[type-arg]
            return {"sequence": []}

        local = graph.create_action_server("/fib", FIBONACCI, fib)  # type: ignore[assignment]
        entries = graph.actions.entries  # type: ignore[assignment]
    owner = entries[entity.name].owner  # type: ignore[attr-defined]
    linked.mirror.apply({"link:e": entity})
    assert entries[entity.name].owner == owner  # type: ignore[attr-defined]
    assert not linked.mirror.mirrored("link:e")
    assert "/robot" not in graph.nodes.names()
    linked.mirror.retry()  # still there: still waiting
    assert not linked.mirror.mirrored("link:e")
    local.close()
    linked.mirror.retry()  # gone: the remote one takes the name
    assert entries[entity.name].owner == "link:e"  # type: ignore[attr-defined]
    assert linked.listed() == {"/robot": {"link:e"}}


@pytest.mark.parametrize(
    ("entity", "reason"),
    [
        (RemoteEntity(RemoteKind.PUBLISHER, "/robot", "/x", "no_msgs/msg/None"), "no_msgs"),
        (RemoteEntity(RemoteKind.SERVICE, "/robot", "/s", "no_srvs/srv/None"), "no_srvs"),
        (RemoteEntity(RemoteKind.ACTION, "/robot", "/a", "no_acts/action/None"), "no_acts"),
        (RemoteEntity(RemoteKind.SUBSCRIPTION, "/robot", "/refused", STRING), "definition"),
        (RemoteEntity(RemoteKind.PUBLISHER, "/robot", "/odom", STRING), "type"),
    ],
    ids=["unknown message", "unknown service", "unknown action", "check", "another type"],
)
def test_a_refused_entity_is_skipped_once_and_leaves_nothing(
    entity: RemoteEntity, reason: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, "rwt.test_mirror")
    linked = _Linked()
    linked.side.refuse.add("/refused")
    linked.graph.port.advertise("ws:1", "/odom", "std_msgs/msg/Int32")
    linked.mirror.apply({"link:e": entity})
    linked.mirror.apply({"link:e": entity})  # not tried again while it lives
    [line] = _skips(caplog)
    assert f"kind={entity.kind.value} name={entity.name}" in line and reason in line
    assert not linked.mirror.mirrored("link:e")
    assert "/robot" not in linked.graph.nodes.names()
    linked.mirror.apply({})
    assert [client for client, _ in linked.side.gone] == ["link:e"]


def test_skips_are_logged_per_kind_or_per_entity(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, "rwt.test_mirror")
    unknown = [
        RemoteEntity(RemoteKind.PUBLISHER, "/robot", f"/t{i}", "no_msgs/msg/None") for i in range(3)
    ]
    _Linked().mirror.apply({f"link:{i}": e for i, e in enumerate(unknown)})
    assert len(_skips(caplog)) == 1  # a peer inventing names writes one line per episode
    caplog.clear()
    _Linked(per_entity=True).mirror.apply({f"link:{i}": e for i, e in enumerate(unknown)})
    assert len(_skips(caplog)) == 3


def test_private_names_are_never_mirrored(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, "rwt.test_mirror")
    linked = _Linked()
    private = RemoteEntity(RemoteKind.SERVICE, "/robot", "/rosapi/topics", SET_BOOL)
    counts = RemoteEntity(RemoteKind.PUBLISHER, "/robot", "/client_count", "std_msgs/msg/Int32")
    linked.mirror.apply({"link:p": private, "link:c": counts, "link:n": NODE})
    assert linked.listed() == {"/robot": {"link:n"}}
    assert "/rosapi/topics" not in linked.graph.services.entries
    assert _skips(caplog) == []


def test_samples_find_only_mirrored_publishers_by_gid() -> None:
    linked = _Linked()
    linked.side.refuse.add("/chatter")
    linked.mirror.add("link:m", MAP)
    linked.mirror.add("link:t", TALKER)  # refused
    assert linked.mirror.publisher_of(MAP.gid) == "link:m"
    assert linked.mirror.publisher_of(TALKER.gid) is None
    linked.mirror.remove("link:m")
    assert linked.mirror.publisher_of(MAP.gid) is None


def test_incremental_changes_and_closing() -> None:
    linked = _Linked()
    mirror = linked.mirror
    mirror.add("link:n", NODE)
    mirror.add("link:n", TALKER)  # a participant id already known: ignored
    assert mirror.entity("link:n") == NODE and len(mirror) == 1
    mirror.remove("link:unknown")  # harmless
    mirror.add("link:s", SERVICE)
    mirror.add("link:a", ACTION)
    mirror.close()
    assert linked.listed() == {}
    assert len(mirror) == 0 and "link:s" not in mirror
    assert {client for client, _ in linked.side.gone} == {"link:n", "link:s", "link:a"}


class _Discovery:
    """A link's discovery wait (``services.DiscoveryWait``): expires when the test says."""

    def __init__(self) -> None:
        self.expiries: list[object] = []
        self.cancelled = 0

    def __call__(self, expire):  # type: ignore[no-untyped-def]
        self.expiries.append(expire)
        return self._cancel

    def _cancel(self) -> None:
        self.cancelled += 1


_ENABLE = ("/enable", {"data": True})  # the service and its arguments


def test_a_call_to_a_service_being_discovered_waits_for_it() -> None:
    linked = _Linked()
    discovery = _Discovery()
    linked.graph.services.discoveries.append(discovery)
    replies: list[tuple[bool, object]] = []
    linked.graph.port.call_service("ws:1", *_ENABLE, lambda ok, value: replies.append((ok, value)))
    assert replies == [] and len(discovery.expiries) == 1  # held, not refused
    linked.mirror.add("link:s", SERVICE)  # discovered: the call goes across
    assert len(linked.side.providers["link:s"].requests) == 1
    assert discovery.cancelled == 1
    assert replies == []


def test_a_call_whose_service_is_not_discovered_fails_as_unknown() -> None:
    linked = _Linked()
    discovery = _Discovery()
    linked.graph.services.discoveries.append(discovery)
    replies: list[tuple[bool, object]] = []
    linked.graph.port.call_service("ws:1", *_ENABLE, lambda ok, value: replies.append((ok, value)))
    discovery.expiries[0]()  # type: ignore[operator]
    assert replies == [(False, "service /enable does not exist")]
    linked.mirror.add("link:s", SERVICE)  # too late: nothing left to send
    assert linked.side.providers["link:s"].requests == []


def test_a_held_call_goes_with_its_caller_or_its_timeout() -> None:
    linked = _Linked()
    discovery = _Discovery()
    linked.graph.services.discoveries.append(discovery)
    replies: list[tuple[bool, object]] = []
    pending = linked.graph.port.call_service(
        "ws:1", *_ENABLE, lambda ok, value: replies.append((ok, value))
    )
    linked.graph.port.call_service("ws:2", *_ENABLE, lambda ok, value: replies.append((ok, value)))
    pending.forget()  # the caller's timeout
    linked.graph.port.release("ws:2")  # the other caller left
    assert discovery.cancelled == 2
    linked.mirror.add("link:s", SERVICE)
    assert linked.side.providers["link:s"].requests == []
    assert replies == []


def test_a_call_with_its_own_timeout_is_held_past_the_links_wait() -> None:
    linked = _Linked()
    discovery = _Discovery()
    linked.graph.services.discoveries.append(discovery)
    replies: list[tuple[bool, object]] = []
    pending = linked.graph.port.call_service(
        "ws:1", *_ENABLE, lambda ok, value: replies.append((ok, value)), timeout_s=20.0
    )
    discovery.expiries[0]()  # type: ignore[operator]
    assert replies == []  # it waits up to its own timeout, not the link's
    linked.mirror.add("link:s", SERVICE)  # discovered late: the call still goes
    assert len(linked.side.providers["link:s"].requests) == 1
    pending.forget()


def test_a_call_with_its_own_timeout_goes_at_that_timeout() -> None:
    linked = _Linked()
    discovery = _Discovery()
    linked.graph.services.discoveries.append(discovery)
    pending = linked.graph.port.call_service(
        "ws:1", *_ENABLE, lambda ok, value: None, timeout_s=20.0
    )
    pending.forget()  # the caller's timeout (the session's timer) ends the wait
    assert discovery.cancelled == 1
    linked.mirror.add("link:s", SERVICE)
    assert linked.side.providers["link:s"].requests == []


def test_without_a_discovering_link_an_unknown_service_fails_at_once() -> None:
    linked = _Linked()
    with pytest.raises(GraphError, match="service /enable does not exist"):
        linked.graph.port.call_service("ws:1", *_ENABLE, lambda ok, v: None)


def test_a_link_with_nothing_to_discover_lets_the_call_fail_at_once() -> None:
    linked = _Linked()
    linked.graph.services.discoveries.append(lambda expire: None)  # the link is not discovering
    with pytest.raises(GraphError, match="service /enable does not exist"):
        linked.graph.port.call_service("ws:1", *_ENABLE, lambda ok, v: None)


def test_a_held_call_fails_only_when_every_links_wait_is_over() -> None:
    linked = _Linked()
    first, second = _Discovery(), _Discovery()
    linked.graph.services.discoveries += [first, second]
    replies: list[tuple[bool, object]] = []
    linked.graph.port.call_service("ws:1", *_ENABLE, lambda ok, value: replies.append((ok, value)))
    first.expiries[0]()  # type: ignore[operator]
    assert replies == []  # the other link may still find it
    second.expiries[0]()  # type: ignore[operator]
    assert replies == [(False, "service /enable does not exist")]


def test_a_held_call_to_a_service_that_comes_with_another_type_fails_with_the_reason() -> None:
    linked = _Linked()
    linked.graph.services.discoveries.append(_Discovery())
    replies: list[tuple[bool, object]] = []
    linked.graph.port.call_service(
        "ws:1",
        *_ENABLE,
        lambda ok, value: replies.append((ok, value)),
        type_name="std_srvs/srv/Trigger",
    )
    linked.mirror.add("link:s", SERVICE)  # discovered as a SetBool
    assert linked.side.providers["link:s"].requests == []
    reason = "service /enable has type std_srvs/srv/SetBool, not std_srvs/srv/Trigger"
    assert replies == [(False, reason)]
