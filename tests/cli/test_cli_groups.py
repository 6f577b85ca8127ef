"""rwt_cli.groups: option groups become a command's options, and come back as groups."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar

import pytest
import typer
from typer.testing import CliRunner

from rwt_cli.groups import GroupedCommand, grouped_command


@dataclass(frozen=True)
class Network:
    PANEL: ClassVar[str] = "Network"

    port: Annotated[int, typer.Option(help="A port.")] = 9090
    tls: Annotated[bool, typer.Option(help="Use TLS.")] = False


@dataclass(frozen=True)
class Output:
    PANEL: ClassVar[str] = "Output"

    name: Annotated[str, typer.Option("--name", "-n", help="A name.")] = "rwt"


@dataclass(frozen=True)
class Both:
    network: Network
    output: Output


def make_app(seen: list[Both]) -> typer.Typer:
    app = typer.Typer(rich_markup_mode=None)

    @app.command(cls=GroupedCommand)
    @grouped_command(Both)
    def run(options: Both) -> None:
        """Run it."""
        seen.append(options)

    @app.command()
    def other() -> None:  # a second command, so `run` is a subcommand
        """Another."""

    return app


def test_options_arrive_in_their_groups() -> None:
    seen: list[Both] = []
    result = CliRunner().invoke(make_app(seen), ["run", "--port", "1", "--tls", "-n", "x"])
    assert result.exit_code == 0, result.output
    assert seen == [Both(Network(port=1, tls=True), Output(name="x"))]


def test_help_shows_a_section_a_group() -> None:
    result = CliRunner().invoke(make_app([]), ["run", "--help"])
    text = result.output
    assert text.index("Network:") < text.index("--port") < text.index("Output:")
    assert text.index("Output:") < text.index("-n, --name") < text.index("Options:")
    assert "Run it." in text


def test_two_groups_may_not_define_the_same_option() -> None:
    @dataclass(frozen=True)
    class Clash:
        first: Network
        second: Network

    with pytest.raises(TypeError, match="repeats the options"):
        grouped_command(Clash)
