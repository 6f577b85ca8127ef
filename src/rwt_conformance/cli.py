"""``rwt conformance URL``: check a rosbridge server against the suite."""

from __future__ import annotations

import ssl
import sys
from enum import StrEnum
from functools import partial
from pathlib import Path
from typing import Annotated

import anyio
import typer

from rwt_protocol.auth import RosauthVerifier
from rwt_protocol.errors import ConfigError

from .bounds import CASE_BUDGET_BYTES, CASE_TIMEOUT_S, MAX_FRAME_BYTES, RUN_TIMEOUT_S
from .model import Dialect, Profile, SuiteError, default_suite_dir, load_suite
from .pace import RETRY_BUDGET_S
from .versions import UNVERSIONED, SpecVersion

__all__ = ["conformance"]


class TransportName(StrEnum):
    """Transports the runner can use."""

    WS = "ws"
    TCP = "tcp"


def _server_url(url: str, transport: TransportName | None) -> str:
    """The URL to connect to, read as every command reads a server (``server_url``).

    ``HOST:PORT`` gets a scheme; ``--transport`` replaces one (``wss://`` becomes
    ``tcp+tls://`` and back).

    Raises:
        typer.Exit: code 2, after one line naming the forms taken.
    """
    # the client loads with the runner, not with the CLI (see ``conformance``)
    from rwt_client.connectors import server_url  # noqa: PLC0415

    try:
        return server_url(url, None if transport is None else transport.value)
    except ConfigError as exc:
        typer.echo(f"rwt conformance: {exc}", err=True)
        raise typer.Exit(2) from None


def _read_secret(path: Path) -> str:
    """The rosauth secret in ``path`` (its first line, read as ``rwt serve`` reads it, D23)."""
    try:
        return RosauthVerifier.from_file(path.read_text("utf-8")).secret
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        typer.echo(f"rwt conformance: cannot use --auth-secret-file: {exc}", err=True)
        raise typer.Exit(2) from None


def _tls_context(cafile: Path | None, insecure: bool) -> ssl.SSLContext | None:
    """The TLS settings for ``wss://`` and ``tcp+tls://`` servers; None: the system's."""
    if insecure:
        typer.echo("rwt conformance: --insecure: the server's certificate is not checked", err=True)
        context = ssl.create_default_context()
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE
        return context
    if cafile is None:
        return None
    try:
        return ssl.create_default_context(cafile=str(cafile))
    except (OSError, ValueError) as exc:  # ssl.SSLError is an OSError
        typer.echo(f"rwt conformance: --cafile: cannot use {cafile}: {exc}", err=True)
        raise typer.Exit(2) from None


# The options of `rwt conformance`, one alias each, so the command reads as its steps.
_Url = Annotated[
    str,
    typer.Argument(
        help="Server: ws://, wss://, tcp:// or tcp+tls://HOST:PORT,"
        " webrtc+http://HOST:PORT/webrtc, or HOST:PORT."
    ),
]
_Transport = Annotated[
    TransportName | None, typer.Option(help="Transport (default: from the URL's scheme).")
]
_Profile = Annotated[
    Profile,
    typer.Option(help="strict: rwt's decisions; reference: rosbridge_suite's behaviour."),
]
_Dialect = Annotated[
    Dialect | None,
    typer.Option(
        help="The server's ROS edition (times, type names, rosapi fields);"
        " default: ask the server (/rosapi/get_ros_version, std_msgs/Header)."
    ),
]
_Only = Annotated[
    list[str] | None,
    typer.Option(help="Run only these requirement or case ids (patterns like 'D1*'); repeatable."),
]
_Junit = Annotated[Path | None, typer.Option(help="Write JUnit XML here.")]
_JsonFile = Annotated[Path | None, typer.Option("--json", help="Write a JSON report here.")]
_Suite = Annotated[Path | None, typer.Option(help="Suite folder (default: the shipped suite).")]
_Timeout = Annotated[
    float,
    typer.Option(
        help="Seconds one expected frame, or one send, may take from a server that answers"
        " at once; the server's measured round trip is added."
    ),
]
_CaseTimeout = Annotated[
    float,
    typer.Option(min=0.001, help="Seconds one whole case may take (the round trip added too)."),
]
_RetryBudget = Annotated[
    float,
    typer.Option(
        min=0,
        help="Seconds the run may spend running again, with longer waits, cases that"
        " missed a wait (0: no retries).",
    ),
]
_RunTimeout = Annotated[
    float,
    typer.Option(
        min=0.001,
        help="Seconds the whole run may take; a longer run stops, saying where (exit 2).",
    ),
]
_MaxFrameBytes = Annotated[
    int,
    typer.Option(
        min=1, help="Largest frame taken from the server, bytes; a bigger one fails the case."
    ),
]
_CaseBudgetBytes = Annotated[
    int,
    typer.Option(
        min=1,
        help="Bytes of received frames one case may hold unconsumed; more fails the case.",
    ),
]
_AuthSecretFile = Annotated[
    Path | None,
    typer.Option(
        help="The server's rosauth secret (first line, as `rwt serve --auth-secret-file`):"
        " every connection authenticates first, and the auth cases run."
    ),
]
_Cafile = Annotated[
    Path | None,
    typer.Option(
        metavar="FILE",
        help="Trust the certificate authorities in this PEM file (wss://, tcp+tls://).",
    ),
]


def _spec_version(text: str | None) -> SpecVersion | None:
    """``--spec-version``'s value, read (``SpecVersion.parse``)."""
    if text is None:
        return None
    try:
        return SpecVersion.parse(text)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None


_SpecVersion = Annotated[
    SpecVersion | None,
    typer.Option(
        metavar="VERSION",
        parser=_spec_version,
        help=f"Judge the server by this spec version: X.Y, X.Y.Z or '{UNVERSIONED}' (the text"
        " before 2.0.0); requirements outside it are skipped. Default: the server's"
        " GET /version, else a probe.",
    ),
]
_Insecure = Annotated[
    bool, typer.Option("--insecure", help="Do not check the server's TLS certificate.")
]


def conformance(
    url: _Url,
    transport: _Transport = None,
    profile: _Profile = Profile.STRICT,
    dialect: _Dialect = None,
    only: _Only = None,
    junit: _Junit = None,
    json_file: _JsonFile = None,
    suite: _Suite = None,
    timeout: _Timeout = 3.0,
    case_timeout: _CaseTimeout = CASE_TIMEOUT_S,
    run_timeout: _RunTimeout = RUN_TIMEOUT_S,
    retry_budget: _RetryBudget = RETRY_BUDGET_S,
    max_frame_bytes: _MaxFrameBytes = MAX_FRAME_BYTES,
    case_budget_bytes: _CaseBudgetBytes = CASE_BUDGET_BYTES,
    auth_secret_file: _AuthSecretFile = None,
    cafile: _Cafile = None,
    insecure: _Insecure = False,
    spec_version: _SpecVersion = None,
) -> None:
    """Check a rosbridge server against the conformance suite; exit 1 on any failure.

    Exit 2 when the server cannot be judged: unreachable, not reading or not
    answering at all (one line on stderr), or the run over --run-timeout.
    """
    # Imported here: `rwt serve` registers this command, and must not pay for the
    # runner, its clients and rich at start (benchmarks B11 base memory).
    from rich.console import Console  # noqa: PLC0415

    from .report import print_table, write_json, write_junit  # noqa: PLC0415
    from .runner import RunOptions, run_suite  # noqa: PLC0415

    console = Console() if sys.stdout.isatty() else Console(width=160)
    server = _server_url(url, transport)
    try:
        loaded = load_suite(suite or default_suite_dir())
    except SuiteError as exc:
        typer.echo(f"rwt conformance: {exc}", err=True)
        raise typer.Exit(2) from None
    patterns = tuple(p for item in only or () for p in item.split(",") if p)
    context = _tls_context(cafile, insecure)
    options = RunOptions(
        server,
        profile,
        patterns,
        expect_timeout_s=timeout,
        case_timeout_s=case_timeout,
        run_timeout_s=run_timeout,
        retry_budget_s=retry_budget,
        max_frame_bytes=max_frame_bytes,
        case_budget_bytes=case_budget_bytes,
        auth_secret=None if auth_secret_file is None else _read_secret(auth_secret_file),
        ssl_context=context,
        dialect=dialect,
        spec_version=spec_version,
    )

    def found(spoken: Dialect, how: str) -> None:
        console.print(f"dialect: {spoken.value} ({how})")

    result = anyio.run(partial(run_suite, loaded, options, on_dialect=found))
    if result.cases or result.verdict is None:  # a server never judged gets no table
        if dialect is not None:
            found(dialect, "--dialect")
        print_table(result, console)
    if junit is not None:
        write_junit(result, junit)
    if json_file is not None:
        write_json(result, json_file)
    if result.verdict is not None:  # one line, not a table of failures
        typer.echo(f"rwt conformance: {result.verdict}", err=True)
        raise typer.Exit(2)
    if not result.ok:
        raise typer.Exit(1)
