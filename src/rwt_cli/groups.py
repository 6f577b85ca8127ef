"""Commands whose options come in groups: a dataclass a group, a help section each.

A command with dozens of options (``rwt serve``) is written as a dataclass of
option groups, each a dataclass whose fields are typer options and whose
``PANEL`` names its section of ``--help``. ``grouped_command(Options)(run)``
makes ``run(options: Options)`` a typer command that takes every field of every
group as an option of the same name, and hands ``run`` the filled-in groups; so
the command's body reads ``options.limits.max_message_size``, not 60 arguments.

Sections: typer's ``rich_help_panel`` carries each option's group, and
``GroupedCommand`` prints the groups as click's plain help sections (the CLI uses
click's help, not rich's: see ``rwt_cli.app``).
"""

from __future__ import annotations

import dataclasses
import inspect
from copy import copy
from typing import TYPE_CHECKING, Annotated, Any, TypeVar, get_args, get_origin, get_type_hints

from typer.core import TyperCommand
from typer.models import OptionInfo

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["GroupedCommand", "grouped_command", "option_panels"]

T = TypeVar("T")

OPTIONS_PANEL = "Options"
"""The section of options that belong to no group (``--help``)."""


def grouped_command(options: type[T]) -> Callable[[Callable[[T], None]], Callable[..., None]]:
    """Make ``run(options: T)`` a typer command taking each option of ``T``'s groups.

    Args:
        options: a dataclass whose fields are option groups: dataclasses whose
            fields are ``Annotated[type, typer.Option(...)]`` with a default, and
            whose ``PANEL`` class attribute names their help section.

    Returns:
        A decorator; the command it returns has ``run``'s name and help text.

    Raises:
        TypeError: two groups define an option of the same name, or a field is
            not an ``Annotated`` typer option.
    """
    groups = _groups(options)

    def decorate(run: Callable[[T], None]) -> Callable[..., None]:
        def command(**values: Any) -> None:
            run(options(**{name: group(**_pick(group, values)) for name, group in groups}))

        command.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
            [param for _, group in groups for param in _parameters(group)]
        )
        command.__name__ = run.__name__
        command.__qualname__ = run.__qualname__
        command.__doc__ = run.__doc__
        command.__module__ = run.__module__
        return command

    return decorate


def _groups(options: type) -> list[tuple[str, type]]:
    """The (field name, group class) of ``options``, checked for clashing option names."""
    hints = get_type_hints(options)
    groups = [(field.name, hints[field.name]) for field in dataclasses.fields(options)]
    seen: set[str] = set()
    for _, group in groups:
        names = {field.name for field in dataclasses.fields(group)}
        if clash := names & seen:
            raise TypeError(f"{group.__name__} repeats the options {sorted(clash)}")
        seen |= names
    return groups


def _parameters(group: type) -> list[inspect.Parameter]:
    """Each field of ``group`` as a keyword parameter whose option sits in its panel."""
    hints = get_type_hints(group, include_extras=True)
    return [
        inspect.Parameter(
            field.name,
            inspect.Parameter.KEYWORD_ONLY,
            default=field.default,
            annotation=_in_panel(field.name, hints[field.name], group.PANEL),  # type: ignore[attr-defined]
        )
        for field in dataclasses.fields(group)
    ]


def _in_panel(name: str, annotation: object, panel: str) -> object:
    """``Annotated[type, typer.Option(...)]`` with the option moved into ``panel``."""
    if get_origin(annotation) is not Annotated:
        raise TypeError(f"{name}: not an Annotated typer option")
    kind, *extras = get_args(annotation)
    infos = [extra for extra in extras if isinstance(extra, OptionInfo)]
    if len(infos) != 1:
        raise TypeError(f"{name}: needs exactly one typer.Option")
    info = copy(infos[0])  # the annotation may be shared (bag.Rate): leave it as it was
    info.rich_help_panel = panel
    return Annotated[kind, info]


def _pick(group: type, values: dict[str, Any]) -> dict[str, Any]:
    return {field.name: values[field.name] for field in dataclasses.fields(group)}


def option_panels(command: Any) -> dict[str, list[Any]]:
    """The visible options of a click ``command`` by help section, in first-use order.

    (typer's commands are of its own copy of click: ``Any`` stands for its types.)
    """
    panels: dict[str, list[Any]] = {}
    for param in command.params:
        if param.param_type_name == "option" and not getattr(param, "hidden", False):
            panel = getattr(param, "rich_help_panel", None) or OPTIONS_PANEL
            panels.setdefault(panel, []).append(param)
    return panels


class GroupedCommand(TyperCommand):
    """A command whose ``--help`` lists its options in one section a group."""

    def format_options(self, ctx: Any, formatter: Any) -> None:
        """Write the arguments, then each section of options (click's plain layout)."""
        records = (p.get_help_record(ctx) for p in self.params if p.param_type_name == "argument")
        arguments = [record for record in records if record is not None]
        if arguments:
            with formatter.section("Arguments"):
                formatter.write_dl(arguments)
        panels = option_panels(self)
        help_option = self.get_help_option(ctx)
        if help_option is not None:
            panels.setdefault(OPTIONS_PANEL, []).append(help_option)
        for panel, params in panels.items():
            rows = [row for row in (p.get_help_record(ctx) for p in params) if row is not None]
            if rows:
                with formatter.section(panel):
                    formatter.write_dl(rows)
