"""Spec versions in the conformance suite (docs/conformance.md, "Spec versions").

A requirement holds for a range of spec versions; the runner judges a server by
the version its ``GET /version`` tells, else by a probe of what 2.0.0 changed (a
``publish`` with ``type`` advertises) and of what 2.1.0 added (such a ``publish`` with a
bad ``qos`` is refused), else by ``--spec-version``; a case none of
whose requirements holds there is skipped, naming the version. In-process servers:
rwt as it is (protocol 2.1.0), ``--compat rosbridge-2.1`` (no ``/version``, a
publish with type refused), rwt behind a hostile ``/version``, and rwt behind a proxy
that hides each op's ``qos`` (a 2.0.0 server).
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import anyio
import anyio.abc
import pytest
from rich.console import Console

from rwt_conformance import Outcome, Profile, RunOptions, SuiteResult, load_suite, run_suite
from rwt_conformance.model import SuiteError
from rwt_conformance.report import print_table, write_json, write_junit
from rwt_conformance.runner import run_case
from rwt_conformance.specdetect import MAX_VERSION_BYTES, SpecSource, read_version_endpoint
from rwt_conformance.versions import SpecVersion, VersionRange
from rwt_protocol.server.compat import Compat
from rwt_protocol.server.session import SessionConfig
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.support.shipped_suite import SUITE

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

    from anyio.abc import ByteStream, SocketStream

pytestmark = pytest.mark.anyio

VERSIONED = ("D48", "spec.publish.type-ignored")
"""The requirement of 2.0.0 on (D48) and the one of the unversioned spec before it."""
UNVERSIONED = SpecVersion.UNVERSIONED


async def _run(server: RosbridgeServer, **options: Any) -> SuiteResult:
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        result = await run_suite(SUITE, RunOptions(url, **{"only": VERSIONED, **options}))
        tg.cancel_scope.cancel()
    return result


def _outcomes(result: SuiteResult) -> dict[str, tuple[Outcome, str]]:
    return {r.requirement.id: (r.outcome, r.detail) for r in result.requirements}


def test_versions_are_spelled_and_ordered() -> None:
    assert str(UNVERSIONED) == "unversioned"
    assert SpecVersion.parse("Unversioned") == UNVERSIONED
    assert SpecVersion.parse("2.1") == SpecVersion.parse("2.1.0") == SpecVersion.of(2, 1)
    assert UNVERSIONED < SpecVersion.parse("1.0") < SpecVersion.of(2) < SpecVersion.of(2, 1)
    for bad in ("2", "v2.0", "2.0.0.0", "", "2.x", "99999.0"):
        with pytest.raises(ValueError, match="not a spec version"):
            SpecVersion.parse(bad)
    d48 = SUITE.requirements["D48"].versions
    assert d48 == VersionRange(since=SpecVersion.of(2))
    assert not d48.holds(UNVERSIONED) and d48.holds(SpecVersion.of(2, 1))
    old = SUITE.requirements["spec.publish.type-ignored"].versions
    assert old.holds(UNVERSIONED) and not old.holds(SpecVersion.of(2))
    assert SUITE.requirements["spec.publish.deliver"].versions.everywhere


def test_a_range_that_ends_before_it_starts_is_refused(tmp_path: Path) -> None:
    (tmp_path / "cases").mkdir()
    (tmp_path / "requirements.toml").write_text(
        '[[requirement]]\nid = "r"\nsource = "spec 1"\nstatement = "s"\n'
        'since = "2.1.0"\nuntil = "unversioned"\n'
    )
    with pytest.raises(SuiteError, match=r"until .* must come after since"):
        load_suite(tmp_path)


async def test_a_case_outside_the_judged_version_is_skipped_naming_it(tmp_path: Path) -> None:
    (tmp_path / "cases").mkdir()
    (tmp_path / "requirements.toml").write_text(
        '[[requirement]]\nid = "new"\nsource = "spec 4"\nstatement = "s"\nsince = "2.1"\n'
    )
    (tmp_path / "cases" / "c.toml").write_text(
        '[[case]]\nid = "c"\nrequirements = ["new"]\nprofiles = "strict"\n'
        'dialects = ["ros1", "ros2"]\nsteps = [{ sync = true }]\n'
    )
    [case] = load_suite(tmp_path).cases
    # no server at this URL: a case skipped for its version connects to nothing
    options = RunOptions("ws://127.0.0.1:1", spec_version=SpecVersion.of(2))
    result = await run_case(case, options, {"ns": "n"})
    assert result.outcome is Outcome.SKIPPED and result.off_version
    assert result.detail == "holds for spec 2.1.0 and later; the server is judged by spec 2.0.0"


async def test_rwt_is_judged_by_its_get_version() -> None:
    result = await _run(RosbridgeServer(config=ServerConfig(port=0)))
    assert result.spec is not None
    assert (result.spec.version, result.spec.source) == (
        SpecVersion.of(2, 1),
        SpecSource.VERSION_ENDPOINT,
    )
    assert result.spec.describe() == "spec version 2.1.0 (from GET /version)"
    outcomes = _outcomes(result)
    assert outcomes["D48"][0] is Outcome.PASSED
    assert outcomes["spec.publish.type-ignored"] == (
        Outcome.SKIPPED,
        "holds for the unversioned spec (before 2.0.0); the server is judged by spec 2.1.0",
    )


async def test_compat_2_1_has_no_version_and_the_probe_judges_it_unversioned() -> None:
    compat = ServerConfig(port=0, session=SessionConfig(compat=Compat.ROSBRIDGE_2_1))
    result = await _run(RosbridgeServer(config=compat), profile=Profile.REFERENCE)
    assert result.ok
    assert result.spec is not None
    assert (result.spec.version, result.spec.source) == (UNVERSIONED, SpecSource.PROBE)
    assert result.spec.describe() == (
        "spec version unversioned (from a probe: it was refused (a publish with type to an"
        " unknown topic, then /rosapi/topic_type: no type after 1 s);"
        " GET /version: answered status 404)"
    )
    outcomes = _outcomes(result)
    assert outcomes["spec.publish.type-ignored"][0] is Outcome.PASSED
    assert outcomes["D48"] == (
        Outcome.SKIPPED,
        "holds for spec 2.0.0 and later; the server is judged by the unversioned spec",
    )


async def test_spec_version_overrides_what_the_server_says() -> None:
    """rwt judged by the unversioned spec fails its rule: rwt's publish with type advertises."""
    server = RosbridgeServer(config=ServerConfig(port=0))
    # the error status that never comes is not waited for long, nor again
    result = await _run(server, spec_version=UNVERSIONED, expect_timeout_s=0.3, retry_budget_s=0)
    assert result.spec is not None
    assert result.spec.describe() == "spec version unversioned (given with --spec-version)"
    outcomes = _outcomes(result)
    assert outcomes["spec.publish.type-ignored"][0] is Outcome.FAILED
    assert outcomes["D48"][0] is Outcome.SKIPPED


async def test_the_reports_name_the_spec_version(tmp_path: Path) -> None:
    result = await _run(RosbridgeServer(config=ServerConfig(port=0)))
    console = Console(width=200, record=True)
    print_table(result, console)
    text = console.export_text()
    assert text.splitlines()[0] == "spec version 2.1.0 (from GET /version)"
    write_json(result, tmp_path / "report.json")
    found = json.loads((tmp_path / "report.json").read_text())["spec_version"]
    assert found["version"] == "2.1.0" and found["source"] == "version-endpoint"
    assert found["detail"].endswith("/version says protocol 2.1.0")
    write_junit(result, tmp_path / "junit.xml")
    assert 'name="spec_version"' in (tmp_path / "junit.xml").read_text()


def _ok(body: bytes) -> bytes:
    return b"HTTP/1.1 200 OK\r\nContent-Length: %d\r\n\r\n%s" % (len(body), body)


# A hostile GET /version: what it answers, and why the runner does not believe it.
HOSTILE = {
    "a huge body": (
        b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n\r\n"
        + b'{"protocol": {"major": 2, "minor": 1, "patch": 0}, "pad": "'
        + b"x" * (4 * MAX_VERSION_BYTES),
        f"the answer is over {MAX_VERSION_BYTES} bytes",
    ),
    "bad JSON": (_ok(b"{protocol"), "the answer is not JSON"),
    "deep JSON": (_ok(b"[" * 40000), "the answer is not JSON"),
    "strings for numbers": (
        _ok(b'{"protocol": {"major": "2", "minor": 1, "patch": 0}}'),
        "the answer has no protocol.major, .minor and .patch as small integers",
    ),
    "booleans and huge numbers": (
        _ok(b'{"protocol": {"major": true, "minor": 1, "patch": 10000000000000000000000}}'),
        "the answer has no protocol.major, .minor and .patch as small integers",
    ),
    "a list": (_ok(b"[]"), "the answer has no protocol"),
    "a 500": (b"HTTP/1.1 500 Oops\r\nContent-Length: 0\r\n\r\n", "answered status 500"),
    "huge headers": (
        b"HTTP/1.1 200 OK\r\n" + b"X-Pad: " + b"y" * 100_000 + b"\r\n\r\n",
        "",
    ),
    "not HTTP": (b"\x00\xff garbage\r\n\r\n", ""),
}


class HostileVersion:
    """An ``HttpEndpoint`` claiming ``/version`` and answering ``answer`` as it stands."""

    def __init__(self, answer: bytes) -> None:
        self.answer = answer

    @staticmethod
    def claims(head: bytes) -> bool | None:
        return head.startswith(b"GET /version") if len(head) >= 12 else None

    async def serve(self, stream: ByteStream, head: bytes, peer: str) -> None:
        with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            for start in range(0, len(self.answer), 65536):  # the runner stops reading
                await stream.send(self.answer[start : start + 65536])

    def bind(self, tg: object) -> None:
        """Nothing runs beyond a request."""


@pytest.fixture
async def hostile_http() -> AsyncIterator[dict[str, str]]:
    """A plain listener per ``HOSTILE`` answer; their ``http://`` URLs by name."""
    urls: dict[str, str] = {}
    async with contextlib.AsyncExitStack() as listeners, anyio.create_task_group() as tg:
        for name, (answer, _) in HOSTILE.items():
            listener = await anyio.create_tcp_listener(local_host="127.0.0.1")
            await listeners.enter_async_context(listener)

            async def handle(stream: SocketStream, answer: bytes = answer) -> None:
                async with stream:
                    await HostileVersion(answer).serve(stream, b"", "")

            port = listener.extra(anyio.abc.SocketAttribute.local_port)
            urls[name] = f"http://127.0.0.1:{port}/version"
            tg.start_soon(listener.serve, handle)
        yield urls
        tg.cancel_scope.cancel()


async def test_a_hostile_version_answer_is_judged_safely(hostile_http: dict[str, str]) -> None:
    for name, (_, why) in HOSTILE.items():
        version, said = await read_version_endpoint(hostile_http[name], timeout_s=2.0)
        assert version is None, name
        assert said.startswith(why), (name, said)
        assert len(said) <= 200 and said.isprintable(), (name, said)


async def test_a_hostile_version_falls_back_to_the_probe_and_says_why() -> None:
    answer, _ = HOSTILE["strings for numbers"]
    server = RosbridgeServer(config=ServerConfig(port=0))
    server.endpoints["version"] = HostileVersion(answer)  # a test's hostile endpoint
    result = await _run(server)
    assert result.spec is not None
    assert (result.spec.version, result.spec.source) == (SpecVersion.of(2, 1), SpecSource.PROBE)
    assert result.spec.detail == (
        "it was advertised, and refused for its qos (a publish with type to an unknown topic,"
        " then /rosapi/topic_type: names std_msgs/msg/String; the same with qos depth -1 to"
        " another: no type after 1 s); GET /version: the answer has no protocol.major, .minor"
        " and .patch as small integers"
    )
    assert _outcomes(result)["D48"][0] is Outcome.PASSED


class _ForgetQos:
    """rwt behind a TCP proxy that renames each op's ``qos`` field: a 2.0.0 server.

    rwt ignores a field it does not know, as a server of 2.0.0 ignores ``qos``
    (rosbridge_suite 2.6.0, 3.2.0, 4.1.0); the name keeps its length, so the
    stream's framing is untouched.
    """

    def __init__(self, port: int) -> None:
        self.port = port

    async def serve(self, task_status: anyio.abc.TaskStatus[int]) -> None:
        async with await anyio.create_tcp_listener(local_host="127.0.0.1") as listener:
            task_status.started(listener.extra(anyio.abc.SocketAttribute.local_port))
            await listener.serve(self._connection)

    async def _connection(self, client: SocketStream) -> None:
        server = await anyio.connect_tcp("127.0.0.1", self.port)
        async with client, server, anyio.create_task_group() as tg:
            tg.start_soon(self._pipe, server, client, b"")
            await self._pipe(client, server, b'"qos"')
            tg.cancel_scope.cancel()

    @staticmethod
    async def _pipe(source: ByteStream, sink: ByteStream, field: bytes) -> None:
        with contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError):
            while True:
                data = await source.receive()
                await sink.send(data.replace(field, b'"xqs"') if field else data)


async def test_the_probe_tells_2_1_0_from_2_0_0_by_a_qos_refused_or_ignored() -> None:
    """Over TCP (no ``GET /version``): rwt refuses a bad ``qos``, a 2.0.0 server ignores it."""
    server = RosbridgeServer(config=ServerConfig(port=None, tcp_port=0))
    only = ("qos.invalid", "D48")
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        tcp = int(server.urls["tcp"].rsplit(":", 1)[1])
        proxy = await tg.start(_ForgetQos(tcp).serve)
        rwt = await run_suite(SUITE, RunOptions(f"tcp://127.0.0.1:{tcp}", only=only))
        old = await run_suite(SUITE, RunOptions(f"tcp://127.0.0.1:{proxy}", only=only))
        tg.cancel_scope.cancel()
    assert rwt.spec is not None and old.spec is not None
    assert (rwt.spec.version, rwt.spec.source) == (SpecVersion.of(2, 1), SpecSource.PROBE)
    assert "refused for its qos" in rwt.spec.detail
    assert (old.spec.version, old.spec.source) == (SpecVersion.of(2), SpecSource.PROBE), old.spec
    assert "its qos ignored" in old.spec.detail
    assert _outcomes(rwt)["spec.qos.invalid"][0] is Outcome.PASSED
    assert _outcomes(old)["spec.qos.invalid"] == (
        Outcome.SKIPPED,
        "holds for spec 2.1.0 and later; the server is judged by spec 2.0.0",
    )
    assert _outcomes(old)["D48"][0] is Outcome.PASSED
