"""The ``rwt`` typer application: its commands, ``--version``, and one-line errors."""

from __future__ import annotations

import importlib.metadata
import sys
from collections.abc import Sequence
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from rwt_conformance.cli import conformance

from .bag import bag_app
from .checks import ClickException, NoArgsIsHelpError, error_line
from .groups import GroupedCommand
from .play import play
from .record import record
from .router import router
from .serve import serve

__all__ = ["app", "main"]


class _RwtGroup(TyperGroup):
    """The ``rwt`` group: an error is one line on stderr, not a usage box or a traceback."""

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
# tables cut option names, and prints [brackets] (rwt[uvloop]) instead of eating them;
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
            version = importlib.metadata.version("rwt")
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


app.command(short_help="Check a rosbridge server against the conformance suite.")(conformance)
app.command(short_help="Record topics of a rosbridge server into a bag.")(record)
app.add_typer(bag_app, name="bag", short_help="Inspect bags.")
app.command(short_help="Run a rosbridge server.", cls=GroupedCommand)(serve)
app.command(short_help="Serve a bag's topics as a live robot.")(play)
app.command(short_help="Run a Zenoh router for rwt servers and ROS 2 nodes.")(router)

if __name__ == "__main__":  # python -m rwt_cli.app
    app(prog_name="rwt")
