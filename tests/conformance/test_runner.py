"""The conformance runner against in-process servers: ours, and deliberately broken ones."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import anyio
import pytest

from rwt_conformance import (
    Outcome,
    Profile,
    RunOptions,
    SuiteResult,
    run_suite,
)
from rwt_conformance.model import Dialect
from rwt_conformance.report import write_json, write_junit
from rwt_conformance.runner import NEEDS_SECRET
from rwt_graph.clock import SystemClock
from rwt_graph.graph import Graph
from rwt_protocol.auth import Authenticator
from rwt_protocol.levels import StatusLevel
from rwt_protocol.names import resolve_name
from rwt_protocol.ports import TopicSink
from rwt_protocol.server.session import Session
from rwt_transports.server import (
    RosbridgeServer,
    ServerConfig,
    rosauth_authenticator,
)
from tests.support.shipped_suite import SUITE

pytestmark = pytest.mark.anyio


class SilentSession(Session):
    """D1 switched off: refused ops are dropped without a status (rosbridge_suite's way)."""

    def report(self, level: StatusLevel, text: str, op_id: str | int | None = None) -> None:
        pass


class SilentServer(RosbridgeServer):
    """A server whose connections never send status messages."""

    session_class = SilentSession


def forgetful_graph() -> Graph:
    """D13 switched off: latched messages are never replayed to later subscribers."""
    graph = Graph()
    subscribe = graph.port.subscribe

    def forgetful(
        client: str, topic: str, type_name: str | None, sink: TopicSink, **qos: Any
    ) -> str:
        entry = graph.topics.get(resolve_name(topic))
        if entry is not None:
            entry.latched = None
        return subscribe(client, topic, type_name, sink, **qos)

    graph.port.subscribe = forgetful  # type: ignore[method-assign]
    return graph


async def _run(server: RosbridgeServer, **options: Any) -> SuiteResult:
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        result = await run_suite(SUITE, RunOptions(url, **options))
        tg.cancel_scope.cancel()
    return result


LOCAL = ServerConfig(port=0)


async def test_our_server_passes_the_strict_profile(tmp_path: Path) -> None:
    result = await _run(RosbridgeServer(config=LOCAL))
    failures = [
        (r.requirement.id, r.detail) for r in result.requirements if r.outcome is Outcome.FAILED
    ]
    assert failures == []
    assert result.count(Outcome.PASSED) > 70
    skipped = [c for c in result.cases if c.outcome is Outcome.SKIPPED]
    cites = re.compile(r"REF §\d|\bD\d+\b")  # a case left out of strict says why
    assert all(
        c.detail.startswith(("pending: ", "needs ")) or cites.search(c.detail)
        for c in skipped
        if not c.off_version
    )
    # rwt answers protocol 2.1.0: the rule of the unversioned spec before it is left out
    assert result.spec is not None and str(result.spec.version) == "2.1.0"
    off = {c.case.id: c.detail for c in skipped if c.off_version}
    assert off == {
        "topics.publish-with-type-does-not-advertise": "holds for the unversioned spec"
        " (before 2.0.0); the server is judged by spec 2.1.0"
    }
    write_junit(result, tmp_path / "junit.xml")
    write_json(result, tmp_path / "report.json")
    assert "<testsuite" in (tmp_path / "junit.xml").read_text()
    assert '"failed": 0' in (tmp_path / "report.json").read_text()


async def test_our_server_passes_the_reference_profile() -> None:
    result = await _run(RosbridgeServer(config=LOCAL), profile=Profile.REFERENCE)
    assert [r.requirement.id for r in result.requirements if r.outcome is Outcome.FAILED] == []
    # where the ROS 2 reference breaks the spec, rwt passes the spec's way
    recorded = [c for c in result.cases if c.case.defects(Profile.REFERENCE, Dialect.ROS2)]
    assert len(recorded) == 10
    assert all(c.outcome is Outcome.PASSED and c.detail == "" for c in recorded)


async def test_a_server_without_status_messages_fails_d1() -> None:
    result = await _run(  # its misses are not retried: each would wait 3 times longer, again
        SilentServer(config=LOCAL),
        only=("D1", "D2", "spec.message.*"),
        expect_timeout_s=0.3,
        retry_budget_s=0,
    )
    failed = {r.requirement.id for r in result.requirements if r.outcome is Outcome.FAILED}
    assert {"D1", "D2", "spec.message.op"} <= failed
    # cases failed without a word from it, but it answers: the run went on to the end
    assert any(c.unanswered for c in result.cases)
    assert result.verdict is None
    assert not result.ok
    assert result.summary().split(", ")[1] == f"{len(failed)} failed"
    [d1] = [r for r in result.requirements if r.requirement.id == "D1"]
    assert "no frame matching {'op': 'status'" in d1.detail


async def test_the_same_broken_server_passes_the_reference_profile_of_those_rules() -> None:
    result = await _run(
        SilentServer(config=LOCAL), only=("D1", "spec.message.*"), profile=Profile.REFERENCE
    )
    assert result.ok


async def test_a_server_without_latching_fails_d13() -> None:
    server = RosbridgeServer(forgetful_graph(), LOCAL)
    result = await _run(server, only=("D13",), expect_timeout_s=0.5, retry_budget_s=0)
    [d13] = [r for r in result.requirements if r.requirement.id == "D13"]
    assert d13.outcome is Outcome.FAILED
    assert "latched" in d13.detail


async def test_a_server_that_is_not_there_is_one_verdict_not_every_case_failing() -> None:
    with anyio.fail_after(30):
        result = await run_suite(
            SUITE, RunOptions("ws://127.0.0.1:1", only=("topics.*",), expect_timeout_s=0.5)
        )
    assert result.verdict is not None
    assert result.verdict.startswith("cannot connect to ws://127.0.0.1:1: ")
    assert result.cases == () and result.requirements == ()
    assert not result.ok


SECRET = "s3cret"
AUTH_ONLY = ("D23", "spec1.auth.*", "D22")


def _secured(authenticator: Authenticator) -> RosbridgeServer:
    return RosbridgeServer(config=LOCAL, authenticator=authenticator)


@pytest.mark.parametrize("profile", list(Profile))
async def test_a_secured_server_passes_the_auth_cases(profile: Profile) -> None:
    server = _secured(rosauth_authenticator(SECRET, SystemClock()))
    result = await _run(server, only=AUTH_ONLY, auth_secret=SECRET, profile=profile)
    outcomes = {r.requirement.id: r.outcome for r in result.requirements}
    assert set(outcomes.values()) == {Outcome.PASSED}
    assert {"D23", "spec1.auth.required", "spec1.auth.disabled"} <= set(outcomes)
    assert "D22" in outcomes  # its connections authenticated first
    assert {c.case.id for c in result.cases} >= {
        "connections.auth-first-op",
        "connections.auth-bad-mac",
        "connections.auth-expired",
        "connections.auth-valid",
    }


async def test_a_server_admitting_any_auth_fails_d23() -> None:
    result = await _run(
        _secured(lambda op, peer: True), only=AUTH_ONLY, auth_secret=SECRET, expect_timeout_s=0.3
    )
    outcomes = {c.case.id: c.outcome for c in result.cases}
    assert outcomes["connections.auth-bad-mac"] is Outcome.FAILED
    assert outcomes["connections.auth-expired"] is Outcome.FAILED
    assert outcomes["connections.auth-first-op"] is Outcome.PASSED
    [d23] = [r for r in result.requirements if r.requirement.id == "D23"]
    assert d23.outcome is Outcome.FAILED
    assert "no frame matching {'op': 'status', 'level': 'error'}" in d23.detail


async def test_a_server_refusing_every_auth_fails_the_valid_case() -> None:
    result = await _run(
        _secured(lambda op, peer: False), only=AUTH_ONLY, auth_secret=SECRET, expect_timeout_s=0.3
    )
    outcomes = {c.case.id: c.outcome for c in result.cases}
    assert outcomes["connections.auth-valid"] is Outcome.FAILED
    assert outcomes["connections.transport"] is Outcome.FAILED  # D22: its connections are refused


async def test_without_the_secret_the_auth_cases_are_skipped_and_a_secured_server_fails() -> None:
    server = _secured(rosauth_authenticator(SECRET, SystemClock()))
    result = await _run(server, only=AUTH_ONLY, expect_timeout_s=0.3)
    outcomes = {r.requirement.id: (r.outcome, r.detail) for r in result.requirements}
    assert outcomes["D23"] == (Outcome.SKIPPED, NEEDS_SECRET)
    assert outcomes["D22"][0] is Outcome.FAILED
