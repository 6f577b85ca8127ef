"""``rwt conformance`` against ``rwt serve`` (the CI run of issue 6), as subprocesses."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from rwt_transports.conformance.cli import TransportName, server_url

SRC = str(Path(__file__).resolve().parents[2] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC}


_SERVE = [sys.executable, "-m", "rwt_transports", "serve"]


def _rwt(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "rwt_transports", *args],
        env=ENV,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


@pytest.fixture(scope="module")
def served_url() -> Iterator[str]:
    """``rwt serve --port 0`` in a subprocess; yields its ws:// URL."""
    process = subprocess.Popen(
        [*_SERVE, "--port", "0", "--log-level", "warning"],
        env=ENV,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    line = process.stdout.readline()
    assert line.startswith("listening on "), line
    try:
        yield line.removeprefix("listening on ").strip()
    finally:
        process.terminate()
        process.wait(timeout=10)


def test_strict_profile_over_websocket_passes_completely(served_url: str, tmp_path: Path) -> None:
    report = tmp_path / "report.json"
    junit = tmp_path / "junit.xml"
    run = _rwt("conformance", served_url, "--json", str(report), "--junit", str(junit))
    assert run.returncode == 0, run.stdout[-3000:]
    summary = json.loads(report.read_text())["summary"]
    assert summary["failed"] == 0
    assert summary["passed"] >= 100
    last = run.stdout.strip().splitlines()[-1]
    assert last.startswith(f"{summary['passed']} passed, 0 failed, {summary['skipped']} skipped")
    assert "D26" in run.stdout and "spec 3.3.3" in run.stdout
    assert 'failures="0"' in junit.read_text()


def test_a_failing_requirement_makes_the_exit_code_non_zero(
    served_url: str, tmp_path: Path
) -> None:
    suite = tmp_path / "suite"
    (suite / "cases").mkdir(parents=True)
    (suite / "requirements.toml").write_text(
        '[[requirement]]\nid = "wrong"\nsource = "spec 3.3.3"\nstatement = "fails on purpose"\n'
    )
    (suite / "cases" / "c.toml").write_text(
        '[[case]]\nid = "c"\nrequirements = ["wrong"]\nsteps = [\n'
        ' { send = { op = "subscribe", topic = "/client_count", type = "std_msgs/Int32" } },\n'
        ' { expect = { op = "publish", msg = { data = -1 } }, timeout_s = 0.3 },\n]\n'
    )
    run = _rwt("conformance", served_url, "--suite", str(suite))
    assert run.returncode == 1
    assert "0 passed, 1 failed, 0 skipped" in run.stdout
    assert "$.msg.data: expected -1" in run.stdout


def test_only_selects_requirements(served_url: str) -> None:
    run = _rwt("conformance", served_url, "--only", "D26", "--only", "spec.publish.*")
    assert run.returncode == 0
    assert "D26" in run.stdout and "D13" not in run.stdout


def test_strict_profile_over_tcp_passes_completely() -> None:
    process = subprocess.Popen(
        [*_SERVE, "--no-websocket", "--tcp-port", "0", "--log-level", "warning"],
        env=ENV,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    try:
        line = process.stdout.readline()
        assert line.startswith("listening on tcp://"), line
        run = _rwt("conformance", line.removeprefix("listening on ").strip())
        assert run.returncode == 0, run.stdout[-3000:]
        assert " 0 failed" in run.stdout.strip().splitlines()[-1]
    finally:
        process.terminate()
        process.wait(10)


def test_server_url_spelling() -> None:
    assert server_url("127.0.0.1:9090", None) == "ws://127.0.0.1:9090"
    assert server_url("127.0.0.1:9090", TransportName.TCP) == "tcp://127.0.0.1:9090"
    assert server_url("ws://h:1/path", TransportName.TCP) == "tcp://h:1"
    assert server_url("tcp://h:1", TransportName.WS) == "ws://h:1"
    assert server_url("wss://h:1", None) == "wss://h:1"
