"""The ``rwt`` typer application: its commands, ``--version``, and one-line errors."""

from __future__ import annotations

import importlib
import importlib.metadata
import sys
from collections.abc import Sequence
from typing import Annotated, Any

import typer
import typer.main
from typer.core import TyperCommand, TyperGroup

from rwt_protocol.distribution import DISTRIBUTION, install_hint

from .checks import ClickException, NoArgsIsHelpError, error_line
from .groups import GroupedCommand

__all__ = ["app", "main"]

#: Each command: the module and name of its function (or typer group), its short help
#: and its click class. A command's module is imported when the command runs or its
#: help is shown, not with the CLI: ``rwt bag info`` does not load the server, nor
#: ``rwt serve`` the conformance runner (a few tenths of a second a run).
_COMMANDS: dict[str, tuple[str, str, str, type[TyperCommand] | None]] = {
    "conformance": (
        "rwt_conformance.cli",
        "conformance",
        "Check a rosbridge server against the conformance suite.",
        None,
    ),
    "mcp": (
        "rwt_mcp.cli",
        "mcp_command",
        "Serve MCP over stdio in front of a rosbridge server, for AI agents.",
        None,
    ),
    "record": ("rwt_cli.record", "record", "Record topics of a rosbridge server into a bag.", None),
    "serve": ("rwt_cli.serve", "serve", "Run a rosbridge server.", GroupedCommand),
    "play": ("rwt_cli.play", "play", "Serve a bag's topics as a live robot.", None),
    "router": (
        "rwt_cli.router",
        "router",
        "Run a Zenoh router for rwt servers and ROS 2 nodes.",
        None,
    ),
    "bag": ("rwt_cli.bag", "bag_app", "Inspect bags.", None),
}


def _load(name: str) -> Any:
    """The click command ``name`` of ``_COMMANDS``, its module imported now."""
    module, attribute, short_help, cls = _COMMANDS[name]
    try:
        target = getattr(importlib.import_module(module), attribute)
    except ModuleNotFoundError as exc:  # as rwt._cli says when the CLI itself cannot load
        typer.echo(
            f"rwt: the command line needs the server extra ({exc.name} is missing): "
            f"python -m {install_hint('server')}",
            err=True,
        )
        sys.exit(2)
    holder = typer.Typer(rich_markup_mode=None, add_completion=False)  # as ``app``'s
    if isinstance(target, typer.Typer):
        holder.add_typer(target, name=name, short_help=short_help)
    else:
        holder.command(name, short_help=short_help, cls=cls)(target)
    return typer.main.get_group(holder).commands[name]


class _RwtGroup(TyperGroup):
    """The ``rwt`` group: an error is one line on stderr, not a usage box or a traceback.

    Its commands (``_COMMANDS``) load when asked for.
    """

    def list_commands(self, ctx: Any) -> list[str]:
        """The names of ``rwt``'s commands, in the order ``rwt --help`` lists them."""
        return list(_COMMANDS)

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        """The command ``cmd_name``, its module imported on first use; None if unknown."""
        command = super().get_command(ctx, cmd_name)
        if command is None and cmd_name in _COMMANDS:
            command = _load(cmd_name)
            self.add_command(command, cmd_name)
        return command

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        """``rwt --help``'s list of commands, from ``_COMMANDS``: it imports no command.

        Click's own asks each command for its short help, which loaded every command's
        module (the MCP SDK, the server, the conformance runner: a second a run).
        """
        rows = [(name, short_help) for name, (_, _, short_help, _) in _COMMANDS.items()]
        with formatter.section("Commands"):
            formatter.write_dl(rows)

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **extra: Any,
    ) -> Any:
        """Run the command line; in standalone mode, exit with its code (2: a usage error)."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, windows_expand_args, **extra)
        try:
            code = super().main(
                args, prog_name or "rwt", complete_var, False, windows_expand_args, **extra
            )
        except ClickException as exc:
            if NoArgsIsHelpError is not None and isinstance(exc, NoArgsIsHelpError):
                typer.echo(str(exc), err=True)  # `rwt` alone: the help
            else:
                typer.echo(error_line(exc), err=True)
            sys.exit(getattr(exc, "exit_code", 1))
        except typer.Abort:
            typer.echo("rwt: aborted", err=True)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


# rich_markup_mode=None: click's plain help, which wraps at 80 columns where rich's
# tables cut option names, and prints [brackets] (rwt-rosbridge[uvloop]) instead of eating them;
# GroupedCommand prints rwt serve's option groups as click help sections
app = typer.Typer(
    cls=_RwtGroup,
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,
)


def _print_version(value: bool) -> None:
    if value:
        try:
            version = importlib.metadata.version(DISTRIBUTION)
        except importlib.metadata.PackageNotFoundError:  # a source tree, not installed
            version = "0+unknown"  # as rwt.__version__
        typer.echo(f"rwt {version}")
        raise typer.Exit


@app.callback()
def main(
    version: Annotated[
        bool,
        typer.Option(
            "--version", is_eager=True, callback=_print_version, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """rwt: a ROS-free rosbridge v2 server, client and conformance suite.

    Run a server with 'rwt serve'; check one with 'rwt conformance URL'.
    """


if __name__ == "__main__":  # python -m rwt_cli.app
    app(prog_name="rwt")
