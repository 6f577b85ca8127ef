"""The CLI reference page (docs/cli.md), generated from the ``rwt`` command itself.

``python -m rwt_cli.reference > docs/cli.md`` writes it; a test
regenerates it and compares, so the page cannot go stale.
"""

from __future__ import annotations

import inspect
from typing import Any

import typer.main

from .app import app
from .groups import option_panels

__all__ = ["render"]

_HEADER = """\
# CLI reference

Generated from the `rwt` command (`python -m rwt_cli.reference >
docs/cli.md`); `rwt COMMAND --help` prints the same. [server.md](server.md) explains
the server's behaviour and [limits.md](limits.md) every cap.
"""


def render() -> str:
    """The whole reference as Markdown: each command's usage, help and options.

    Returns:
        The page text, ending with a newline.
    """
    root = typer.main.get_command(app)
    parts = [_HEADER, _command("rwt", root)]
    _subcommands("rwt", root, parts)
    return "\n".join(parts)


def _subcommands(prefix: str, group: Any, parts: list[str]) -> None:
    """Each command of ``group``, sorted, and those of its groups (``rwt bag info``)."""
    if not hasattr(group, "list_commands"):
        return
    context = _context(group)
    for name in sorted(group.list_commands(context)):
        command = group.get_command(context, name)  # rwt's commands load when asked for
        parts.append(_command(f"{prefix} {name}", command))
        _subcommands(f"{prefix} {name}", command, parts)


def _command(name: str, command: Any) -> str:
    usage = " ".join(command.collect_usage_pieces(_context(command)))
    lines = [f"## `{name}`", "", "```text", f"{name} {usage}".rstrip(), "```", ""]
    if command.help:
        lines += [inspect.cleandoc(command.help), ""]
    panels = option_panels(command)
    for panel, options in panels.items():
        if len(panels) > 1:  # rwt serve: a table a group of options, as --help shows them
            lines += [f"### {panel}", ""]
        lines += ["| option | default | meaning |", "|---|---|---|"]
        lines += [_row(option) for option in options]
        lines.append("")
    return "\n".join(lines)


def _context(command: Any) -> Any:
    return command.context_class(command, info_name=command.name)


def _row(option: Any) -> str:
    names = ", ".join(f"`{n}`" for n in [*option.opts, *option.secondary_opts])
    if getattr(option, "metavar", None) and not option.is_flag:
        names += f" `{option.metavar}`"
    default = option.default
    if option.is_flag and option.secondary_opts:
        shown = option.opts[0] if default else option.secondary_opts[0]
    elif option.is_flag or default is None or default == () or not option.show_default:
        shown = ""
    else:
        shown = str(default.value if hasattr(default, "value") else default)
    help_text = " ".join((option.help or "").split()).replace("|", "\\|")
    return f"| {names} | {f'`{shown}`' if shown else ''} | {help_text} |"


if __name__ == "__main__":
    print(render(), end="")  # noqa: T201 - the page goes to stdout
