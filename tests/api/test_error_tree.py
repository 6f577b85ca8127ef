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

import anyio
import numpy as np
import pytest

import rwt_protocol.errors
from rwt_protocol.errors import RwtError
from tests.support.packages import packages

PACKAGES = packages()  # every package under src/, found
# Exceptions that never leave the module raising them: a checker's internal signal
# (turned into a FieldError) and typer's own parameter error (a usage message).
INTERNAL = {"Problem", "OptionError"}


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
                    and value.__module__.split(".")[0].startswith("rwt")  # "rwt" once exported
                    and not name.startswith("_")
                ):
                    found[f"{value.__module__}.{name}"] = value
    unique = {id(cls): cls for cls in found.values() if cls.__name__ not in INTERNAL}
    return sorted(unique.values(), key=lambda cls: cls.__name__)


def test_every_public_error_is_under_rwt_error_and_drawn_in_the_tree() -> None:
    errors = public_exceptions()
    assert len(errors) > 20  # the walk found the packages' modules
    drawing = rwt_protocol.errors.__doc__ or ""
    for error in errors:
        if error is RwtError:  # the root, drawn first
            continue
        assert issubclass(error, RwtError), f"{error.__module__}.{error.__name__}"
        assert re.search(rf"── {error.__name__}\b", drawing), f"{error.__name__} is not drawn"


def test_every_error_of_the_tree_is_in_rwt_or_a_namespace() -> None:
    from rwt._names import PUBLIC  # noqa: PLC0415

    drawn = set(re.findall(r"── (\w+)", rwt_protocol.errors.__doc__ or ""))
    home_only = {"InflateError", "SendTimeoutError", "StepFailedError", "SuiteError"}
    home_only |= {"StreamParamError", "EncodeError", "VideoError"}
    home_only |= {"FoxgloveInputError", "AssetError"}  # the Foxglove session's own
    home_only |= {"InterfaceBuildError"}  # the ROS 2 link's build of a package rclpy lacks
    home_only |= {"OfferError"}  # WebRTC signalling's own: an HTTP 400
    home_only |= {"RouteError"}  # the HTTP API's own: an HTTP 404, 405 or 400
    public = {name for homes in PUBLIC.values() for names in homes.values() for name in names}
    assert sorted(drawn - home_only - public) == []


def test_user_input_gets_a_tree_error() -> None:
    import rwt  # noqa: PLC0415

    async def connect() -> None:
        async with rwt.Ros("http://127.0.0.1:9090"):
            pass

    with pytest.raises(rwt.ConfigError, match="unsupported URL scheme 'http'"):
        anyio.run(connect)
    with pytest.raises(rwt.media.ImageError, match="must be positive"):
        rwt.media.encode_depthcloud(np.zeros((4, 4), np.float32), max_depth_per_tile=0)
    with pytest.raises(rwt.ConfigError, match="unknown status level 'loud'"):
        rwt.StatusLevel.from_wire("loud")
    assert issubclass(rwt.ConfigError, ValueError)  # what these raised before
