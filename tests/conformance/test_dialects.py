"""The suite speaks the server's dialect: ROS 1 (secs/nsecs, pkg/Type) or ROS 2."""

from __future__ import annotations

import json
from pathlib import Path

import anyio
import pytest

from rwt_conformance import Outcome, Profile, RunOptions, SuiteResult, load_suite, run_suite
from rwt_conformance.detect import detect_dialect
from rwt_conformance.frames import Received
from rwt_conformance.model import Dialect, SuiteError
from rwt_conformance.runner import _CaseRun, _Link
from rwt_graph.graph import Graph
from rwt_graph.types.names import Dialect as GraphDialect
from rwt_graph.types.registry import TypeRegistry
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.support.shipped_suite import SUITE

pytestmark = pytest.mark.anyio


def _server(dialect: GraphDialect) -> RosbridgeServer:
    return RosbridgeServer(Graph(TypeRegistry(dialect)), ServerConfig(port=0))


async def _run(server: RosbridgeServer, **options: object) -> SuiteResult:
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        result = await run_suite(SUITE, RunOptions(url, **options))  # type: ignore[arg-type]
        tg.cancel_scope.cancel()
    return result


@pytest.mark.parametrize("profile", list(Profile))
async def test_rwt_serve_dialect_ros1_passes_both_profiles(profile: Profile) -> None:
    result = await _run(_server(GraphDialect.ROS1), profile=profile, dialect=Dialect.ROS1)
    failures = [(c.case.id, c.detail) for c in result.cases if c.outcome is Outcome.FAILED]
    assert failures == []
    assert result.count(Outcome.PASSED) > 70


@pytest.mark.parametrize(
    ("served", "expected"),
    [(GraphDialect.ROS1, Dialect.ROS1), (GraphDialect.ROS2, Dialect.ROS2)],
)
async def test_the_dialect_is_asked_of_the_server(served: GraphDialect, expected: Dialect) -> None:
    async with anyio.create_task_group() as tg:
        url = await tg.start(_server(served).serve)
        found, how = await detect_dialect(url, timeout_s=2.0)
        tg.cancel_scope.cancel()
    assert found is expected
    assert how


async def test_a_run_without_a_dialect_detects_it_and_speaks_it() -> None:
    result = await _run(_server(GraphDialect.ROS1), only=("types.time-forms",))
    assert result.options.dialect is Dialect.ROS1
    assert [c.outcome for c in result.cases] == [Outcome.PASSED]


async def test_speaking_ros2_to_a_ros1_server_fails_the_time_forms() -> None:
    """The dialect steps are what make the case pass: the wrong one fails it."""
    result = await _run(
        _server(GraphDialect.ROS1),
        only=("types.time-forms",),
        dialect=Dialect.ROS2,
        expect_timeout_s=0.5,
    )
    [case] = result.cases
    assert case.outcome is Outcome.FAILED
    assert "nanosec" in case.detail


async def test_a_server_that_is_not_there_is_assumed_ros2() -> None:
    found, how = await detect_dialect("ws://127.0.0.1:1", timeout_s=0.5)
    assert found is Dialect.ROS2
    assert how.startswith("assumed")


def _suite(folder: Path, case: str) -> Path:
    (folder / "cases").mkdir()
    (folder / "requirements.toml").write_text(
        '[[requirement]]\nid = "r1"\nsource = "spec 1"\nstatement = "s"\n'
    )
    (folder / "cases" / "c.toml").write_text(
        '[[case]]\nid = "c"\nrequirements = ["r1"]\nsteps = []\n' + case
    )
    return folder


def test_a_case_must_say_its_dialects(tmp_path: Path) -> None:
    with pytest.raises(SuiteError, match="profiles and dialects"):
        load_suite(_suite(tmp_path, 'profiles = ["strict"]\n'))


def test_an_unknown_dialect_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SuiteError, match="ros3"):
        load_suite(_suite(tmp_path, 'profiles = ["strict"]\ndialects = ["ros3"]\n'))


def test_an_unknown_skip_key_is_refused(tmp_path: Path) -> None:
    case = 'profiles = ["strict"]\ndialects = ["ros1"]\nskip = { ros3 = "no" }\n'
    with pytest.raises(SuiteError, match="skip takes a table"):
        load_suite(_suite(tmp_path, case))


def test_skip_reasons_are_given_per_profile_dialect_and_both(tmp_path: Path) -> None:
    case = (
        'profiles = ["strict", "reference"]\ndialects = ["ros2"]\n'
        'skip = { ros1 = "REF §4.3: no such type", "reference+ros2" = "REF §1.4: stalls" }\n'
    )
    [loaded] = load_suite(_suite(tmp_path, case)).cases
    assert loaded.skip_reason(Profile.STRICT, Dialect.ROS1) == "REF §4.3: no such type"
    assert loaded.skip_reason(Profile.REFERENCE, Dialect.ROS2) == "REF §1.4: stalls"
    assert loaded.skip_reason(Profile.STRICT, Dialect.ROS2) is None


def _parts(message: dict[str, object], size: int, fragment_id: object) -> list[Received]:
    text = json.dumps(message)
    pieces = [text[i : i + size] for i in range(0, len(text), size)]
    return [
        Received(
            {"op": "fragment", "id": fragment_id, "data": p, "num": n, "total": len(pieces) / 1},
            False,
        )
        for n, p in enumerate(pieces)
    ]


def test_a_sync_echo_cut_into_fragments_still_counts_and_leaves_no_frames() -> None:
    """rosbridge_suite's fragment_size applies to all later output (REF §1.3)."""
    case = SUITE.cases[0]
    run = _CaseRun(case, RunOptions("ws://127.0.0.1:1", dialect=Dialect.ROS1), {"ns": "n"})
    link = _Link("a", None, "/n/sync_a")  # type: ignore[arg-type]
    echo = {"op": "publish", "topic": "/n/sync_a", "msg": {"data": "sync-1"}}
    other = {"op": "publish", "topic": "/n/t", "msg": {"data": "keep me"}}
    for part in _parts(other, 20, 0) + _parts(echo, 20, 0):
        link.frames.append(part)
        run._defragment(link, part)
    assert link.tokens == {"sync-1"}
    kept = [f.value for f in link.frames]
    assert len(kept) == len(_parts(other, 20, 0))  # the case still sees the other message's parts
    assert all(isinstance(v, dict) and v["op"] == "fragment" for v in kept)
