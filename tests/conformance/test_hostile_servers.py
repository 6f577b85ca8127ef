"""The runner against hostile servers: every run ends, with a report and an exit code.

Each server (``hostile``) attacks the runner's bounds (docs/conformance.md, "Against
a hostile server"): it answers too deeply nested JSON, sends frames too big or too
many, closes mid-case, or sends garbage. The run must fail the cases it spoils with
a clear reason, go on to the next case and end as usual. A server that does not
read or answer at all (never reads, reads a byte a second, answers nothing, closes
at once) gets one verdict instead, soon, and exit code 2; so does a run over
``--run-timeout``.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest

from rwt_client.connectors import connect
from rwt_conformance import Outcome, RunOptions, SuiteResult, run_suite
from rwt_conformance.bounds import CASE_BUDGET_BYTES
from rwt_conformance.frames import NESTING_PROBLEM
from rwt_conformance.model import Dialect
from tests.conformance import hostile
from tests.support.cli import RWT
from tests.support.shipped_suite import SUITE

SRC = str(Path(__file__).resolve().parents[2] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC}
TWO_CASES = ("topics.publish-example", "topics.advertise-then-infer")
RWT_CONFORMANCE = [*RWT, "conformance"]
RUN_LIMIT_S = 120  # far above what a bounded run takes: only a hang reaches it


def _rwt_conformance(url: str, *args: str, report: Path) -> subprocess.CompletedProcess[str]:
    """``rwt conformance URL`` on the two cases, with short bounds and a JSON report."""
    only = [arg for case in TWO_CASES for arg in ("--only", case)]
    bounds = ["--timeout", "1", "--case-timeout", "8"]
    return subprocess.run(
        [*RWT_CONFORMANCE, url, *only, *bounds, "--json", str(report), *args],
        env=ENV,
        capture_output=True,
        text=True,
        timeout=RUN_LIMIT_S,
        check=False,
    )


def _case_details(report: Path) -> dict[str, tuple[str, str]]:
    document = json.loads(report.read_text("utf-8"))
    return {
        case["id"]: (case["result"], case["detail"])
        for requirement in document["requirements"]
        for case in requirement["cases"]
    }


def _assert_reported(done: subprocess.CompletedProcess[str], report: Path) -> dict[str, str]:
    """The run ended with exit code 1, its table and summary, and no traceback."""
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    assert " failed, " in done.stdout
    details = _case_details(report)
    assert set(details) == set(TWO_CASES)
    assert {result for result, _ in details.values()} == {"failed"}
    return {case: detail for case, (_, detail) in details.items()}


def _one_verdict(done: subprocess.CompletedProcess[str], report: Path) -> str:
    """The run ended with exit code 2 and one line on stderr, no table, no traceback;
    its JSON report holds the verdict and no case."""
    assert done.returncode == 2, done.stdout[-3000:] + done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert line.startswith("rwt conformance: "), line
    verdict = line.removeprefix("rwt conformance: ")
    document = json.loads(report.read_text("utf-8"))
    assert document["verdict"] == verdict
    assert document["requirements"] == []
    assert done.stdout == ""
    return verdict


DOES_NOT_ANSWER = "the server does not answer: nothing received within 3 s of sending"
NO_HANDSHAKE = "the server does not answer (connecting and its WebSocket handshake took over 6 s)"


BELOW_THE_PROTOCOL: list[tuple[hostile.SocketBehaviour, str, str | tuple[str, ...]]] = [
    (hostile.never_reads, "tcp://", DOES_NOT_ANSWER),
    (hostile.never_reads, "ws://", NO_HANDSHAKE),
    (hostile.reads_a_byte_a_second, "tcp://", DOES_NOT_ANSWER),
    (hostile.reads_a_byte_a_second, "ws://", NO_HANDSHAKE),
    (hostile.closes_at_once, "tcp://", "the server closed the connection before answering"),
    # the close comes during the handshake: a FIN, or a reset when the request was unread
    (hostile.closes_at_once, "ws://", (": the server closed the connection", "reset by peer")),
]
ANSWERING_NOTHING: list[hostile.Behaviour] = [hostile.silent, hostile.never_reads_and_pings]


class _Launched:
    """One ``rwt conformance`` subprocess started early; ``done()`` waits for its end."""

    def __init__(self, args: list[str], report: Path) -> None:
        self.report = report
        self.process = subprocess.Popen(
            [*RWT_CONFORMANCE, *args, "--json", str(report)],
            env=ENV,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )

    def done(self) -> subprocess.CompletedProcess[str]:
        try:
            stdout, stderr = self.process.communicate(timeout=RUN_LIMIT_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.communicate()
            raise
        return subprocess.CompletedProcess(
            self.process.args, self.process.returncode, stdout, stderr
        )


@pytest.fixture(scope="module")
def whole_suite_runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, _Launched]]:
    """The whole-suite runs of the two tests below, all started at once, each against its
    own hostile server, by test id: each waits out the runner's default bounds (3 s, 6 s),
    and the waits overlap instead of adding up. Each run is judged by its own test."""
    folder = tmp_path_factory.mktemp("whole_suite")
    with contextlib.ExitStack() as servers:
        runs: dict[str, _Launched] = {}
        for behaviour, scheme, _ in BELOW_THE_PROTOCOL:
            address = servers.enter_context(hostile.serving_sockets(behaviour))
            key = f"{behaviour.__name__}-{scheme}"
            runs[key] = _Launched([scheme + address], folder / f"{len(runs)}.json")
        for answering in ANSWERING_NOTHING:
            url = servers.enter_context(hostile.serving(answering))
            runs[answering.__name__] = _Launched([url], folder / f"{len(runs)}.json")
        try:
            yield runs
        finally:
            for run in runs.values():  # a test that failed early leaves its run going
                if run.process.poll() is None:
                    run.process.kill()
                run.process.communicate()


@pytest.mark.parametrize(
    ("behaviour", "scheme", "expected"),
    BELOW_THE_PROTOCOL,
    ids=lambda value: getattr(value, "__name__", str(value)[:12]),
)
def test_a_server_below_the_protocol_gets_one_verdict_for_the_whole_suite(
    whole_suite_runs: dict[str, _Launched],
    behaviour: hostile.SocketBehaviour,
    scheme: str,
    expected: str | tuple[str, ...],
) -> None:
    """The whole suite at the default bounds (it took about 500 s, 188 failures, before)."""
    run = whole_suite_runs[f"{behaviour.__name__}-{scheme}"]
    verdict = _one_verdict(run.done(), run.report)
    assert any(
        text in verdict for text in (expected if isinstance(expected, tuple) else (expected,))
    )


@pytest.mark.parametrize("behaviour", ANSWERING_NOTHING, ids=lambda b: b.__name__)
def test_a_websocket_server_answering_nothing_gets_one_verdict(
    whole_suite_runs: dict[str, _Launched], behaviour: hostile.Behaviour
) -> None:
    run = whole_suite_runs[behaviour.__name__]
    verdict = _one_verdict(run.done(), run.report)
    assert verdict.startswith(DOES_NOT_ANSWER), verdict
    assert "--auth-secret-file" in verdict  # what a rosauth server without the secret looks like


def test_a_run_over_its_run_timeout_stops_saying_where(tmp_path: Path) -> None:
    report, junit = tmp_path / "run.json", tmp_path / "run.xml"
    reports = ["--json", str(report), "--junit", str(junit)]
    with hostile.serving(hostile.echo) as url:  # answers, so every case waits out its expects
        done = subprocess.run(
            [*RWT_CONFORMANCE, url, "--timeout", "0.5", "--run-timeout", "5", *reports],
            env=ENV,
            capture_output=True,
            text=True,
            timeout=RUN_LIMIT_S,
            check=False,
        )
    assert done.returncode == 2, done.stdout[-3000:] + done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert "the run took longer than 5 s (--run-timeout): stopped " in line, line
    document = json.loads(report.read_text("utf-8"))
    assert line == f"rwt conformance: {document['verdict']}"
    ran = {case["id"] for r in document["requirements"] for case in r["cases"]}
    assert len(ran) < len(SUITE.cases)
    assert 'errors="1"' in junit.read_text("utf-8")


@pytest.mark.anyio
async def test_a_server_that_stops_answering_mid_run_stops_the_run() -> None:
    # its first connection (the runner's check before the cases) is answered, no later one
    with hostile.serving(hostile.answers_first(1)) as url:
        result = await _run(url, dialect=Dialect.ROS2)
    assert [c.case.id for c in result.cases] == [TWO_CASES[0]]  # the second never ran
    assert result.cases[0].unanswered
    assert result.verdict is not None
    assert result.verdict.startswith(
        f"the run stopped after case {TWO_CASES[0]}: the server does not answer"
    ), result.verdict
    assert not result.ok


def test_deep_json_fails_the_case_without_a_crash(tmp_path: Path) -> None:
    report = tmp_path / "run.json"
    with hostile.serving(hostile.deep_json) as url:
        done = _rwt_conformance(url, report=report)
    details = _assert_reported(done, report)
    assert all(NESTING_PROBLEM in d for d in details.values()), details


def test_garbage_and_lone_surrogates_are_reported(tmp_path: Path) -> None:
    report = tmp_path / "run.json"
    with hostile.serving(hostile.garbage) as url:
        done = _rwt_conformance(url, "--junit", str(tmp_path / "run.xml"), report=report)
    details = _assert_reported(done, report)
    assert "std_msgs/Header has fields '\\ud800', '\\x00'" in done.stdout
    # the CBOR nested 1000 deep is the first frame the runner cannot judge
    assert all(NESTING_PROBLEM in d for d in details.values()), details
    assert (tmp_path / "run.xml").read_text("utf-8").count("<testcase") > 0


async def _run(url: str, expect_timeout_s: float = 1.0, **options: Any) -> SuiteResult:
    with anyio.fail_after(RUN_LIMIT_S):
        return await run_suite(
            SUITE, RunOptions(url, only=TWO_CASES, expect_timeout_s=expect_timeout_s, **options)
        )


def _details(result: SuiteResult) -> dict[str, str]:
    assert [c.case.id for c in result.cases] == list(TWO_CASES)  # the run went on
    assert {c.outcome for c in result.cases} == {Outcome.FAILED}
    assert not any("runner error" in c.detail for c in result.cases)
    return {c.case.id: c.detail for c in result.cases}


@pytest.mark.anyio
async def test_frames_over_the_cap_close_the_connection() -> None:
    with hostile.serving(hostile.huge_frames(2 * hostile.MiB)) as url:
        result = await _run(url, max_frame_bytes=hostile.MiB)
    details = _details(result)
    assert all("closed by the client (1009" in d for d in details.values()), details


@pytest.mark.anyio
async def test_63_mib_frames_are_refused_at_the_default_cap() -> None:
    with hostile.serving(hostile.huge_frames(63 * hostile.MiB)) as url:
        # the case waits long enough for the frame: on a loaded machine sending 63 MiB
        # can take longer than the usual 1 s, and then the case fails for its silence
        result = await _run(url, expect_timeout_s=15.0)
    details = _details(result)
    assert all("closed by the client (1009" in d for d in details.values()), details


@pytest.mark.anyio
async def test_frames_a_case_does_not_consume_are_bounded_by_its_budget() -> None:
    budget = 4 * hostile.MiB
    assert budget < CASE_BUDGET_BYTES
    with hostile.serving(hostile.huge_frames(256 * 1024)) as url:
        result = await _run(url, case_budget_bytes=budget)
    details = _details(result)
    assert all(f"more than {budget} bytes" in d for d in details.values()), details


@pytest.mark.anyio
async def test_a_server_closing_mid_case_fails_that_case_with_its_reason() -> None:
    with hostile.serving(hostile.closes_after(2, 1011, "bye")) as url:
        result = await _run(url)
    details = _details(result)
    assert all("closed by the server (1011 bye)" in d for d in details.values()), details


@pytest.mark.anyio
async def test_a_frame_sent_with_the_handshake_answer_is_the_first_received() -> None:
    greeting = '{"op": "status", "level": "info", "msg": "hello"}'
    with hostile.serving_raw(hostile.greets_with(greeting)) as url:
        conn = await connect(url, timeout_s=5)
        try:
            with anyio.fail_after(5):
                assert await conn.receive() == greeting
        finally:
            await conn.aclose()


@pytest.mark.anyio
async def test_a_frame_over_the_cap_with_the_handshake_answer_fails_the_case() -> None:
    with hostile.serving_raw(hostile.greets_with(b"\x00" * (2 * hostile.MiB))) as url:
        result = await _run(url, max_frame_bytes=hostile.MiB)
    details = _details(result)
    assert all("closed by the client (1009" in d for d in details.values()), details
