"""A slow server gets the verdict of a fast one; a server that never answers still fails.

``rwt conformance`` runs against rwt's server behind a proxy that delays every frame
the server sends (``delaying``), as a loaded machine or a far server would. Its
waits grow with the round trip it measures, a case that misses a wait is run again
with longer waits, and the cases that passed late are reported slow (``pace``,
docs/conformance.md, "Slow servers and loaded machines"). A server that never
answers an op fails that case after its retry.
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import anyio
import pytest

from rwt_conformance.pace import RETRY_FACTOR, Pace, RoundTrips
from rwt_transports.server import RosbridgeServer, ServerConfig
from tests.conformance.delaying import delaying
from tests.support.cli import ENV, RWT

pytestmark = pytest.mark.anyio

RUN_LIMIT_S = 300  # a bound on a hung run, not a speed requirement
STALLED, DELAYED = "topics.publish-example", "topics.advertise-then-infer"
EVERY_FRAME_S = 0.2
"""What the proxy adds to every frame from the server."""
WAIT_S = 1.0
"""The run's ``--timeout`` (the nominal wait; 3 s by default): the delays below are set
against it, so the run waits seconds, not tens of seconds."""
CASE_ONE_S = 1.2
"""What it adds besides to the frames of the second case (``${ns}`` ends in ``/c1``)."""


@pytest.fixture
async def server_port() -> AsyncIterator[int]:
    """An in-process rwt server's WebSocket port (the proxy runs in the same event loop)."""
    server = RosbridgeServer(config=ServerConfig(port=0))
    async with anyio.create_task_group() as tg:
        url = await tg.start(server.serve)
        yield int(url.rsplit(":", 1)[1])
        tg.cancel_scope.cancel()


async def _conformance(*args: str) -> tuple[int, str, str]:
    """``rwt conformance ARGS`` in a subprocess, while this loop serves the proxy."""
    with anyio.fail_after(RUN_LIMIT_S):
        done = await anyio.run_process(
            [*RWT, "conformance", *args], env={**ENV, "COLUMNS": "200"}, check=False
        )
    return done.returncode, done.stdout.decode(), done.stderr.decode()


def _cases(report: Path) -> dict[str, dict[str, Any]]:
    document = json.loads(report.read_text("utf-8"))
    return {c["id"]: c for r in document["requirements"] for c in r["cases"]}


def _delay(chunk: bytes) -> float:
    return EVERY_FRAME_S + (CASE_ONE_S if b"/c1" in chunk else 0.0)


async def test_a_server_slowed_by_a_proxy_passes_and_its_slow_cases_are_reported(
    server_port: int, tmp_path: Path
) -> None:
    """Every frame 0.2 s late, the second case's 1.4 s (over the run's 1 s wait), and the
    first case's first connection stalled once (a missed wait: retried)."""
    report = tmp_path / "run.json"
    async with delaying(server_port, _delay, stall=b"/c0/") as (proxy, port):
        code, stdout, stderr = await _conformance(
            f"ws://127.0.0.1:{port}",
            *("--only", STALLED, "--only", DELAYED, "--timeout", f"{WAIT_S:g}"),
            *("--json", str(report)),
        )
    assert code == 0, stdout[-3000:] + stderr
    assert proxy.stalled == 1
    cases = _cases(report)
    assert {c["result"] for c in cases.values()} == {"passed"}
    stalled = cases[STALLED]
    assert stalled["retried"] is True
    assert stalled["slow"]["first_try"].startswith("step 2 (sync on b): sync: the server did not")
    assert f"passed on its retry, every wait {RETRY_FACTOR:g}x" in stalled["slow"]["text"]
    delayed = cases[DELAYED]
    assert delayed["slow"] is not None
    assert delayed["slow"]["took_s"] > delayed["slow"]["nominal_s"] == WAIT_S
    assert f"slow: {STALLED}: passed on its retry" in stdout
    assert f"slow: {DELAYED}: " in stdout
    document = json.loads(report.read_text("utf-8"))
    assert document["slow_cases"] == 2
    timing = document["timing"]
    # the proxy's delay is in every round trip the runner measured, and in every wait
    assert timing["round_trip_s"]["first"] >= EVERY_FRAME_S
    assert timing["extra_wait_s"] >= 2 * EVERY_FRAME_S
    assert timing["retries"] == 1
    passed = document["summary"]["passed"]
    assert passed == len(document["requirements"])
    last = stdout.strip().splitlines()[-1]
    assert last.startswith(f"{passed} passed, 0 failed, 0 skipped (2 cases in "), last
    assert last.endswith("; 2 slow)"), last


NEVER_ANSWERED = """
[[case]]
id = "never-answered"
requirements = ["answers"]
profiles = "strict"
dialects = ["ros1", "ros2"]
steps = [
  { on = "b", send = { op = "advertise_service", service = "/${ns}/x", type = "std_srvs/Empty" } },
  { on = "b", sync = true },
  { send = { op = "call_service", service = "/${ns}/x", id = "call" } },
  { expect = { op = "service_response", id = "call" }, timeout_s = 0.5 },
]
"""


def _suite(folder: Path) -> Path:
    """A suite of one case: a call its provider (the case's second connection) never answers."""
    (folder / "cases").mkdir(parents=True)
    (folder / "requirements.toml").write_text(
        '[[requirement]]\nid = "answers"\nsource = "spec 3.3.6"\nstatement = "a call is answered"\n'
    )
    (folder / "cases" / "c.toml").write_text(NEVER_ANSWERED)
    return folder


async def test_an_op_never_answered_fails_after_its_retry(server_port: int, tmp_path: Path) -> None:
    report = tmp_path / "run.json"
    url = f"ws://127.0.0.1:{server_port}"
    code, stdout, stderr = await _conformance(
        url, "--suite", str(_suite(tmp_path / "suite")), "--json", str(report)
    )
    assert code == 1, stdout[-3000:] + stderr
    [case] = _cases(report).values()
    assert case["result"] == "failed" and case["retried"] is True and case["slow"] is None
    assert case["detail"].startswith("step 4 (expect on a): no frame matching")
    assert case["detail"].endswith(f"(also on its retry, every wait {RETRY_FACTOR:g}x)")
    assert json.loads(report.read_text("utf-8"))["timing"]["retries"] == 1
    assert "0 passed, 1 failed, 0 skipped" in stdout


async def test_without_a_retry_budget_a_missed_wait_fails_at_once(
    server_port: int, tmp_path: Path
) -> None:
    report = tmp_path / "run.json"
    code, _, _ = await _conformance(
        f"ws://127.0.0.1:{server_port}",
        "--suite",
        str(_suite(tmp_path / "suite")),
        "--retry-budget",
        "0",
        "--json",
        str(report),
    )
    assert code == 1
    [case] = _cases(report).values()
    assert case["retried"] is False
    assert case["detail"].endswith("(not retried: retries took their 0 s)")
    assert json.loads(report.read_text("utf-8"))["timing"]["not_retried"] == 1


def test_the_round_trip_estimate_is_rfc_6298s() -> None:
    trips = RoundTrips()
    assert Pace(trips).wait_s(3.0) == 3.0  # nothing measured: the suite's wait
    trips.add(1.0)  # the first: SRTT = R, RTTVAR = R / 2
    assert (trips.srtt_s, trips.rttvar_s, trips.rto_s) == (1.0, 0.5, 3.0)
    trips.add(3.0)  # RTTVAR = 3/4 0.5 + 1/4 |1 - 3|, SRTT = 7/8 1 + 1/8 3
    assert (trips.srtt_s, trips.rttvar_s) == (1.25, 0.875)
    assert trips.rto_s == 1.25 + 4 * 0.875
    pace = Pace(trips)
    assert pace.wait_s(3.0) == 3.0 + 2 * trips.rto_s
    assert pace.case_s(20.0, 4) == 20.0 + 4 * 2 * trips.rto_s
    assert pace.retry().wait_s(3.0) == RETRY_FACTOR * pace.wait_s(3.0)
    for _ in range(100):
        trips.add(1000.0)
    assert pace.extra_s == 30.0  # MAX_EXTRA_WAIT_S: a round trip cannot stretch waits forever
    assert (trips.samples, trips.first_s, trips.max_s) == (102, 1.0, 1000.0)
