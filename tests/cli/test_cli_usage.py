"""What a user sees of `rwt` when an option is wrong: one line naming it, no traceback.

Usage errors exit with 2 and say which option and why (``rwt serve: --port: ...``);
an address that cannot be bound exits with 1 and names the listener and the
address. The help of every command reads cleanly at 80 columns and names no
internal document. Most cases run the real command line in a subprocess; the
many small usage cases use typer's CliRunner, which drives the same group.
"""

from __future__ import annotations

import functools
import importlib.metadata
import re
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import typer

from rwt_cli.app import app
from rwt_cli.checks import check_glob_list
from rwt_protocol.distribution import DISTRIBUTION, install_hint
from tests.support import cli
from tests.support.cli import ENV, TIMEOUT_S, invoke_rwt, run_rwt
from tests.support.realclients import REPO

SERVE = [*cli.SERVE, "--log-level", "warning"]


def invoke(*args: str) -> tuple[int, str]:
    """Run ``rwt ARGS`` in-process; its exit code and stderr."""
    result = invoke_rwt(*args)
    return result.exit_code, result.stderr


def only_line(stderr: str) -> str:
    """The one line of an error on stderr (log lines aside); fails on a traceback."""
    assert "Traceback" not in stderr, stderr
    lines = [line for line in stderr.splitlines() if line.startswith("rwt")]
    assert len(lines) == 1, stderr
    return lines[0]


# ---- addresses in use (tests/conftest.py's taken ports) ---------------------------


@pytest.mark.parametrize(
    ("listener", "option", "kind"),
    [
        ("WebSocket", "--port", "tcp"),
        ("TCP", "--tcp-port", "tcp"),
        ("UDP", "--udp-port", "udp"),
        ("HTTP video", "--video-port", "tcp"),
    ],
)
def test_an_address_in_use_names_the_listener_and_the_port(
    listener: str, option: str, kind: str, request: pytest.FixtureRequest
) -> None:
    port = request.getfixturevalue(f"taken_{kind}_port")
    args = [option, str(port)] if option == "--port" else ["--port", "0", option, str(port)]
    run = run_rwt(*args, command=SERVE)
    assert run.returncode == 1
    assert only_line(run.stderr) == (
        f"rwt serve: cannot listen for {listener} on 127.0.0.1:{port}: address already in use"
    )
    assert "listening on" not in run.stdout


def test_workers_name_the_port_in_use_as_one_server_does(taken_tcp_port: int) -> None:
    pytest.importorskip("zenoh", reason="--workers shares the graph over Zenoh")
    run = run_rwt("--workers", "2", "--port", str(taken_tcp_port), command=SERVE)
    assert run.returncode == 1
    assert only_line(run.stderr) == (
        f"rwt serve: cannot listen for WebSocket on 127.0.0.1:{taken_tcp_port}: "
        "address already in use"
    )


# ---- option values refused at start ----------------------------------------------


def test_a_usage_error_is_one_line_from_the_real_command() -> None:
    run = run_rwt("serve", "--port", "99999")
    assert run.returncode == 2
    assert only_line(run.stderr).startswith("rwt serve: --port: ")
    assert run.stderr.count("\n") == 1 and run.stdout == ""


@pytest.mark.parametrize("option", ["--certfile", "--keyfile", "--auth-secret-file"])
def test_a_missing_file_is_named(
    option: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    code, stderr = invoke("serve", option, "cert.pem")
    assert code == 2
    assert only_line(stderr) == f"rwt serve: {option}: no such file: cert.pem"


def test_a_folder_is_not_a_file(tmp_path: Path) -> None:
    code, stderr = invoke("serve", "--certfile", str(tmp_path))
    assert code == 2
    assert only_line(stderr) == f"rwt serve: --certfile: not a file: {tmp_path}"


def test_a_file_that_is_no_certificate_is_refused(tmp_path: Path) -> None:
    cert = tmp_path / "cert.pem"
    cert.write_text("not a certificate\n")
    code, stderr = invoke("serve", "--certfile", str(cert))
    assert code == 2
    assert only_line(stderr).startswith(f"rwt serve: --certfile: cannot load {cert}: ")


def test_a_key_without_a_certificate_is_refused(tmp_path: Path) -> None:
    key = tmp_path / "key.pem"
    key.write_text("")
    code, stderr = invoke("serve", "--keyfile", str(key))
    assert code == 2
    assert only_line(stderr) == "rwt serve: --keyfile needs --certfile"


def test_an_empty_secret_file_is_refused(tmp_path: Path) -> None:
    secret = tmp_path / "secret"
    secret.write_text("\n")
    code, stderr = invoke("serve", "--auth-secret-file", str(secret))
    assert code == 2
    assert only_line(stderr) == (
        f"rwt serve: --auth-secret-file: the first line of {secret} is empty"
    )


@pytest.mark.parametrize("option", ["--port", "--tcp-port", "--udp-port", "--video-port"])
@pytest.mark.parametrize("value", ["99999", "65536", "-1"])
def test_a_port_out_of_range_is_a_usage_error(option: str, value: str) -> None:
    code, stderr = invoke("serve", option, value)
    assert code == 2
    assert only_line(stderr).startswith(f"rwt serve: {option}: ")


@pytest.mark.parametrize(
    "option", ["--topics-glob", "--services-glob", "--params-glob", "--actions-glob"]
)
def test_a_malformed_glob_is_a_usage_error_naming_the_option(option: str) -> None:
    code, stderr = invoke("serve", option, "[/robot/*, /tf")
    assert code == 2
    assert only_line(stderr) == (
        f"rwt serve: {option}: an unclosed '[' in pattern '[/robot/*'"
        " (write a list as /a/*,/b or [/a/*, /b])"
    )


@pytest.mark.parametrize(
    "text",
    [
        "",
        "[]",
        "/a/*,/b",
        "[/robot/*, /tf]",
        "['/robot/*', \"/tf\"]",
        "/cam[0-9]/image",
        "[/cam[0-9]/*, /tf]",
        "/a[!b]",
        "/x[]]",
        "chatter",
    ],
)
def test_globs_the_server_understands_pass(text: str) -> None:
    assert check_glob_list(text) == text


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("[/robot/*, /tf", "an unclosed '['"),
        ("/robot/*, /tf]", "a ']' without '['"),
        ("/a/* /b", "a blank"),
        ("/cam[0-9/image", "an unclosed '['"),
        ("/a[]", "an unclosed '['"),
        ("/a'b", "a quote"),
    ],
)
def test_globs_that_would_silently_match_nothing_are_refused(text: str, problem: str) -> None:
    with pytest.raises(typer.BadParameter, match=re.escape(problem)):
        check_glob_list(text)


def test_a_missing_interfaces_folder_is_named(tmp_path: Path) -> None:
    missing = tmp_path / "interfaces"
    code, stderr = invoke("serve", "--interfaces", str(tmp_path), "--interfaces", str(missing))
    assert code == 2
    assert only_line(stderr) == f"rwt serve: --interfaces: no such directory: {missing}"
    (tmp_path / "file").write_text("")
    code, stderr = invoke("serve", "--interfaces", str(tmp_path / "file"))
    assert code == 2
    assert only_line(stderr).endswith(f"not a directory: {tmp_path / 'file'}")


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["serve", "--no-websocket"], "rwt serve: nothing to serve: --no-websocket needs"),
        (
            ["serve", "--no-websocket", "--tcp-port", "0", "--webrtc"],
            "rwt serve: --webrtc answers on the WebSocket port",
        ),
        (
            ["serve", "--no-websocket", "--tcp-port", "0", "--mcp"],
            "rwt serve: --mcp answers on the WebSocket port",
        ),
        (["serve", "--mcp-read-only"], "rwt serve: --mcp-read-only is a setting of --mcp"),
        (
            ["serve", "--mcp-authorization-server", "https://login.example.com"],
            "rwt serve: --mcp-authorization-server is a setting of --mcp",
        ),
        (
            ["serve", "--mcp", "--mcp-authorization-server", "login.example.com"],
            "rwt serve: --mcp-authorization-server: an issuer URL",
        ),
        (["serve", "--log-level", "loud"], "rwt serve: --log-level: 'loud' is not one of"),
        (["serve", "--prot", "1"], "rwt serve: no such option: --prot"),
        (["nosuch"], "rwt: no such command 'nosuch'"),
    ],
)
def test_other_usage_errors_are_one_line(args: list[str], expected: str) -> None:
    code, stderr = invoke(*args)
    assert code == 2
    assert only_line(stderr).startswith(expected)


# ---- --version, --help ------------------------------------------------------------


def test_version() -> None:
    run = run_rwt("--version")
    assert run.returncode == 0, run.stderr
    assert run.stdout == f"rwt {importlib.metadata.version(DISTRIBUTION)}\n"


#: Internal references and markup that have no place in help text.
NOT_IN_HELP = {
    "an issue number": r"\b[Ii]ssue \d+|#\d+\b",
    # a decision id such as D22 (an --only pattern like 'D1*' is an example value)
    "a decision id": r"(?<![\w'])D\d+\b(?![*?])",
    "the decisions document": r"docs/decisions.md",
    "a reference section": r"REF §|§",
    "RST markup": r"``|:\w+:`",
    "a rich box": r"[╭╰│…]",
}


def commands() -> list[list[str]]:
    """`rwt` and each of its commands, as argument lists for --help."""
    group = typer.main.get_command(app)
    assert isinstance(group, typer.core.TyperGroup)
    names = group.list_commands(group.context_class(group, info_name="rwt"))
    return [[], *([name] for name in sorted(names))]


@functools.cache
def help_of(*command: str) -> subprocess.CompletedProcess[str]:
    """``rwt COMMAND --help`` on an 80-column terminal, run once for the module's tests."""
    return run_rwt(*command, "--help", env={"COLUMNS": "80"})


@pytest.mark.parametrize("command", commands(), ids=lambda c: " ".join(["rwt", *c]))
def test_help_is_for_users_and_fits_80_columns(command: list[str]) -> None:
    run = help_of(*command)
    assert run.returncode == 0, run.stderr
    text = run.stdout
    assert text.startswith("Usage: rwt")
    for what, pattern in NOT_IN_HELP.items():
        found = re.search(pattern, text)
        assert found is None, f"{what} in `rwt {' '.join(command)} --help`: {found}"
    too_wide = [line for line in text.splitlines() if len(line) > 80]
    assert not too_wide, too_wide


def test_the_commands_are_listed() -> None:
    text = help_of().stdout
    assert re.search(r"^  conformance +\S", text, re.MULTILINE)
    assert re.search(r"^  serve +\S", text, re.MULTILINE)


# ---- --video-port, --uvloop -------------------------------------------------------


def test_video_port_implies_video() -> None:
    process = subprocess.Popen(
        [*SERVE, "--port", "0", "--video-port", "0"],
        env=ENV,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout is not None
        first = process.stdout.readline()
        second = process.stdout.readline()
    finally:
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=TIMEOUT_S)
    assert first.startswith("listening on ws://"), stderr
    assert second.startswith("video on http://127.0.0.1:"), stderr
    assert process.returncode == 0, stderr


#: rwt serve's help sections and an option of each, in the order --help shows them.
SERVE_SECTIONS = {
    "Listeners": "--tcp-port",
    "Security": "--certfile",
    "Limits": "--max-message-size",
    "Graph": "--dialect",
    "Console and media": "--video-port",
    "Record and replay": "--record-topics",
    "Scale-out (Zenoh)": "--zenoh-connect",
    "ROS 2": "--ros2-node-name",
    "Process": "--log-level",
    "Options": "--help",
}


def test_serve_help_lists_its_options_in_sections() -> None:
    text = help_of("serve").stdout
    headings = re.findall(r"^(\S[^:\n]*):$", text, re.MULTILINE)
    assert headings == list(SERVE_SECTIONS)
    bodies = re.split(r"^\S[^:\n]*:$", text, flags=re.MULTILINE)[1:]
    sections = dict(zip(headings, bodies, strict=True))
    for heading, option in SERVE_SECTIONS.items():
        assert re.search(rf"^  {option}\b", sections[heading], re.MULTILINE), heading
    assert "--reuse-port" not in text  # hidden: the workers' own option


def test_the_help_of_video_port_says_it_implies_video() -> None:
    text = " ".join(help_of("serve").stdout.split())
    assert "implies --video" in text


def test_uvloop_names_its_extra() -> None:
    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    assert any(dep.startswith("uvloop") for dep in extras["uvloop"])
    assert install_hint("uvloop") in " ".join(help_of("serve").stdout.split())


def test_uvloop_missing_is_one_line_naming_the_extra() -> None:
    # The child cannot import uvloop (a None entry in sys.modules hides a package).
    code = (
        "import runpy, sys;"
        "sys.modules['uvloop'] = None;"
        "runpy.run_module('rwt', run_name='__main__')"
    )
    run = run_rwt("serve", "--port", "0", "--uvloop", command=[sys.executable, "-c", code])
    assert run.returncode == 1
    assert only_line(run.stderr) == f"rwt serve: --uvloop needs uvloop: {install_hint('uvloop')}"
