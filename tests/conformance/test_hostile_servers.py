"""The runner against hostile servers: every run ends, with a report and an exit code.

Each server (``hostile``) attacks the runner's bounds (docs/conformance.md, "Against
a hostile server"): it never reads, answers too deeply nested JSON, sends frames
too big or too many, closes mid-case, or sends garbage. The run must fail the
cases it spoils with a clear reason, go on to the next case and end as usual.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import anyio
import pytest

from rwt_client.connectors import connect
from rwt_conformance import Outcome, RunOptions, SuiteResult, load_suite, run_suite
from rwt_conformance.bounds import CASE_BUDGET_BYTES
from rwt_conformance.frames import NESTING_PROBLEM
from tests.conformance import hostile

SRC = str(Path(__file__).resolve().parents[2] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC}
SUITE = load_suite()
TWO_CASES = ("topics.publish-example", "topics.advertise-then-infer")
RWT_CONFORMANCE = [sys.executable, "-m", "rwt", "conformance"]
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


def test_a_server_that_never_reads_and_pings_cannot_hang_the_run(tmp_path: Path) -> None:
    report = tmp_path / "run.json"
    with hostile.serving(hostile.never_reads_and_pings) as url:
        done = _rwt_conformance(url, report=report)
    details = _assert_reported(done, report)
    assert "assumed" in done.stdout  # dialect detection gave up in time
    assert all("timed out" in d or "within 1 s" in d for d in details.values()), details


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
