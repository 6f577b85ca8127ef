"""``rwt conformance`` over TLS: wss:// and tcp+tls:// against ``rwt serve --certfile``."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import trustme

from rwt_client.connectors import server_url
from tests.support.cli import run_rwt

from .test_cli import RUN_LIMIT_S, _serve, _stop


@pytest.fixture(scope="module")
def authority(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """A private CA (not trusted by the system) and a certificate for 127.0.0.1."""
    folder = tmp_path_factory.mktemp("tls")
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1")
    cafile, certfile, keyfile = folder / "ca.pem", folder / "cert.pem", folder / "key.pem"
    ca.cert_pem.write_to_path(str(cafile))
    cert.cert_chain_pems[0].write_to_path(str(certfile))
    cert.private_key_pem.write_to_path(str(keyfile))
    return cafile, certfile, keyfile


@pytest.fixture(scope="module")
def urls(authority: tuple[Path, Path, Path]) -> Iterator[dict[str, str]]:
    _, certfile, keyfile = authority
    process, found = _serve("--certfile", str(certfile), "--keyfile", str(keyfile))
    try:
        assert set(found) == {"wss", "tcp+tls"}
        yield found
    finally:
        _stop(process)


# over wss:// the whole strict suite below passes with the same --cafile (exit code 0,
# no SSLError): a spec.* run there would check nothing more
@pytest.mark.parametrize("scheme", ["tcp+tls"])
def test_a_trusted_authority_passes(
    urls: dict[str, str], authority: tuple[Path, Path, Path], scheme: str
) -> None:
    run = run_rwt(
        "conformance",
        urls[scheme],
        "--cafile",
        str(authority[0]),
        "--only",
        "spec.*",
        timeout=RUN_LIMIT_S,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    assert " 0 failed" in run.stdout
    assert "SSLError" not in run.stdout + run.stderr


def test_the_whole_strict_suite_over_wss_closes_cleanly(
    urls: dict[str, str], authority: tuple[Path, Path, Path]
) -> None:
    """Hundreds of TLS connections opened and closed: none may end in an SSL error."""
    run = run_rwt("conformance", urls["wss"], "--cafile", str(authority[0]), timeout=RUN_LIMIT_S)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    assert "Traceback" not in run.stderr and "SSLError" not in run.stdout + run.stderr
    # GET /version over https, trusting the same --cafile (docs/conformance.md, "Spec versions")
    assert "spec version 2.1.0 (from GET /version)" in run.stdout


@pytest.mark.parametrize("scheme", ["wss", "tcp+tls"])
def test_an_untrusted_certificate_is_one_clear_line(urls: dict[str, str], scheme: str) -> None:
    run = run_rwt("conformance", urls[scheme], timeout=RUN_LIMIT_S)
    assert run.returncode == 2
    [line] = run.stderr.strip().splitlines()
    assert "CERTIFICATE_VERIFY_FAILED" in line and "--cafile" in line and "--insecure" in line
    assert run.stdout == ""


def test_insecure_skips_the_check_and_says_so(urls: dict[str, str]) -> None:
    run = run_rwt(
        "conformance", urls["tcp+tls"], "--insecure", "--only", "spec.publish*", timeout=RUN_LIMIT_S
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    assert "not checked" in run.stderr


def test_a_bad_cafile_is_a_usage_error(urls: dict[str, str], tmp_path: Path) -> None:
    bogus = tmp_path / "bogus.pem"
    bogus.write_text("not a certificate\n")
    for cafile in (bogus, tmp_path / "missing.pem"):
        run = run_rwt("conformance", urls["wss"], "--cafile", str(cafile), timeout=RUN_LIMIT_S)
        assert run.returncode == 2
        assert "--cafile" in run.stderr and "Traceback" not in run.stderr


def test_an_unreachable_server_is_one_line_not_every_case_failing() -> None:
    run = run_rwt("conformance", "ws://127.0.0.1:9", "--timeout", "1", timeout=RUN_LIMIT_S)
    assert run.returncode == 2
    assert "cannot connect" in run.stderr and run.stdout == ""


def test_transport_switch_keeps_tls() -> None:
    assert server_url("wss://h:1", "tcp") == "tcp+tls://h:1"  # --transport tcp
    assert server_url("tcp+tls://h:1", "ws") == "wss://h:1"
    assert server_url("tcp+tls://h:1", "tcp") == "tcp+tls://h:1"
