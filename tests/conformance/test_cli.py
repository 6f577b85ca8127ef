"""``rwt conformance`` against ``rwt serve`` (as CI runs it), as subprocesses."""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from rwt_conformance.runner import NEEDS_SECRET
from tests.support.cli import RWT, run_rwt

SRC = str(Path(__file__).resolve().parents[2] / "src")
ENV = {**os.environ, "PYTHONPATH": SRC}


_SERVE = [*RWT, "serve"]
RUN_LIMIT_S = 120  # a whole suite on a loaded machine: only a hang reaches it


APPLIES = 'profiles = "strict"\ndialects = ["ros1", "ros2"]\n'
SECRET = "conformance-secret-\u00e9"
AUTH_REQUIREMENTS = {"D23", "spec1.auth.required"}
OFF_VERSION = "holds for the unversioned spec (before 2.0.0); the server is judged by spec "


def _serve(*args: str) -> tuple[subprocess.Popen[str], dict[str, str]]:
    """``rwt serve`` on free ports (WebSocket and TCP); returns it and its URLs by scheme."""
    process = subprocess.Popen(
        [*_SERVE, "--port", "0", "--tcp-port", "0", "--log-level", "error", *args],
        env=ENV,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    urls: dict[str, str] = {}
    for _ in range(2):
        line = process.stdout.readline()
        assert line.startswith("listening on "), line
        url = line.removeprefix("listening on ").strip()
        urls[url.split("://")[0]] = url
    return process, urls


@pytest.fixture(scope="module")
def secret_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("auth") / "secret"
    path.write_text(SECRET + "\nsecond line ignored\n", encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def servers(secret_file: Path) -> Iterator[dict[str, dict[str, str]]]:
    """Two ``rwt serve`` subprocesses: ``open`` and ``secured`` (--auth-secret-file)."""
    plain, plain_urls = _serve()
    try:
        secured, secured_urls = _serve("--auth-secret-file", str(secret_file))
        try:
            yield {"open": plain_urls, "secured": secured_urls}
        finally:
            _stop(secured)
    finally:
        _stop(plain)


def _stop(process: subprocess.Popen[str]) -> None:
    process.terminate()
    process.wait(timeout=10)
    if process.stdout is not None:
        process.stdout.close()


@pytest.fixture(scope="module")
def served_url(servers: dict[str, dict[str, str]]) -> str:
    return servers["open"]["ws"]


@pytest.mark.parametrize("transport", ["ws", "tcp"])
@pytest.mark.parametrize("server", ["open", "secured"])
def test_strict_profile_passes_completely(
    servers: dict[str, dict[str, str]],
    secret_file: Path,
    tmp_path: Path,
    transport: str,
    server: str,
) -> None:
    """Every requirement passes over both transports; only the auth ones need a secret."""
    report = tmp_path / "report.json"
    junit = tmp_path / "junit.xml"
    auth = ["--auth-secret-file", str(secret_file)] if server == "secured" else []
    url = servers[server][transport]
    run = run_rwt(
        "conformance", url, *auth, "--json", str(report), "--junit", str(junit), timeout=RUN_LIMIT_S
    )
    assert run.returncode == 0, run.stdout[-3000:]
    document = json.loads(report.read_text())
    summary = document["summary"]
    assert summary["failed"] == 0
    skipped = {r["id"]: r["detail"] for r in document["requirements"] if r["result"] == "skipped"}
    # judged by protocol 2.1.0, from its GET /version, or over TCP, with no HTTP, from a
    # probe (its publish with type advertises, and one with a malformed qos is refused);
    # the unversioned spec's rule is left out
    spec = document["spec_version"]
    version, source = "2.1.0", "version-endpoint" if transport == "ws" else "probe"
    assert (spec["version"], spec["source"]) == (version, source)
    assert run.stdout.splitlines()[1].startswith(f"spec version {version} (from ")
    off_version = {"spec.publish.type-ignored": OFF_VERSION + version}
    if server == "secured":
        assert skipped == off_version
    else:  # skipped by design: an open server cannot show what a secured one does
        assert skipped == dict.fromkeys(AUTH_REQUIREMENTS, NEEDS_SECRET) | off_version
    assert summary["passed"] == len(document["requirements"]) - len(skipped) >= 190 - 2
    last = run.stdout.strip().splitlines()[-1]
    assert last.startswith(f"{summary['passed']} passed, 0 failed, {len(skipped)} skipped")
    assert "D26" in run.stdout and "spec 3.3.3" in run.stdout
    assert 'failures="0"' in junit.read_text()


def test_an_unusable_secret_file_is_refused(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.write_text("\n")
    run = run_rwt(
        "conformance", "ws://127.0.0.1:1", "--auth-secret-file", str(empty), timeout=RUN_LIMIT_S
    )
    assert run.returncode == 2
    assert "first line is empty" in run.stderr


def test_a_failing_requirement_makes_the_exit_code_non_zero(
    served_url: str, tmp_path: Path
) -> None:
    suite = tmp_path / "suite"
    (suite / "cases").mkdir(parents=True)
    (suite / "requirements.toml").write_text(
        '[[requirement]]\nid = "wrong"\nsource = "spec 3.3.3"\nstatement = "fails on purpose"\n'
    )
    (suite / "cases" / "c.toml").write_text(
        '[[case]]\nid = "c"\nrequirements = ["wrong"]\n' + APPLIES + "steps = [\n"
        ' { send = { op = "subscribe", topic = "/client_count", type = "std_msgs/Int32" } },\n'
        ' { expect = { op = "publish", msg = { data = -1 } }, timeout_s = 0.3 },\n]\n'
    )
    run = run_rwt("conformance", served_url, "--suite", str(suite), timeout=RUN_LIMIT_S)
    assert run.returncode == 1
    assert "0 passed, 1 failed, 0 skipped" in run.stdout
    assert "$.msg.data: expected -1" in run.stdout


def test_only_selects_requirements(served_url: str) -> None:
    run = run_rwt(
        "conformance", served_url, "--only", "D26", "--only", "spec.publish.*", timeout=RUN_LIMIT_S
    )
    assert run.returncode == 0
    assert "D26" in run.stdout and "D13" not in run.stdout


def test_a_url_of_another_scheme_is_one_line_naming_the_forms_taken() -> None:
    run = run_rwt("conformance", "http://127.0.0.1:9090", timeout=RUN_LIMIT_S)
    assert (run.returncode, run.stdout) == (2, "")
    assert run.stderr == (
        "rwt conformance: unsupported URL scheme 'http' in 'http://127.0.0.1:9090':"
        " use ws://, wss://, tcp:// or tcp+tls://HOST:PORT, webrtc+http://HOST:PORT/webrtc,"
        " or HOST:PORT\n"
    )


def test_host_and_port_means_websocket(served_url: str) -> None:
    """As for ``rwt record`` and the client: one parser (rwt_client.connectors.server_url)."""
    bare = served_url.removeprefix("ws://")
    run = run_rwt("conformance", bare, "--only", "D26", timeout=RUN_LIMIT_S)
    assert run.returncode == 0, run.stderr
    assert f"{served_url} (strict)" in run.stdout  # the table's title
    assert "1 passed, 0 failed, 0 skipped" in run.stdout


def test_compat_rosbridge_2_1_passes_judged_by_the_unversioned_spec(tmp_path: Path) -> None:
    """No GET /version there (rosbridge_suite 2.1.0 has none): the probe finds the old rule."""
    process, urls = _serve("--compat", "rosbridge-2.1")
    try:
        report = tmp_path / "report.json"
        run = run_rwt(
            "conformance",
            urls["ws"],
            "--profile",
            "reference",
            "--json",
            str(report),
            timeout=RUN_LIMIT_S,
        )
    finally:
        _stop(process)
    assert run.returncode == 0, run.stdout[-3000:]
    document = json.loads(report.read_text())
    spec = document["spec_version"]
    assert (spec["version"], spec["source"]) == ("unversioned", "probe")
    assert "it was refused" in spec["detail"]
    assert "GET /version: answered status 404" in spec["detail"]
    assert "spec version unversioned (from a probe: it was refused" in run.stdout
    [d48] = [r for r in document["requirements"] if r["id"] == "D48"]
    assert d48["result"] == "skipped"
    assert d48["detail"] == (
        "holds for spec 2.0.0 and later; the server is judged by the unversioned spec"
    )


def test_spec_version_is_checked_and_given(served_url: str) -> None:
    bad = run_rwt("conformance", served_url, "--spec-version", "2", timeout=RUN_LIMIT_S)
    assert bad.returncode == 2
    assert "not a spec version: '2' (X.Y, X.Y.Z or 'unversioned')" in bad.stderr
    run = run_rwt(
        "conformance", served_url, "--only", "D26", "--spec-version", "2.0", timeout=RUN_LIMIT_S
    )
    assert run.returncode == 0, run.stdout
    assert "spec version 2.0.0 (given with --spec-version)" in run.stdout
