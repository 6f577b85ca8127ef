"""Every error rwt raises on purpose is in one tree under ``RwtError``.

The tree is drawn in ``rwt_protocol.errors``' docstring; this walks every module of
every rwt package and checks each public exception class defined there is in the
tree, and drawn in it, so a new error cannot be added beside it.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re

import pytest

import rwt_protocol.errors
from rwt_protocol.errors import RwtError

PACKAGES = [
    "rwt",
    "rwt_protocol",
    "rwt_graph",
    "rwt_client",
    "rwt_conformance",
    "rwt_video",
    "rwt_zenoh",
    "rwt_transports",
    "rwt_cli",
]
# Exceptions that never leave the module raising them: a checker's internal signal
# (turned into a FieldError) and typer's own parameter error (a usage message).
INTERNAL = {"rwt_graph.types.problem.Problem", "rwt_cli.checks.OptionError"}


def public_exceptions() -> list[type[BaseException]]:
    found: dict[str, type[BaseException]] = {}
    for package_name in PACKAGES:
        package = importlib.import_module(package_name)
        modules = [package]
        for info in pkgutil.walk_packages(package.__path__, f"{package_name}."):
            if info.name.endswith(".__main__"):  # running it is the command line
                continue
            try:
                modules.append(importlib.import_module(info.name))
            except ImportError as exc:  # an optional extra that is not installed
                pytest.skip(f"{info.name}: {exc}")
        for module in modules:
            for name, value in vars(module).items():
                if (
                    inspect.isclass(value)
                    and issubclass(value, BaseException)
                    and value.__module__ == module.__name__
                    and not name.startswith("_")
                ):
                    found[f"{value.__module__}.{name}"] = value
    return [cls for key, cls in sorted(found.items()) if key not in INTERNAL]


def test_every_public_error_is_under_rwt_error_and_drawn_in_the_tree() -> None:
    errors = public_exceptions()
    assert len(errors) > 20  # the walk found the packages' modules
    drawing = rwt_protocol.errors.__doc__ or ""
    for error in errors:
        if error is RwtError:  # the root, drawn first
            continue
        assert issubclass(error, RwtError), f"{error.__module__}.{error.__name__}"
        assert re.search(rf"── {error.__name__}\b", drawing), f"{error.__name__} is not drawn"
