"""What ``rwt serve`` checks before it starts, and how the CLI words its errors.

Each check refuses a bad option value at start, naming the option, instead of
letting it surface later as a traceback or as a server that silently matches
nothing. Errors are one line on stderr: ``rwt serve: --port: ...``.
"""

from __future__ import annotations

import os
import ssl
import sys
from pathlib import Path
from typing import Any, Protocol, cast

import typer

__all__ = [
    "ClickException",
    "NoArgsIsHelpError",
    "OptionError",
    "check_directories",
    "check_glob_list",
    "check_readable_file",
    "check_tls",
    "error_line",
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
    from rwt_protocol.server.access import parse_glob_list  # noqa: PLC0415

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
