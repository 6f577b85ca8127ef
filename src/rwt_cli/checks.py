"""What ``rwt serve`` checks before it starts, and how the CLI words its errors.

Each check refuses a bad option value at start, naming the option, instead of
letting it surface later as a traceback or as a server that silently matches
nothing. Errors are one line on stderr: ``rwt serve: --port: ...``; an error
raised while a command runs too, however deep task groups wrapped it
(``one_line_errors``).
"""

from __future__ import annotations

import contextlib
import os
import ssl
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, cast

import typer

from rwt_protocol.errors import ConfigError
from rwt_transports.webrtc.ice import parse_ice_servers
from rwt_transports.webrtc.stacks import stack_refusal

if TYPE_CHECKING:
    from collections.abc import Iterator

__all__ = [
    "ClickException",
    "NoArgsIsHelpError",
    "OptionError",
    "check_directories",
    "check_glob_list",
    "check_readable_file",
    "check_server_url",
    "check_tls",
    "error_line",
    "error_message",
    "one_line_errors",
    "usage_error",
]

# The exceptions typer raises are click's, or since typer 0.2x those of its own
# copy of click (typer._click); typer.BadParameter is one of them either way.
_click_exceptions = sys.modules[typer.BadParameter.__module__]
#: What typer raises for a usage error (exit code 2) and the like.
ClickException: type[Exception] = _click_exceptions.ClickException
#: `rwt` without arguments: its message is the help (click >= 8.2; None before).
NoArgsIsHelpError: type[Exception] | None = getattr(_click_exceptions, "NoArgsIsHelpError", None)
_UsageError: type[Exception] = _click_exceptions.UsageError
_MissingParameter: type[Exception] = _click_exceptions.MissingParameter


class _ClickError(Protocol):
    """What ``error_line`` reads of a click exception."""

    exit_code: int
    ctx: Any
    message: str

    def format_message(self) -> str: ...


class OptionError(typer.BadParameter):
    """A bad option value, worded by rwt (lowercase, no trailing period, kept as is)."""


def usage_error(message: str) -> Exception:
    """A usage error (exit code 2) of the running command, for a combination of options."""
    return _UsageError(message)


def check_readable_file(path: Path | None) -> Path | None:
    """Typer callback: ``path`` names a readable file (None passes).

    Raises:
        OptionError: ``no such file: PATH``, ``not a file: PATH`` or ``cannot read: PATH``.
    """
    if path is None:
        return None
    if not path.exists():
        raise OptionError(f"no such file: {path}")
    if not path.is_file():
        raise OptionError(f"not a file: {path}")
    if not os.access(path, os.R_OK):
        raise OptionError(f"cannot read: {path}")
    return path


def check_directories(paths: list[Path] | None) -> list[Path] | None:
    """Typer callback: every path is a directory (interface folders given by a user).

    Raises:
        OptionError: ``no such directory: PATH`` or ``not a directory: PATH``.
    """
    for path in paths or ():
        if not path.exists():
            raise OptionError(f"no such directory: {path}")
        if not path.is_dir():
            raise OptionError(f"not a directory: {path}")
    return paths


def check_ice_servers(urls: list[str] | None) -> list[str] | None:
    """Typer callback: the ``--ice-server`` URLs are ones aiortc can use, one STUN and one TURN.

    Raises:
        OptionError: the reason ``rwt_transports.webrtc.ice.parse_ice_servers`` gives.
    """
    try:
        parse_ice_servers(urls or ())
    except ValueError as exc:
        raise OptionError(str(exc)) from None
    return urls


def check_webrtc_stack(stack: str) -> str:
    """Typer callback: ``--webrtc-stack`` is one of ``webrtc.native.STACKS``, and usable here.

    Raises:
        OptionError: another name, or a stack that does not import here (``native``:
            libdatachannel-py, Python 3.12+, D51; ``reactor``: reactor-webrtc, D70;
            ``webrtc.stacks.stack_refusal`` says why).
    """
    if (refused := stack_refusal(stack)) is not None:
        raise OptionError(refused)
    return stack


def check_glob_list(text: str) -> str:
    """Typer callback: ``text`` parses, as the server parses it, into usable patterns.

    The server's parser (``parse_glob_list``) is lenient: ``[/robot/*, /tf``, a
    list missing its ``]``, becomes the patterns ``[/robot/*`` and ``/tf``, and the
    first one matches no name. So each parsed pattern is checked here: brackets
    pair up as fnmatch reads them, and no blank or quote is left inside (names
    have none; they come from a missing comma or an unbalanced quote).

    Raises:
        OptionError: naming the pattern and its problem.
    """
    # the server's access module loads its ops: rwt bag and rwt record need neither
    from rwt_protocol.runtime.access import parse_glob_list  # noqa: PLC0415

    for pattern in parse_glob_list(text):
        problem = _pattern_problem(pattern)
        if problem is not None:
            raise OptionError(
                f"{problem} in pattern {pattern!r} (write a list as /a/*,/b or [/a/*, /b])"
            )
    return text


def _pattern_problem(pattern: str) -> str | None:
    if any(c.isspace() for c in pattern):
        return "a blank"
    if "'" in pattern or '"' in pattern:
        return "a quote"
    i = 0
    while i < len(pattern):
        if pattern[i] == "]":
            return "a ']' without '['"
        if pattern[i] == "[":
            # fnmatch: a ']' right after '[' or '[!' is a member, the next one closes
            start = i + 1
            if pattern.startswith("!", start):
                start += 1
            close = pattern.find("]", start + 1)
            if close < 0:
                return "an unclosed '['"
            i = close
        i += 1
    return None


def check_tls(certfile: Path | None, keyfile: Path | None) -> None:
    """The certificate and key load as the server will load them.

    Raises:
        UsageError: ``--keyfile`` without ``--certfile``.
        OptionError: the files are not a PEM certificate and its key.
    """
    if certfile is None:
        if keyfile is not None:
            raise usage_error("--keyfile needs --certfile")
        return
    try:
        ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(certfile, keyfile)
    except (ssl.SSLError, OSError, ValueError) as exc:
        with_key = f" with --keyfile {keyfile}" if keyfile is not None else ""
        raise OptionError(
            f"cannot load {certfile}{with_key}: {exc}", param_hint="--certfile"
        ) from None


def error_line(exc: Exception) -> str:
    """A click exception as one line: ``rwt serve: --port: 99999 is not in the range ...``."""
    error = cast(_ClickError, exc)
    where = getattr(error.ctx, "command_path", None) or "rwt"
    if isinstance(exc, typer.BadParameter) and not isinstance(exc, _MissingParameter):
        message = exc.message if isinstance(exc, OptionError) else _plain(exc.message)
        name = _param_name(exc)
        if name:
            message = f"{name}: {message}"
    elif isinstance(exc, _UsageError):
        message = _plain(error.format_message())
    else:
        message = error.format_message()
    return f"{where}: {' '.join(message.splitlines())}"


def _param_name(exc: typer.BadParameter) -> str | None:
    if isinstance(exc.param_hint, str):
        return exc.param_hint.strip("'\"")
    opts: list[str] = getattr(exc.param, "opts", None) or []
    if getattr(exc.param, "param_type_name", None) == "option" and opts:
        return opts[0]
    return getattr(exc.param, "human_readable_name", None)


def _plain(message: str) -> str:
    """Click's wording in rwt's style: lowercase first letter, no trailing period."""
    # typer >= 0.2x converts values with pydantic, whose errors may start so
    message = message.strip().removeprefix("Value error, ").removesuffix(".")
    return message[:1].lower() + message[1:]


def check_server_url(text: str) -> str:
    """Typer callback: a rosbridge server's address, as the client takes it (``server_url``).

    Every command that takes a server (``rwt record``, and ``rwt conformance``,
    which parses with ``server_url`` too) takes the same forms: ``ws://``,
    ``wss://``, ``tcp://``, ``tcp+tls://`` and ``HOST:PORT`` (WebSocket).

    Returns:
        The URL with its scheme.

    Raises:
        OptionError: another scheme, no host or no port; the text lists the forms.
    """
    # the client's connectors load with the command that connects, not with the CLI
    from rwt_client.connectors import server_url  # noqa: PLC0415

    try:
        return server_url(text)
    except ConfigError as exc:
        raise OptionError(str(exc)) from None


def error_message(exc: BaseException, expected: tuple[type[BaseException], ...]) -> str | None:
    """One line for an error a user can act on, however deep task groups wrapped it.

    anyio's task groups wrap what a task raised in an ``ExceptionGroup``, one group
    a level, whose own text (``unhandled errors in a TaskGroup (1 sub-exception)``)
    says nothing: the line is made of the errors inside, each text once, joined
    by ``; ``.

    Args:
        exc: what the command raised.
        expected: the errors a user causes (a port in use, a bag that exists...).

    Returns:
        The line; None when an error inside is none of ``expected`` (a bug, whose
        traceback the caller lets through).
    """
    if isinstance(exc, BaseExceptionGroup):
        messages: list[str] = []
        for each in exc.exceptions:
            message = error_message(each, expected)
            if message is None:
                return None
            if message not in messages:
                messages.append(message)
        return "; ".join(messages)
    return str(exc) if isinstance(exc, expected) else None


@contextlib.contextmanager
def one_line_errors(command: str, expected: tuple[type[BaseException], ...]) -> Iterator[None]:
    """Run the block; an ``expected`` error exits 1 with ``rwt COMMAND: MESSAGE`` on stderr.

    The one place where the commands that run (``serve``, ``play``, ``record``)
    turn what they raised into one line (``error_message``); anything else
    goes on as a traceback.

    Raises:
        typer.Exit: code 1, after the line.
    """
    try:
        yield
    except (Exception, BaseExceptionGroup) as exc:
        message = error_message(exc, expected)
        if message is None:
            raise
        typer.echo(f"rwt {command}: {message}", err=True)
        raise typer.Exit(1) from None
