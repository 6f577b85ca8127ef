"""Shared pieces of service calls and action goals: arguments, spawning, pending records."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

from rwt_protocol.errors import FieldError, GraphError
from rwt_protocol.ops.base import json_type_name

from .types import Converted, MessageType

__all__ = ["Spawner", "convert_args", "require_spawner"]

Spawner = Callable[[Callable[[], Awaitable[None]]], Callable[[], None]]
"""Runs an async job in the server's event loop; returns a function that cancels it.

The graph does no I/O and knows no event loop (STYLE.md), so whoever runs it (the
server) installs a spawner for async in-process services and actions."""


def convert_args(msgtype: MessageType, args: object, *, path: str, now: float) -> Converted:
    """Build a request or goal from ``args`` (REF §4.4, PROTOCOL-DECISIONS D25).

    Args:
        msgtype: the request or goal type.
        args: an object (fields by name), a list (fields by position), or None.
        path: JSON path of ``args``, for error texts.
        now: wall-clock seconds, for header stamps.

    Returns:
        The converted message and the paths filled with defaults.

    Raises:
        FieldError: a value does not fit, too many positional values, or ``args``
            is neither object, array nor null.
    """
    if args is None:
        args = {}
    elif isinstance(args, list):
        names = [spec.name for spec in msgtype.fields]
        if len(args) > len(names):
            raise FieldError(path, f"expected at most {len(names)} arguments, got {len(args)}")
        args = dict(zip(names, args, strict=False))
    elif not isinstance(args, dict):
        raise FieldError(path, f"expected object or array, got {json_type_name(args)}")
    return msgtype.from_json(args, path=path, now=now)


def require_spawner(spawner: Spawner | None, what: str) -> Spawner:
    """Return the graph's spawner.

    Raises:
        GraphError: none is installed, so ``what`` (an async handler) cannot run.
    """
    if spawner is None:
        raise GraphError(f"{what} is async but no event loop runs this graph")
    return spawner
