"""Session gates and limits without sockets: auth (D23), access rules, slow consumers (D24)."""

from __future__ import annotations

import hashlib
import json
import logging

import pytest

from rwt_graph.graph import Graph
from rwt_protocol import ops
from rwt_protocol.auth import RosauthVerifier, rosauth_mac
from rwt_protocol.errors import LocalProtocolError
from rwt_protocol.levels import StatusLevel
from rwt_protocol.ops import Auth, CallService, Subscribe
from rwt_protocol.ratelog import EpisodeLog
from rwt_protocol.runtime import access
from rwt_protocol.runtime.access import (
    AccessPolicy,
    Family,
    TopicUse,
    parse_glob_list,
    parse_split_glob,
)
from rwt_protocol.runtime.lifecycle import TRANSITIONS, State, advance
from rwt_protocol.runtime.outbox import Outbox, OutFrame
from rwt_protocol.server.handlers import HANDLERS
from rwt_protocol.server.op_access import check_op
from rwt_protocol.server.replies import failure_reply
from rwt_protocol.server.session import CloseCode, CloseConnection, Session, SessionConfig
from tests.conftest import FakeClock, Peer

SECRET = "relaxthisisatest"
WALL = 1_700_000_000.0


def auth_op(mac: str | None = None, **overrides: object) -> dict[str, object]:
    fields: dict[str, object] = {
        "client": "192.168.1.101",
        "dest": "192.168.1.111",
        "rand": "xyzzy",
        "t": WALL - 1,
        "level": "admin",
        "end": WALL + 60,
    }
    fields.update(overrides)
    if mac is None:
        mac = rosauth_mac(SECRET, **fields)  # type: ignore[arg-type]
    return {"op": "auth", "mac": mac, **fields}


class GatedPeer(Peer):
    """A peer whose session has a config of the test's choosing."""

    def __init__(self, graph: Graph, name: str, config: SessionConfig) -> None:
        self.session = Session(graph.port, name, config=config, peer="10.0.0.1:5000")
        self.clock = graph.clock

    def commands(self) -> list[CloseConnection]:
        return self.session.commands_to_run()


def rosauth(clock_wall: list[float]) -> SessionConfig:
    verifier = RosauthVerifier(SECRET)
    return SessionConfig(authenticator=lambda op, peer: verifier.problem(op, clock_wall[0]) is None)


# ---- rosauth MAC ---------------------------------------------------------------


def test_mac_is_sha512_hex_of_the_fields_with_whole_seconds() -> None:
    expected = hashlib.sha512(b"s" + b"c" + b"d" + b"r" + b"10" + b"admin" + b"20").hexdigest()
    assert rosauth_mac("s", client="c", dest="d", rand="r", t=10.9, level="admin", end=20.2) == (
        expected
    )


@pytest.mark.parametrize(
    ("overrides", "now", "problem"),
    [
        ({}, WALL, None),
        ({}, WALL + 61, "expired"),
        ({"t": WALL + 10}, WALL, "not yet valid"),
        ({"t": WALL + 3}, WALL, None),  # within the 5 s skew rosauth allows
    ],
)
def test_verifier_checks_the_time_window(
    overrides: dict[str, object], now: float, problem: str | None
) -> None:
    op = Auth.model_validate(auth_op(**overrides))
    found = RosauthVerifier(SECRET).problem(op, now)
    assert found == problem if problem is None else found is not None and problem in found


def test_verifier_rejects_a_mac_made_with_another_secret_or_garbage() -> None:
    good = auth_op()
    verifier = RosauthVerifier(SECRET)
    for mac in ("0" * 128, "é" * 10, good["mac"][:-1] + "0", ""):  # type: ignore[index]
        op = Auth.model_validate({**good, "mac": mac})
        assert verifier.problem(op, WALL) == "MAC does not match"
    assert RosauthVerifier(SECRET).problem(Auth.model_validate(good), WALL) is None


def test_verifier_from_file_reads_the_first_line() -> None:
    assert RosauthVerifier.from_file(f"{SECRET}\nignored\n").secret == SECRET
    with pytest.raises(ValueError, match="empty"):
        RosauthVerifier.from_file("\n")


# ---- the auth gate ---------------------------------------------------------------


def test_valid_auth_admits_the_connection(graph: Graph) -> None:
    peer = GatedPeer(graph, "a", rosauth([WALL]))
    peer.send(**auth_op())
    peer.send(op="advertise", topic="/t", type="std_msgs/String", id="adv")
    assert peer.session.authenticated
    assert peer.received() == []
    assert peer.commands() == []
    assert "/t" in graph.topics


@pytest.mark.parametrize(
    "first",
    [
        auth_op(mac="f" * 128),
        auth_op(end=WALL - 5),
        {"op": "advertise", "topic": "/t", "type": "std_msgs/String"},
        {"op": "auth", "mac": "x"},  # missing fields
        "not json",
        5,
    ],
    ids=["bad-mac", "expired", "op-before-auth", "incomplete-auth", "not-json", "number"],
)
def test_anything_but_a_valid_auth_first_gets_a_status_and_a_close(
    graph: Graph, first: object
) -> None:
    peer = GatedPeer(graph, "a", rosauth([WALL]))
    peer.send_raw(first if isinstance(first, str) else json.dumps(first))
    peer.send(op="advertise", topic="/later", type="std_msgs/String")  # ignored: closing
    [status] = peer.received()
    assert status["op"] == "status" and status["level"] == "error"
    assert "auth" in str(status["msg"])
    assert peer.commands() == [
        CloseConnection(CloseCode.POLICY_VIOLATION, "authentication required")
    ]
    assert not peer.session.authenticated
    assert "/t" not in graph.topics and "/later" not in graph.topics


def test_a_call_before_auth_is_answered_before_the_close(graph: Graph) -> None:
    peer = GatedPeer(graph, "a", rosauth([WALL]))
    peer.send(op="call_service", service="/rosapi/topics", id="c1")
    reply, status = peer.received()
    assert reply == {
        "op": "service_response",
        "service": "/rosapi/topics",
        "values": "authentication required",
        "result": False,
        "id": "c1",
    }
    assert status["level"] == "error"


def test_a_pluggable_authenticator_gets_the_op_and_the_peer(graph: Graph) -> None:
    seen: list[tuple[str, str]] = []

    def authenticator(op: Auth, peer: str) -> bool:
        seen.append((op.level, peer))
        return op.rand == "open sesame"

    config = SessionConfig(authenticator=authenticator)
    good, bad = GatedPeer(graph, "g", config), GatedPeer(graph, "b", config)
    good.send(**auth_op(rand="open sesame"))
    bad.send(**auth_op())
    assert good.session.authenticated and not bad.session.authenticated
    assert seen == [("admin", "10.0.0.1:5000"), ("admin", "10.0.0.1:5000")]
    assert bad.commands()[0].code is CloseCode.POLICY_VIOLATION


def test_an_authenticator_that_raises_refuses(graph: Graph) -> None:
    def broken(op: Auth, peer: str) -> bool:
        raise RuntimeError("database down")

    peer = GatedPeer(graph, "a", SessionConfig(authenticator=broken))
    peer.send(**auth_op())
    [status] = peer.received()
    assert status["msg"] == "auth: authentication failed"
    assert "database" not in str(status)  # no internals reach the client (D1)


def test_a_second_auth_is_ignored_with_info(graph: Graph) -> None:
    peer = GatedPeer(
        graph, "a", SessionConfig(status_level=StatusLevel.INFO, authenticator=lambda o, p: True)
    )
    peer.send(**auth_op())
    peer.send(**auth_op())
    assert [s["msg"] for s in peer.statuses()] == [
        "auth: authenticated",
        "auth: already authenticated; ignored",
    ]


def test_without_authenticator_auth_is_ignored(peers: tuple[Peer, Peer]) -> None:
    a, _ = peers
    a.send(op="set_level", level="info")
    a.received()
    a.send(**auth_op())
    assert a.statuses()[0]["msg"] == "auth: authentication is not enabled; ignored"


# ---- access rules -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "patterns"),
    [
        ("", ()),
        ("[]", ()),
        ("[/a/*, '/b']", ("/a/*", "/b")),
        ("/a/*,/b ,", ("/a/*", "/b")),
        ('["*"]', ("*",)),
    ],
)
def test_glob_lists_parse_like_rosbridge(text: str, patterns: tuple[str, ...]) -> None:
    assert parse_glob_list(text) == patterns


def test_policy_matches_resolved_names_and_keeps_rosapi() -> None:
    policy = AccessPolicy(topics=("/allowed/*", "chatter"), services=("/add",))
    assert policy.allows(Family.TOPICS, "allowed/x")
    assert policy.allows(Family.TOPICS, "/chatter")
    assert not policy.allows(Family.TOPICS, "/secret")
    assert policy.allows(Family.SERVICES, "rosapi/topics")
    assert not policy.allows(Family.SERVICES, "/reboot")
    assert policy.allows(Family.ACTIONS, "/anything")  # no action patterns: no filter
    assert policy.filter(Family.TOPICS, ["/a", "/allowed/b", "/chatter"]) == [
        "/allowed/b",
        "/chatter",
    ]
    assert policy.restricted and not AccessPolicy().restricted


def denied_peer(graph: Graph) -> GatedPeer:
    policy = AccessPolicy(
        topics=parse_glob_list("[/public/*]"),
        services=parse_glob_list("[/public/*]"),
        actions=parse_glob_list("[/public/*]"),
        params=parse_glob_list("[/public/*]"),
    )
    return GatedPeer(graph, "d", SessionConfig(access=policy))


@pytest.mark.parametrize(
    "op",
    [
        {"op": "advertise", "topic": "/secret", "type": "std_msgs/String"},
        {"op": "subscribe", "topic": "secret", "type": "std_msgs/String"},
        {"op": "publish", "topic": "/secret", "msg": {"data": "x"}},
        {"op": "unsubscribe", "topic": "/secret"},
        {"op": "advertise_service", "service": "/secret", "type": "std_srvs/Empty"},
        {"op": "advertise_action", "action": "/secret", "type": "example_interfaces/Fibonacci"},
        {"op": "cancel_action_goal", "action": "/secret", "id": "g"},
    ],
    ids=lambda op: op["op"],
)
def test_denied_op_gets_an_error_status_and_has_no_side_effect(
    graph: Graph, op: dict[str, object]
) -> None:
    peer = denied_peer(graph)
    peer.send(**{"id": "req", **op})
    [status] = peer.received()
    assert status["level"] == "error" and status["id"] == op.get("id", "req")
    assert "is not allowed" in str(status["msg"])
    assert str(status["msg"]).startswith(f"{op['op']}: ")
    assert "/secret" not in graph.topics
    assert graph.services.entries == {} and graph.actions.entries == {}


def test_denied_call_and_goal_also_get_their_failure_reply(graph: Graph) -> None:
    peer = denied_peer(graph)
    peer.send(op="call_service", service="/secret", args={}, id=7)
    peer.send(op="send_action_goal", action="/secret", action_type="x/Y", args={}, id="g1")
    reply, status, result, status2 = peer.received()
    assert reply["op"] == "service_response" and reply["result"] is False and reply["id"] == 7
    assert status["op"] == "status" and status["id"] == 7
    assert result["op"] == "action_result" and result["status"] == 6 and result["id"] == "g1"
    assert status2["id"] == "g1"


def test_parameter_services_check_the_parameter_name(graph: Graph) -> None:
    peer = denied_peer(graph)
    peer.send(op="call_service", service="/rosapi/get_param", args={"name": "/secret"}, id=1)
    peer.send(op="call_service", service="rosapi/set_param", args=["/secret", "1"], id=2)
    replies = [m for m in peer.received() if m["op"] == "service_response"]
    assert [(r["id"], r["result"]) for r in replies] == [(1, False), (2, False)]
    assert all("parameter /secret is not allowed" in str(r["values"]) for r in replies)


def test_allowed_ops_pass_the_policy(graph: Graph) -> None:
    peer, other = denied_peer(graph), Peer(graph, "o")
    peer.send(op="advertise", topic="/public/chat", type="std_msgs/String")
    other.send(op="subscribe", topic="/public/chat")
    peer.send(op="publish", topic="/public/chat", msg={"data": "ok"})
    assert peer.received() == []
    assert other.received()[0]["msg"] == {"data": "ok"}


# ---- split topic globs: --topics-pub-glob, --topics-sub-glob (REF §13.5, D50) ----------

PUB, SUB = TopicUse.PUBLISH, TopicUse.SUBSCRIBE


def split(topics: str = "", pub: str = "", sub: str = "") -> AccessPolicy:
    """The policy ``rwt serve`` builds from the three options' texts."""
    return AccessPolicy(
        topics=parse_glob_list(topics),
        topics_pub=parse_split_glob(pub),
        topics_sub=parse_split_glob(sub),
    )


def test_split_globs_parse_unset_apart_from_an_empty_list() -> None:
    assert parse_split_glob("") is None and parse_split_glob("  ") is None
    assert parse_split_glob("[]") == ()
    assert parse_split_glob("[/a/*, '/b']") == ("/a/*", "/b")


ALL = {"/a", "/b", "/c"}


@pytest.mark.parametrize(
    ("options", "publish", "subscribe", "listed", "refused_by"),
    [
        # nothing set, or "" (unset): no filtering
        ({}, ALL, ALL, ALL, None),
        ({"pub": "", "sub": ""}, ALL, ALL, ALL, None),
        # pub allowed, sub denied on the same topic
        ({"pub": "[/a]", "sub": "[/b]"}, {"/a"}, {"/b"}, {"/a", "/b"}, "topics_sub_glob"),
        # "[]" alone denies every publish; sub unset inherits topics_glob (none: all)
        ({"pub": "[]"}, set(), ALL, ALL, None),
        ({"pub": "[]", "sub": "[]"}, set(), set(), set(), "topics_sub_glob"),
        # unset inherits topics_glob as it is
        ({"topics": "[/a]"}, {"/a"}, {"/a"}, {"/a"}, "topics_glob"),
        ({"topics": "[/a]", "sub": "[/b]"}, {"/a"}, {"/a", "/b"}, {"/a", "/b"}, None),
        # set, even "[]", is merged with topics_glob
        ({"topics": "[/a]", "pub": "[]"}, {"/a"}, {"/a"}, {"/a"}, "topics_glob"),
        (
            {"topics": "[/a]", "pub": "[/c]", "sub": "[]"},
            {"/a", "/c"},
            {"/a"},
            {"/a", "/c"},
            "topics_sub_glob",
        ),
    ],
)
def test_split_globs_follow_the_reference(
    options: dict[str, str],
    publish: set[str],
    subscribe: set[str],
    listed: set[str],
    refused_by: str | None,
) -> None:
    policy = split(**options)
    assert {n for n in sorted(ALL) if policy.allows(Family.TOPICS, n, PUB)} == publish
    assert {n for n in sorted(ALL) if policy.allows(Family.TOPICS, n, SUB)} == subscribe
    # a listing (rosapi, what a Foxglove client sees of the graph): either use allows it
    assert set(policy.filter(Family.TOPICS, sorted(ALL))) == listed
    assert policy.refusal(Family.TOPICS, "b", SUB) == (None if "/b" in subscribe else refused_by)
    assert policy.restricted == (publish != ALL or subscribe != ALL)


def test_a_refused_subscribe_names_its_glob_and_a_publish_on_the_topic_passes(
    graph: Graph, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(access, "_episodes", EpisodeLog(access.logger))  # a new episode
    caplog.set_level(logging.WARNING, logger="rwt.session")
    peer = GatedPeer(graph, "s", SessionConfig(access=split(pub="[/cmd]", sub="[/state]")))
    other = Peer(graph, "o")
    other.send(op="subscribe", topic="/cmd", type="std_msgs/String")
    peer.send(op="advertise", topic="/cmd", type="std_msgs/String")
    peer.send(op="publish", topic="cmd", msg={"data": "go"})
    assert other.received()[0]["msg"] == {"data": "go"}
    peer.send(op="subscribe", topic="/cmd", id="s1")
    peer.clock.now += 60  # the next refusal is a new episode, logged again
    peer.send(op="advertise", topic="/state", type="std_msgs/String", id="a1")
    refused = peer.received()
    assert [(m["id"], m["msg"]) for m in refused] == [
        ("s1", "subscribe: topic /cmd is not allowed on this server"),
        ("a1", "advertise: topic /state is not allowed on this server"),
    ]
    assert "op=subscribe glob=topics_sub_glob" in caplog.text
    assert "op=advertise glob=topics_pub_glob" in caplog.text
    assert list(graph.topics["/cmd"].subscribers) == ["o"]


def test_a_refusal_by_a_rule_that_is_not_a_glob_shares_the_access_logs_episodes(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(access, "_episodes", EpisodeLog(access.logger))  # a new episode
    caplog.set_level(logging.WARNING, logger="rwt.session")
    why = "refused, the MCP server is read-only"
    access.log_refused(client="mcp:h#1", op="publish", rule="--mcp-read-only", reason=why, now=0)
    denied = access.AccessDeniedError("topic /x is not allowed on this server", "topics_glob")
    access.log_denied(denied, client="mcp:h#1", op="echo", now=1)  # the same episode
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        "event=access_denied client=mcp:h#1 op=publish rule=--mcp-read-only"
        " reason='refused, the MCP server is read-only'"
    ]


# ---- slow consumers (D24) ----------------------------------------------------------------


def flood(graph: Graph, count: int, size: int = 100) -> None:
    publisher = graph.create_publisher("/flood", "std_msgs/msg/String")
    for i in range(count):
        publisher.publish({"data": f"{i:06d}" + "x" * size})


def limited(graph: Graph, limit: int, timeout_s: float = 5.0, **kw: object) -> GatedPeer:
    config = SessionConfig(send_buffer_limit=limit, send_timeout_s=timeout_s, **kw)  # type: ignore[arg-type]
    peer = GatedPeer(graph, "slow", config)
    peer.send(op="subscribe", topic="/flood", type="std_msgs/String")
    return peer


def test_over_the_limit_the_oldest_topic_messages_go_and_drops_are_counted(
    graph: Graph,
) -> None:
    peer = limited(graph, 2000, status_level=StatusLevel.WARNING)
    flood(graph, 100)
    frames = peer.received()
    assert sum(len(json.dumps(f)) for f in frames) < 2000 + 300
    [warning] = [f for f in frames if f["op"] == "status"]
    assert warning["level"] == "warning" and "dropping the oldest topic messages" in warning["msg"]
    published = [f["msg"]["data"][:6] for f in frames if f["op"] == "publish"]  # type: ignore[index]
    assert published == sorted(published) and published[-1] == "000099"  # the newest are kept
    assert peer.session.stats.dropped_frames == 100 - len(published)


def test_status_and_replies_are_never_dropped(graph: Graph) -> None:
    peer = limited(graph, 1000)
    peer.send(op="subscribe", topic="/x", id="bad", throttle_rate="fast")
    flood(graph, 50)
    frames = peer.received()
    assert frames[0]["op"] == "status" and frames[0]["id"] == "bad"


def test_a_stalled_connection_is_closed_after_the_send_timeout(
    graph: Graph, clock: FakeClock
) -> None:
    peer = limited(graph, 1000, timeout_s=5.0)
    flood(graph, 50)
    assert peer.session.get_timer() == clock.now + 5.0
    clock.now += 4.9
    peer.session.handle_timer(clock.now)
    assert peer.commands() == []
    clock.now += 0.2
    peer.session.handle_timer(clock.now)
    [close] = peer.commands()
    assert close.code is CloseCode.POLICY_VIOLATION
    assert close.reason == "slow consumer: send buffer over 1000 bytes for 5 s"
    peer.send(op="subscribe", topic="/y", type="std_msgs/String")
    assert "/y" not in graph.topics  # input after the close is ignored


def test_a_slow_but_reading_connection_is_not_closed(graph: Graph, clock: FakeClock) -> None:
    peer = limited(graph, 1000, timeout_s=5.0)
    for _ in range(10):
        flood(graph, 50)
        peer.session.frames_to_send(max_bytes=200)  # reads a little: progress
        clock.now += 3.0
        peer.session.handle_timer(clock.now)
    assert peer.commands() == []
    assert peer.session.stats.dropped_frames > 0


def test_catching_up_ends_the_episode_and_a_new_one_warns_again(
    graph: Graph, clock: FakeClock
) -> None:
    peer = limited(graph, 1000, status_level=StatusLevel.WARNING)
    flood(graph, 30)
    assert len(peer.statuses()) == 1  # read everything: caught up
    assert peer.session.get_timer() is None
    flood(graph, 30)
    assert len(peer.statuses()) == 1


def test_undroppable_frames_past_the_limit_close_the_connection(graph: Graph) -> None:
    peer = GatedPeer(graph, "p", SessionConfig(send_buffer_limit=500))
    for i in range(40):
        peer.send(op="subscribe", topic=f"/nope{i}", id=i)  # each gets an error status
    [close] = peer.commands()
    assert close.code is CloseCode.POLICY_VIOLATION and "send buffer overflow" in close.reason
    assert peer.session.stats.queued_bytes < 500 + 200


def test_frames_are_taken_in_bounded_batches(graph: Graph) -> None:
    peer = limited(graph, 1 << 20)
    flood(graph, 20)
    batch = peer.session.frames_to_send(max_bytes=300)
    assert 1 <= len(batch) <= 3
    assert len(peer.session.frames_to_send()) == 20 - len(batch)


# ---- shutdown ---------------------------------------------------------------------------


def test_shutdown_releases_then_closes_with_going_away(graph: Graph) -> None:
    peer = GatedPeer(graph, "a", SessionConfig())
    peer.send(op="advertise", topic="/t", type="std_msgs/String")
    peer.session.begin_shutdown()
    peer.send(op="advertise", topic="/u", type="std_msgs/String")
    assert "/u" not in graph.topics and peer.session.closing
    peer.session.request_close(CloseCode.GOING_AWAY, "server shutting down")
    peer.session.request_close(CloseCode.NORMAL, "second request is ignored")
    assert peer.commands() == [CloseConnection(CloseCode.GOING_AWAY, "server shutting down")]


def test_a_closed_session_ignores_everything(graph: Graph) -> None:
    peer = GatedPeer(graph, "a", SessionConfig())
    peer.session.close()
    peer.session.begin_shutdown()
    peer.session.request_close(CloseCode.GOING_AWAY, "late")
    peer.session.report(StatusLevel.ERROR, "late")
    peer.send(op="advertise", topic="/t", type="std_msgs/String")
    assert peer.received() == [] and peer.commands() == [] and "/t" not in graph.topics


def test_a_bug_in_a_handler_is_an_internal_error_status(
    graph: Graph, monkeypatch: pytest.MonkeyPatch
) -> None:
    def broken(session: Session, op: object, now: float) -> None:
        raise KeyError("oops")

    monkeypatch.setitem(HANDLERS, ops.SetLevel, broken)
    peer = GatedPeer(graph, "a", SessionConfig())
    peer.send(op="set_level", level="info", id="x")
    assert peer.received() == [
        {"op": "status", "level": "error", "msg": "set_level: internal error", "id": "x"}
    ]


def test_failure_replies_without_an_id_have_none() -> None:
    reply = failure_reply(CallService(service="/s"), "no")
    assert reply is not None and "id" not in reply
    assert failure_reply(Subscribe(topic="/t"), "no") is None


def test_parameter_services_without_a_name_are_left_to_rosapi(graph: Graph) -> None:
    policy = AccessPolicy(params=("/public/*",))
    for args in (None, [], {"name": 5}, "x"):
        check_op(policy, CallService(service="/rosapi/get_param", args=args))


def test_the_transport_is_woken_for_output_and_closes_are_idempotent(graph: Graph) -> None:
    wakes: list[int] = []
    session = Session(graph.port, "w", config=SessionConfig(), on_output=lambda: wakes.append(1))
    session.receive_frame(b"5", 1.0)  # an error status: output
    assert wakes and session.close_request is None
    session.request_close(CloseCode.NORMAL, "bye")
    assert session.close_request == CloseConnection(CloseCode.NORMAL, "bye")
    session.close()
    session.close()
    session.handle_timer(1e9)
    assert session.closed and session.get_timer() is None


def test_the_lifecycle_moves_along_its_table(graph: Graph) -> None:
    peer = GatedPeer(graph, "a", rosauth([WALL]))
    assert peer.session.state is State.AUTHENTICATING
    peer.send(**auth_op())
    assert peer.session.state is State.OPEN
    peer.session.begin_shutdown()
    peer.send(op="advertise", topic="/t", type="std_msgs/String")  # ignored: draining
    assert peer.session.state is State.DRAINING and "/t" not in graph.topics
    peer.session.request_close(CloseCode.GOING_AWAY, "stopping")
    assert peer.session.state is State.CLOSING and peer.session.authenticated
    peer.session.close()
    assert peer.session.state is State.CLOSED


def test_what_a_session_holds_changes_through_its_ops(graph: Graph) -> None:
    peer = Peer(graph, "h")
    peer.send(op="subscribe", topic="/a", type="std_msgs/String", id="s")
    peer.send(op="advertise", topic="/b", type="std_msgs/String", id="p")
    peer.send(op="advertise_service", service="/srv", type="std_srvs/Trigger")
    holdings = peer.session.holdings
    assert list(holdings.subscriptions) == ["/a"] and holdings.advertisements == {"/b": {"p"}}
    assert holdings.offers == {("service", "/srv")} and holdings.offered() == 2
    with pytest.raises(AttributeError):  # read-only: set_level (or set_status_level) changes it
        peer.session.status_level = StatusLevel.INFO  # type: ignore[misc]
    peer.send(op="unsubscribe", topic="/a", id="s")
    peer.send(op="unadvertise", topic="/b")
    peer.send(op="unadvertise_service", service="/srv")
    assert not holdings.holds_anything() and peer.received() == []


def test_an_illegal_transition_is_an_error() -> None:
    with pytest.raises(LocalProtocolError, match="no transition from CLOSED to OPEN"):
        advance(State.CLOSED, State.OPEN)
    assert all(
        State.OPEN not in targets
        for state, targets in TRANSITIONS.items()
        if state is not State.AUTHENTICATING
    )
    assert advance(State.OPEN, State.CLOSING) is State.CLOSING


def test_bounded_batches_keep_undroppable_frames_counted(graph: Graph) -> None:
    peer = limited(graph, 1 << 20)
    peer.send(op="subscribe", topic="/nope", id=1)  # an error status
    flood(graph, 3)
    first = peer.session.frames_to_send(max_bytes=1)
    assert len(first) == 1 and not first[0].droppable
    assert len(peer.session.frames_to_send()) == 3


def test_a_fragmented_message_already_partly_sent_is_never_cut() -> None:
    box = Outbox(limit_bytes=10, frame_overhead_bytes=0)  # payload sizes only
    group = object()
    box.extend([OutFrame(part, droppable=True, group=group) for part in (b"aaaa", b"bbbb", b"cc")])
    assert [f.data for f in box.take(max_bytes=4)] == [b"aaaa"]  # the peer has part 1
    box.push(OutFrame(b"dddddddd", droppable=True))  # over the limit: something must go
    assert [f.data for f in box.take()] == [b"bbbb", b"cc"]  # the rest of the message
    assert box.dropped == 1  # the newer whole message went instead


def test_dropping_many_small_frames_is_linear(graph: Graph) -> None:
    box = Outbox(limit_bytes=1000, frame_overhead_bytes=0)
    box.push(OutFrame(b"s" * 10))  # an undroppable frame at the front stays there
    for i in range(20000):
        box.push(OutFrame(b"%08d" % i, droppable=True))
    frames = box.take()
    assert frames[0].data == b"s" * 10 and frames[-1].data == b"%08d" % 19999
    assert box.dropped == 20000 - (len(frames) - 1)
